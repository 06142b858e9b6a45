//! `voltab scene`: what an importer understood, as text for tech artists and JSON for tests.
//!
//! **Input → output.** A checked [`Scene`] → a [`SceneSummary`] (counts, bounds, every light with its
//! converted value and unit, the environment (dome) with its texture, scale and rotation, every medium
//! with σ_s, σ_a, g and its boundary, cameras, materials, warnings) → text or JSON.

use std::fmt::Write as _;

use glam::DVec3;
use serde::Serialize;

use super::{
    Boundary, Camera, Density, EnvironmentLight, LightKind, Material, Scene, SceneFormat, SceneWarning, Surface,
};

/// Counts of what was imported.
#[derive(Debug, Clone, Serialize)]
pub struct Counts {
    /// Meshes.
    pub meshes: usize,
    /// Triangles over all meshes.
    pub triangles: usize,
    /// Vertices over all meshes.
    pub vertices: usize,
    /// Materials.
    pub materials: usize,
    /// Lights, emissive meshes included.
    pub lights: usize,
    /// Cameras.
    pub cameras: usize,
    /// Media.
    pub media: usize,
}

/// One light as reported.
#[derive(Debug, Clone, Serialize)]
pub struct LightSummary {
    /// Node name or prim path.
    pub name: String,
    /// `point`, `spot`, `directional`, `rect`, `disk`, `sphere` or `emissive_mesh`.
    pub kind: &'static str,
    /// Position or centre \[m\] (None for directional lights; the mesh centroid for emissive meshes).
    pub position: Option<[f64; 3]>,
    /// Emission direction (spot axis, travel direction of a directional light, normal of a rect/disk).
    pub direction: Option<[f64; 3]>,
    /// The quantity `value` holds, with its unit.
    pub quantity: &'static str,
    /// Per-channel value in voltab's convention.
    pub value: [f64; 3],
    /// Emitting area \[m²\] of area lights and emissive meshes.
    pub area: Option<f64>,
    /// Total emitted power per channel \[W\] (None for directional lights).
    pub power: Option<[f64; 3]>,
    /// Full geometry.
    pub geometry: LightKind,
}

/// One medium as reported.
#[derive(Debug, Clone, Serialize)]
pub struct MediumSummary {
    /// Source name.
    pub name: String,
    /// Scattering coefficient \[1/m\].
    pub sigma_s: [f64; 3],
    /// Absorption coefficient \[1/m\].
    pub sigma_a: [f64; 3],
    /// Extinction \[1/m\].
    pub sigma_t: [f64; 3],
    /// Single-scattering albedo.
    pub albedo: [f64; 3],
    /// HG g.
    pub g: [f64; 3],
    /// `global`, or the name of the bounding mesh.
    pub boundary: String,
    /// The boundary's surface: `global`, `index-matched` or `refractive (ior X)`.
    pub interface: String,
    /// Density field.
    pub density: Density,
}

/// Everything `voltab scene` prints.
#[derive(Debug, Clone, Serialize)]
pub struct SceneSummary {
    /// Source file.
    pub file: String,
    /// Format.
    pub format: SceneFormat,
    /// Counts.
    pub counts: Counts,
    /// Bounds `[min, max]` in metres (None for an empty scene).
    pub bounds: Option<[[f64; 3]; 2]>,
    /// Bounds diagonal \[m\].
    pub diagonal: f64,
    /// Meshes lacking lightmap UVs.
    pub meshes_without_lightmap_uv: Vec<String>,
    /// Lights.
    pub lights: Vec<LightSummary>,
    /// The environment (USD `DomeLight`), radiance per texel value `scale × color` \[W/(m² sr)\].
    pub environment: Option<EnvironmentLight>,
    /// Media.
    pub media: Vec<MediumSummary>,
    /// Cameras.
    pub cameras: Vec<Camera>,
    /// Materials.
    pub materials: Vec<Material>,
    /// Warnings from import and checks.
    pub warnings: Vec<SceneWarning>,
}

/// Area \[m²\] and area-weighted centroid of a mesh.
pub fn mesh_area(mesh: &super::Mesh) -> (f64, [f64; 3]) {
    let mut area = 0.0;
    let mut c = [0.0; 3];
    for t in &mesh.triangles {
        let p = t.map(|i| DVec3::from(mesh.positions[i as usize].map(f64::from)));
        let a = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length();
        area += a;
        for k in 0..3 {
            c[k] += a * (p[0][k] + p[1][k] + p[2][k]) / 3.0;
        }
    }
    if area > 0.0 {
        c = c.map(|v| v / area);
    }
    (area, c)
}

