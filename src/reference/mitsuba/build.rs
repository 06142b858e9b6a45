//! [`Scene`] → Mitsuba XML elements, binary files and the manifest, all in memory (the mapping is in the
//! module doc of [`super`]).

use glam::DVec3;

use super::geometry as geo;
use super::xml::Element;
use super::{
    CameraEntry, ExportError, ExportOptions, ExportWarning, GRID_MAX_CELLS, GRID_TOLERANCE, GlobalRegion, GridEntry,
    LightEntry, Manifest, MediumEntry, ShapeEntry, ply, vol,
};
use crate::scene::{Boundary, Density, LightKind, Medium, Projection, Scene, Surface};

/// The export in memory.
#[derive(Debug, Clone)]
pub struct Built {
    /// The scene document.
    pub xml: Element,
    /// Binary files by path relative to the export folder.
    pub files: Vec<(String, Vec<u8>)>,
    /// `export.json`.
    pub manifest: Manifest,
}

const DEFAULT_GREY: f64 = 0.8;

fn medium_id(i: usize) -> String {
    format!("medium_{i}")
}

struct Builder<'a> {
    scene: &'a Scene,
    root: Element,
    files: Vec<(String, Vec<u8>)>,
    m: Manifest,
    global_box: Option<(DVec3, DVec3)>,
}

/// Builds the export of `scene`.
pub fn build(scene: &Scene, options: &ExportOptions) -> Result<Built, ExportError> {
    let global = scene.media.iter().position(|m| m.boundary == Boundary::Global);
    let global_box =
        global.and_then(|_| scene.global_medium_bounds()).map(|(lo, hi)| (DVec3::from(lo), DVec3::from(hi)));
    let units = [
        ("length", "metre; world space, right-handed, +Y up (voltab's frame, unchanged)"),
        ("point, spot", "intensity [W/sr] → Mitsuba point/spot `intensity`"),
        ("directional", "irradiance [W/m²] on a surface facing the light → Mitsuba `irradiance`"),
        ("area lights, emissive meshes, environment", "radiance [W/(m²·sr)] → Mitsuba `radiance`/`scale`"),
        ("media", "σ_t = σ_s + σ_a [1/m], albedo = σ_s/σ_t, HG g; density ρ multiplies σ_t (grid volumes hold σ_t·ρ)"),
        ("irradiance from the harness", "W/m², E = ∫ L cos θ dω"),
    ];
    let mut b = Builder {
        scene,
        root: Element::new("scene").attr("version", "3.0.0"),
        files: Vec::new(),
        m: Manifest {
            format: "voltab-mitsuba-export".into(),
            version: 1,
            source: scene.source.clone(),
            scene_xml: "scene.xml".into(),
            units: units.iter().map(|(a, b)| (a.to_string(), b.to_string())).collect(),
            global_medium: None,
            camera: None,
            shapes: Vec::new(),
            media: Vec::new(),
            lights: Vec::new(),
            warnings: Vec::new(),
        },
        global_box,
    };
    for (name, value) in [("spp", options.spp.to_string()), ("max_depth", "-1".into()), ("rr_depth", "5".into())] {
        b.root.push(Element::new("default").attr("name", name).attr("value", value));
    }
    b.camera(options)?;
    b.root.push(
        Element::new("integrator")
            .attr("type", "volpath")
            .child(Element::new("integer").attr("name", "max_depth").attr("value", "$max_depth"))
            .child(Element::new("integer").attr("name", "rr_depth").attr("value", "$rr_depth")),
    );
    b.media();
    if let (Some(g), Some((lo, hi))) = (global, global_box) {
        b.global_region(g, lo, hi);
    } else if let Some(g) = global {
        b.warn(
            &scene.media[g].name,
            "the scene has no geometry or positioned lights to bound the global medium; it is left out",
        );
    }
    b.meshes();
    b.lights();
    b.environment();
    for w in &scene.warnings {
        b.warn(&w.location, &format!("import warning carried over: {}", w.message));
    }
    Ok(Built { xml: b.root, files: b.files, manifest: b.m })
}