/// Emitting area \[m²\] of a light (None for point, spot and directional lights).
pub fn light_area(scene: &Scene, kind: &LightKind) -> Option<f64> {
    use std::f64::consts::PI;
    match kind {
        LightKind::Point { .. } | LightKind::Spot { .. } | LightKind::Directional { .. } => None,
        LightKind::Rect { half_u, half_v, .. } => {
            Some(4.0 * DVec3::from(*half_u).length() * DVec3::from(*half_v).length())
        }
        LightKind::Disk { radius, .. } => Some(PI * radius * radius),
        LightKind::Sphere { radius, .. } => Some(4.0 * PI * radius * radius),
        LightKind::EmissiveMesh { mesh } => scene.meshes.get(*mesh).map(|m| mesh_area(m).0),
    }
}

/// Total power \[W\] per channel of a light (None for directional lights, which have no finite power).
pub fn light_power(scene: &Scene, light: &super::Light) -> Option<[f64; 3]> {
    use std::f64::consts::PI;
    let v = light.radiance;
    let factor = match &light.kind {
        LightKind::Point { .. } => 4.0 * PI,
        // Solid angle of the outer cone (the smooth falloff between the cones is not integrated).
        LightKind::Spot { outer_cone, .. } => 2.0 * PI * (1.0 - outer_cone.cos()),
        LightKind::Directional { .. } => return None,
        // A Lambertian emitter of radiance L and area A emits π·L·A.
        kind => PI * light_area(scene, kind)?,
    };
    Some(v.map(|c| c * factor))
}

impl SceneSummary {
    /// Builds the summary of a scene.
    pub fn of(scene: &Scene) -> SceneSummary {
        let counts = Counts {
            meshes: scene.meshes.len(),
            triangles: scene.triangle_count(),
            vertices: scene.meshes.iter().map(|m| m.positions.len()).sum(),
            materials: scene.materials.len(),
            lights: scene.lights.len(),
            cameras: scene.cameras.len(),
            media: scene.media.len(),
        };
        let lights = scene
            .lights
            .iter()
            .map(|l| {
                let (kind, position, direction, quantity) = match &l.kind {
                    LightKind::Point { position } => ("point", Some(*position), None, "intensity [W/sr]"),
                    LightKind::Spot { position, direction, .. } => {
                        ("spot", Some(*position), Some(*direction), "intensity [W/sr]")
                    }
                    LightKind::Directional { direction, .. } => {
                        ("directional", None, Some(*direction), "irradiance [W/m^2]")
                    }
                    LightKind::Rect { center, normal, .. } => {
                        ("rect", Some(*center), Some(*normal), "radiance [W/(m^2 sr)]")
                    }
                    LightKind::Disk { center, normal, .. } => {
                        ("disk", Some(*center), Some(*normal), "radiance [W/(m^2 sr)]")
                    }
                    LightKind::Sphere { center, .. } => ("sphere", Some(*center), None, "radiance [W/(m^2 sr)]"),
                    LightKind::EmissiveMesh { mesh } => (
                        "emissive_mesh",
                        scene.meshes.get(*mesh).map(|m| mesh_area(m).1),
                        None,
                        "radiance [W/(m^2 sr)]",
                    ),
                };
                LightSummary {
                    name: l.name.clone(),
                    kind,
                    position,
                    direction,
                    quantity,
                    value: l.radiance,
                    area: light_area(scene, &l.kind),
                    power: light_power(scene, l),
                    geometry: l.kind.clone(),
                }
            })
            .collect();
        let media = scene
            .media
            .iter()
            .map(|m| {
                let (boundary, interface) = match m.boundary {
                    Boundary::Global => ("global".to_string(), "global".to_string()),
                    Boundary::Mesh(i) => {
                        let mesh = &scene.meshes[i];
                        let surface = mesh.material.and_then(|k| scene.materials.get(k)).map(|mat| mat.surface);
                        let interface = match surface {
                            Some(Surface::Dielectric { ior }) if ior != 1.0 => format!("refractive (ior {ior})"),
                            _ => "index-matched".to_string(),
                        };
                        (mesh.name.clone(), interface)
                    }
                };
                MediumSummary {
                    name: m.name.clone(),
                    sigma_s: m.sigma_s,
                    sigma_a: m.sigma_a,
                    sigma_t: m.sigma_t(),
                    albedo: m.albedo(),
                    g: m.g,
                    boundary,
                    interface,
                    density: m.density.clone(),
                }
            })
            .collect();
        SceneSummary {
            file: scene.source.display().to_string(),
            format: scene.format,
            counts,
            bounds: scene.bounds().map(|(lo, hi)| [lo, hi]),
            diagonal: scene.diagonal(),
            meshes_without_lightmap_uv: scene
                .meshes
                .iter()
                .filter(|m| m.lightmap_uv.is_none() && m.medium.is_none())
                .map(|m| m.name.clone())
                .collect(),
            lights,
            environment: scene.environment.clone(),
            media,
            cameras: scene.cameras.clone(),
            materials: scene.materials.clone(),
            warnings: scene.warnings.clone(),
        }
    }