impl Builder<'_> {
    fn warn(&mut self, location: &str, message: &str) {
        self.m.warnings.push(ExportWarning { location: location.into(), message: message.into() });
    }

    /// The Mitsuba id of the medium around `p` (see [`geo::medium_at`]).
    fn medium_around(&self, p: DVec3, exclude: Option<usize>) -> Option<String> {
        geo::medium_at(self.scene, p, exclude, self.global_box).map(medium_id)
    }

    fn camera(&mut self, options: &ExportOptions) -> Result<(), ExportError> {
        let cams = &self.scene.cameras;
        let cam = match &options.camera {
            Some(name) => cams.iter().find(|c| &c.name == name).ok_or_else(|| ExportError::UnknownCamera {
                scene: self.scene.source.clone(),
                name: name.clone(),
                available: cams.iter().map(|c| c.name.clone()).collect(),
            })?,
            None => match cams.first() {
                Some(c) => c,
                None => {
                    self.warn("(scene)", "the scene has no camera: no sensor is written (Mitsuba adds a default one; the harness's point and ray queries need none)");
                    return Ok(());
                }
            },
        };
        let Projection::Perspective { yfov, aspect } = cam.projection else {
            self.warn(&cam.name, "orthographic cameras are not exported: no sensor is written");
            return Ok(());
        };
        let width = options.width.max(1);
        let height =
            options.height.unwrap_or_else(|| (f64::from(width) / aspect.unwrap_or(4.0 / 3.0)).round().max(1.0) as u32);
        let f = |v: DVec3| format!("{}, {}, {}", super::xml::num(v.x), super::xml::num(v.y), super::xml::num(v.z));
        let target = DVec3::from(cam.position) + DVec3::from(cam.forward);
        let diag = self.scene.diagonal().max(1.0);
        let mut sensor = Element::new("sensor")
            .attr("type", "perspective")
            .comment(format!("camera {}", cam.name))
            .child(Element::float("fov", yfov.to_degrees()))
            .child(Element::string("fov_axis", "y"))
            .child(Element::float("near_clip", cam.znear.max(1e-6)))
            .child(Element::float("far_clip", cam.zfar.unwrap_or(1e4 * diag)))
            .child(
                Element::new("transform").attr("name", "to_world").child(
                    Element::new("lookat")
                        .attr("origin", f(DVec3::from(cam.position)))
                        .attr("target", f(target))
                        .attr("up", f(DVec3::from(cam.up))),
                ),
            )
            .child(
                Element::new("sampler")
                    .attr("type", "independent")
                    .child(Element::new("integer").attr("name", "sample_count").attr("value", "$spp")),
            )
            .child(
                Element::new("film")
                    .attr("type", "hdrfilm")
                    .child(Element::new("integer").attr("name", "width").attr("value", "$width"))
                    .child(Element::new("integer").attr("name", "height").attr("value", "$height"))
                    .child(Element::string("pixel_format", "rgb"))
                    .child(Element::new("rfilter").attr("type", "box")),
            );
        let medium = self.medium_around(DVec3::from(cam.position), None);
        if let Some(id) = &medium {
            sensor.push(Element::reference(Some("medium"), id));
        }
        for (name, value) in [("width", width), ("height", height)] {
            self.root.push(Element::new("default").attr("name", name).attr("value", value.to_string()));
        }
        self.root.push(sensor);
        self.m.camera =
            Some(CameraEntry { name: cam.name.clone(), width, height, fov_y_deg: yfov.to_degrees(), medium });
        Ok(())
    }

    fn media(&mut self) {
        for (i, med) in self.scene.media.iter().enumerate() {
            let boundary = match med.boundary {
                Boundary::Global => "global".to_string(),
                Boundary::Mesh(k) => self.scene.meshes.get(k).map_or(format!("mesh {k}"), |m| m.name.clone()),
            };
            let region = match med.boundary {
                Boundary::Global => self.global_box,
                Boundary::Mesh(k) => self.scene.meshes.get(k).and_then(|m| mesh_box(&m.positions)),
            };
            let t = med.sigma_t();
            let albedo = med.albedo();
            let g = med.g.iter().sum::<f64>() / 3.0;
            if med.g.iter().any(|&x| (x - g).abs() > 1e-9) {
                self.warn(
                    &med.name,
                    &format!("Mitsuba's hg phase has one g; per-channel g {:?} exported as their mean {g}", med.g),
                );
            }
            let phase = Element::new("phase").attr("type", "hg").child(Element::float("g", g));
            let id = medium_id(i);
            let mut e = Element::new("medium").attr("id", &id).comment(format!("medium {} ({boundary})", med.name));
            let mut grid_entry = None;
            // Mitsuba reads an `rgb` as a reflectance (each channel ≤ 1): σ_t = (σ_t / s) · scale s.
            let s = t.iter().copied().fold(0.0, f64::max);
            let s = if s > 0.0 { s } else { 1.0 };
            let mut scale = s;
            match (&med.density, region) {
                (Density::Homogeneous, _) => {
                    e = e.attr("type", "homogeneous").child(Element::rgb("sigma_t", t.map(|x| x / s)));
                }
                (Density::ExponentialHeight { .. }, Some((lo, hi))) => {
                    let (grid, entry) = self.height_grid(i, med, lo, hi);
                    let size = hi - lo;
                    e = e.attr("type", "heterogeneous").child(
                        Element::new("volume")
                            .attr("name", "sigma_t")
                            .attr("type", "gridvolume")
                            .child(Element::string("filename", &entry.file))
                            .child(Element::to_world_matrix(geo::affine(
                                DVec3::new(size.x, 0.0, 0.0),
                                DVec3::new(0.0, size.y, 0.0),
                                DVec3::new(0.0, 0.0, size.z),
                                lo,
                            ))),
                    );
                    self.files.push((entry.file.clone(), vol::encode(&grid)));
                    grid_entry = Some(entry);
                    scale = 1.0;
                }
                (Density::ExponentialHeight { .. }, None) => {
                    self.warn(&med.name, "exponential density over an empty region: exported homogeneous at density 1");
                    e = e.attr("type", "homogeneous").child(Element::rgb("sigma_t", t.map(|x| x / s)));
                }
            }
            e = e.child(Element::rgb("albedo", albedo)).child(Element::float("scale", scale)).child(phase);
            self.m.media.push(MediumEntry {
                name: med.name.clone(),
                id,
                mitsuba_type: if grid_entry.is_some() { "heterogeneous" } else { "homogeneous" }.into(),
                boundary,
                grid: grid_entry,
            });
            self.root.push(e);
        }
    }

    /// A 3-channel σ_t·ρ grid over `[lo, hi]`, resolved along each axis in proportion to how fast the
    /// exponential changes along it.
    fn height_grid(&mut self, i: usize, med: &Medium, lo: DVec3, hi: DVec3) -> (vol::Grid, GridEntry) {
        let Density::ExponentialHeight { rho, falloff, direction, offset } = med.density else {
            unreachable!("height_grid is called for exponential densities only")
        };
        let n = geo::unit(DVec3::from(direction)).unwrap_or(DVec3::Y);
        let size = hi - lo;
        let mut res =
            [0, 1, 2].map(|k| ((falloff.abs() * n[k].abs() * size[k] / GRID_TOLERANCE).ceil() as usize).clamp(2, 4096));
        while res.iter().product::<usize>() > GRID_MAX_CELLS {
            let k = (0..3).max_by_key(|&k| res[k]).unwrap_or(0);
            res[k] = (res[k] / 2).max(2);
        }
        // Trilinear interpolation of e^{−b h} between samples Δh apart: relative error ≤ (bΔh)²/8.
        let step: f64 = (0..3).map(|k| n[k].abs() * size[k] / res[k] as f64).sum();
        let err = (falloff * step).powi(2) / 8.0;
        if falloff * step > GRID_TOLERANCE * 1.0001 {
            self.warn(
                &med.name,
                &format!("grid capped at {GRID_MAX_CELLS} cells: relative interpolation error up to {err:.2e}"),
            );
        }
        let t = med.sigma_t();
        let grid = vol::sample_cell_centres((lo.to_array(), hi.to_array()), res, 3, |p| {
            let h = (DVec3::from(p) - DVec3::from(offset)).dot(n);
            let d = rho * (-falloff * h).exp();
            t.iter().map(|s| s * d).collect()
        });
        let entry = GridEntry {
            file: format!("volumes/medium_{i}.vol"),
            resolution: res,
            min: lo.to_array(),
            max: hi.to_array(),
            max_relative_interpolation_error: err,
        };
        (grid, entry)
    }

    fn global_region(&mut self, g: usize, lo: DVec3, hi: DVec3) {
        let id = medium_id(g);
        let size = hi - lo;
        let centre = (lo + hi) * 0.5;
        // Mitsuba's cube spans [−1, 1]³.
        let m = geo::affine(
            DVec3::new(size.x / 2.0, 0.0, 0.0),
            DVec3::new(0.0, size.y / 2.0, 0.0),
            DVec3::new(0.0, 0.0, size.z / 2.0),
            centre,
        );
        self.root.push(
            Element::new("shape")
                .attr("type", "cube")
                .attr("id", "global_medium_box")
                .comment("the region the global medium fills (voltab::scene::extent)")
                .child(Element::to_world_matrix(m))
                .child(Element::new("bsdf").attr("type", "null"))
                .child(Element::reference(Some("interior"), &id)),
        );
        self.m.shapes.push(ShapeEntry {
            id: "global_medium_box".into(),
            name: self.scene.media[g].name.clone(),
            file: None,
            bsdf: "null".into(),
            interior: Some(id.clone()),
            exterior: None,
            emission: None,
            flipped: false,
        });
        self.m.global_medium = Some(GlobalRegion {
            medium: g,
            id,
            min: lo.to_array(),
            max: hi.to_array(),
            model: "the scene bounds (mesh vertices and positioned lights) padded on each side by 1 % of their \
                    diagonal + 1 mm; vacuum outside"
                .into(),
        });
    }

    fn meshes(&mut self) {
        let scene = self.scene;
        for (i, mesh) in scene.meshes.iter().enumerate() {
            if mesh.triangles.is_empty() {
                self.warn(&mesh.name, "mesh without triangles: left out");
                continue;
            }
            let bounded = scene.media.iter().position(|m| m.boundary == Boundary::Mesh(i));
            let material = mesh.material.and_then(|k| scene.materials.get(k));
            let flipped = bounded.is_some() && geo::signed_volume(mesh) < 0.0;
            if flipped {
                self.warn(&mesh.name, "medium boundary wound inward: written with reversed winding and normals");
            }
            let (bsdf, kind) = match material.map(|m| m.surface) {
                Some(Surface::Dielectric { ior }) if (ior - 1.0).abs() > 1e-12 => (
                    Element::new("bsdf")
                        .attr("type", "dielectric")
                        .child(Element::float("int_ior", ior))
                        .child(Element::float("ext_ior", 1.0)),
                    "dielectric",
                ),
                Some(Surface::Dielectric { .. }) => (Element::new("bsdf").attr("type", "null"), "null"),
                None if bounded.is_some() => (Element::new("bsdf").attr("type", "null"), "null"),
                Some(Surface::Opaque) | None => {
                    let colour = material.map_or([DEFAULT_GREY; 3], |m| m.base_color);
                    (
                        Element::new("bsdf").attr("type", "twosided").child(
                            Element::new("bsdf").attr("type", "diffuse").child(Element::rgb("reflectance", colour)),
                        ),
                        "diffuse",
                    )
                }
            };
            if material.is_some_and(|m| m.roughness > 0.0 && kind == "dielectric") {
                self.warn(&mesh.name, "rough dielectric exported smooth (voltab's references treat it as smooth)");
            }
            let file = format!("meshes/mesh_{i}.ply");
            self.files.push((file.clone(), ply::encode(&mesh.positions, &mesh.normals, &mesh.triangles, flipped)));
            let id = format!("mesh_{i}");
            let mut e = Element::new("shape")
                .attr("type", "ply")
                .attr("id", &id)
                .comment(format!("mesh {}", mesh.name))
                .child(Element::string("filename", &file))
                .child(bsdf);
            let interior = bounded.map(medium_id);
            // Media on a surface Mitsuba crosses: its own medium inside, the one around it outside.
            let exterior = if kind == "diffuse" {
                None
            } else {
                self.medium_around(
                    DVec3::from_array(mesh.positions[mesh.triangles[0][0] as usize].map(f64::from)),
                    Some(i),
                )
            };
            if let Some(m) = &interior {
                e.push(Element::reference(Some("interior"), m));
            }
            if let Some(m) = &exterior {
                e.push(Element::reference(Some("exterior"), m));
            }
            let emission = scene.lights.iter().find_map(|l| match l.kind {
                LightKind::EmissiveMesh { mesh } if mesh == i => Some(l.radiance),
                _ => None,
            });
            if let Some(l) = emission {
                e.push(Element::new("emitter").attr("type", "area").child(Element::rgb("radiance", l)));
            }
            self.root.push(e);
            self.m.shapes.push(ShapeEntry {
                id,
                name: mesh.name.clone(),
                file: Some(file),
                bsdf: kind.into(),
                interior,
                exterior,
                emission,
                flipped,
            });
        }
    }

    fn lights(&mut self) {
        for (i, light) in self.scene.lights.iter().enumerate() {
            let rgb = light.radiance;
            let (kind, plugin, element) = match &light.kind {
                LightKind::Point { position } => (
                    "point",
                    "point",
                    Some(
                        Element::new("emitter")
                            .attr("type", "point")
                            .child(Element::xyz("point", "position", *position))
                            .child(Element::rgb("intensity", rgb)),
                    ),
                ),
                LightKind::Spot { position, direction, inner_cone, outer_cone } => {
                    let Some(axis) = geo::unit(DVec3::from(*direction)) else {
                        self.warn(&light.name, "spot light without a direction: left out");
                        continue;
                    };
                    let (up, _) = geo::frame(axis);
                    let inner = inner_cone.min(*outer_cone);
                    let diff = spot_falloff_difference(inner, *outer_cone);
                    if diff > 1e-3 {
                        self.warn(
                            &light.name,
                            &format!(
                                "Mitsuba's spot falloff is linear in angle between beam_width {:.3}° and cutoff {:.3}°, \
                                 voltab's is KHR's t² in cosine: they differ by up to {diff:.3} of the on-axis intensity",
                                inner.to_degrees(),
                                outer_cone.to_degrees()
                            ),
                        );
                    }
                    let f = |v: DVec3| {
                        format!("{}, {}, {}", super::xml::num(v.x), super::xml::num(v.y), super::xml::num(v.z))
                    };
                    (
                        "spot",
                        "spot",
                        Some(
                            Element::new("emitter")
                                .attr("type", "spot")
                                .child(
                                    Element::new("transform").attr("name", "to_world").child(
                                        Element::new("lookat")
                                            .attr("origin", f(DVec3::from(*position)))
                                            .attr("target", f(DVec3::from(*position) + axis))
                                            .attr("up", f(up)),
                                    ),
                                )
                                .child(Element::rgb("intensity", rgb))
                                .child(Element::float("cutoff_angle", outer_cone.to_degrees()))
                                .child(Element::float("beam_width", inner.to_degrees())),
                        ),
                    )
                }
                LightKind::Directional { direction, angle } => {
                    let Some(d) = geo::unit(DVec3::from(*direction)) else {
                        self.warn(&light.name, "directional light without a direction: left out");
                        continue;
                    };
                    if *angle > 0.0 {
                        self.warn(
                            &light.name,
                            "angular diameter ignored: Mitsuba's directional light is a delta (so is the bake's)",
                        );
                    }
                    (
                        "directional",
                        "directional",
                        Some(
                            Element::new("emitter")
                                .attr("type", "directional")
                                .child(Element::xyz("vector", "direction", d.to_array()))
                                .child(Element::rgb("irradiance", rgb)),
                        ),
                    )
                }
                LightKind::Rect { center, half_u, half_v, normal } => {
                    let Some(n) = geo::unit(DVec3::from(*normal)) else { continue };
                    let (hu, hv) = (DVec3::from(*half_u), DVec3::from(*half_v));
                    let (u, v) = if hu.cross(hv).dot(n) < 0.0 { (hv, hu) } else { (hu, hv) };
                    // Mitsuba's rectangle spans [−1, 1]² in local xy with normal +z.
                    let m = geo::affine(u, v, n, DVec3::from(*center));
                    ("rect", "rectangle", Some(area_shape("rectangle", i, m, rgb)))
                }
                LightKind::Disk { center, normal, radius } => {
                    let Some(n) = geo::unit(DVec3::from(*normal)) else { continue };
                    let (t, b) = geo::frame(n);
                    let m = geo::affine(t * *radius, b * *radius, n, DVec3::from(*center));
                    ("disk", "disk", Some(area_shape("disk", i, m, rgb)))
                }
                LightKind::Sphere { center, radius } => {
                    let e = Element::new("shape")
                        .attr("type", "sphere")
                        .attr("id", format!("light_{i}"))
                        .child(Element::xyz("point", "center", *center))
                        .child(Element::float("radius", *radius))
                        .child(Element::new("bsdf").attr("type", "null"))
                        .child(Element::new("emitter").attr("type", "area").child(Element::rgb("radiance", rgb)));
                    ("sphere", "sphere + area", Some(e))
                }
                LightKind::EmissiveMesh { .. } => ("emissive mesh", "area emitter on the mesh's shape", None),
            };
            if let Some(e) = element {
                self.root.push(e.comment(format!("light {}", light.name)));
            }
            self.m.lights.push(LightEntry { name: light.name.clone(), kind: kind.into(), mitsuba: plugin.into() });
        }
    }

    fn environment(&mut self) {
        let Some(env) = &self.scene.environment else { return };
        let mult = env.multiplier();
        let e = match &env.texture {
            None => Element::new("emitter").attr("type", "constant").child(Element::rgb("radiance", mult)),
            Some(tex) => {
                let grey = env.color.iter().sum::<f64>() / 3.0;
                if env.color.iter().any(|&c| (c - grey).abs() > 1e-9) {
                    self.warn(
                        &env.name,
                        &format!(
                            "Mitsuba's envmap scale is one number: tint {:?} exported as its mean {grey}",
                            env.color
                        ),
                    );
                }
                let r = env.rotation;
                Element::new("emitter")
                    .attr("type", "envmap")
                    .child(Element::string("filename", &tex.to_string_lossy()))
                    .child(Element::float("scale", env.scale * grey))
                    .child(Element::to_world_matrix(geo::affine(
                        DVec3::from(r[0]),
                        DVec3::from(r[1]),
                        DVec3::from(r[2]),
                        DVec3::ZERO,
                    )))
            }
        };
        self.root.push(e.comment(format!("environment {}", env.name)));
        self.m.lights.push(LightEntry {
            name: env.name.clone(),
            kind: "environment".into(),
            mitsuba: if env.texture.is_some() { "envmap" } else { "constant" }.into(),
        });
    }
}