    /// The human-readable form.
    pub fn text(&self) -> String {
        let mut s = String::new();
        let c = &self.counts;
        let _ = writeln!(s, "{} ({:?})", self.file, self.format);
        let _ = writeln!(
            s,
            "  {} meshes, {} triangles, {} vertices, {} materials, {} lights, {} cameras, {} media",
            c.meshes, c.triangles, c.vertices, c.materials, c.lights, c.cameras, c.media
        );
        if let Some([lo, hi]) = self.bounds {
            let _ = writeln!(
                s,
                "  bounds [{:.4}, {:.4}, {:.4}] .. [{:.4}, {:.4}, {:.4}] m, diagonal {:.4} m",
                lo[0], lo[1], lo[2], hi[0], hi[1], hi[2], self.diagonal
            );
        }
        if !self.lights.is_empty() {
            let _ = writeln!(s, "lights (radiometric, 1 W = 683 lm):");
        }
        for l in &self.lights {
            let at = l.position.map(|p| format!(" at [{:.4}, {:.4}, {:.4}]", p[0], p[1], p[2])).unwrap_or_default();
            let dir = l.direction.map(|d| format!(" dir [{:.4}, {:.4}, {:.4}]", d[0], d[1], d[2])).unwrap_or_default();
            let v = l.value;
            let _ = write!(
                s,
                "  {} {}{at}{dir}: {} [{:.6e}, {:.6e}, {:.6e}]",
                l.kind, l.name, l.quantity, v[0], v[1], v[2]
            );
            if let Some(a) = l.area {
                let _ = write!(s, ", area {a:.6e} m^2");
            }
            if let Some(p) = l.power {
                let _ = write!(s, ", power [{:.4e}, {:.4e}, {:.4e}] W", p[0], p[1], p[2]);
            }
            let _ = writeln!(s);
        }
        if let Some(env) = &self.environment {
            let m = env.multiplier();
            let texture = env.texture.as_ref().map_or("none (uniform)".to_string(), |t| t.display().to_string());
            let r = env.rotation;
            let _ = writeln!(
                s,
                "environment {}: texture {texture}, radiance per texel value [{:.6e}, {:.6e}, {:.6e}] W/(m^2 sr), \
                 map +Y (up) toward [{:.4}, {:.4}, {:.4}], +Z (centre) toward [{:.4}, {:.4}, {:.4}]",
                env.name, m[0], m[1], m[2], r[1][0], r[1][1], r[1][2], r[2][0], r[2][1], r[2][2]
            );
        }
        if !self.media.is_empty() {
            let _ = writeln!(s, "media (1/m):");
        }
        for m in &self.media {
            let f = |v: [f64; 3]| format!("[{:.6e}, {:.6e}, {:.6e}]", v[0], v[1], v[2]);
            let _ = writeln!(
                s,
                "  {} in {} ({}): sigma_s {}, sigma_a {}, albedo {}, g {}",
                m.name,
                m.boundary,
                m.interface,
                f(m.sigma_s),
                f(m.sigma_a),
                f(m.albedo),
                f(m.g)
            );
            if let Density::ExponentialHeight { rho, falloff, direction, offset } = &m.density {
                let _ = writeln!(
                    s,
                    "    exponential height density: rho {rho}, falloff {falloff} 1/m, direction {direction:?}, offset {offset:?}"
                );
            }
        }
        for cam in &self.cameras {
            let p = cam.position;
            let d = cam.forward;
            let _ = writeln!(
                s,
                "camera {} at [{:.4}, {:.4}, {:.4}] looking [{:.4}, {:.4}, {:.4}]: {:?}",
                cam.name, p[0], p[1], p[2], d[0], d[1], d[2], cam.projection
            );
        }
        for m in &self.materials {
            let _ = writeln!(
                s,
                "material {}: base colour {:?}, {:?}, roughness {}, emission {:?}",
                m.name, m.base_color, m.surface, m.roughness, m.emission
            );
        }
        if !self.meshes_without_lightmap_uv.is_empty() {
            let _ = writeln!(s, "meshes without lightmap UVs: {}", self.meshes_without_lightmap_uv.join(", "));
        }
        for w in &self.warnings {
            let _ = writeln!(s, "warning: {}: {}\n  help: {}", w.location, w.message, w.help);
        }
        s
    }
}