fn area_shape(kind: &str, i: usize, m: [[f64; 4]; 4], radiance: [f64; 3]) -> Element {
    Element::new("shape")
        .attr("type", kind)
        .attr("id", format!("light_{i}"))
        .child(Element::to_world_matrix(m))
        .child(Element::new("bsdf").attr("type", "null"))
        .child(Element::new("emitter").attr("type", "area").child(Element::rgb("radiance", radiance)))
}

fn mesh_box(p: &[[f32; 3]]) -> Option<(DVec3, DVec3)> {
    let mut lo = DVec3::INFINITY;
    let mut hi = DVec3::NEG_INFINITY;
    for v in p {
        let v = DVec3::from_array(v.map(f64::from));
        lo = lo.min(v);
        hi = hi.max(v);
    }
    lo.x.is_finite().then(|| {
        let pad = 1e-4 * (hi - lo).length() + 1e-6;
        (lo - pad, hi + pad)
    })
}

/// Largest |KHR falloff − Mitsuba falloff| over the cone, as a fraction of the on-axis intensity.
pub(crate) fn spot_falloff_difference(inner: f64, outer: f64) -> f64 {
    let (ci, co) = (inner.cos(), outer.cos());
    (0..=2000)
        .map(|k| {
            let th = outer * k as f64 / 2000.0;
            let t = ((th.cos() - co) / (ci - co).max(1e-3)).clamp(0.0, 1.0);
            let khr = t * t;
            let mi = if th <= inner {
                1.0
            } else if th < outer {
                (outer - th) / (outer - inner)
            } else {
                0.0
            };
            (khr - mi).abs()
        })
        .fold(0.0, f64::max)
}
