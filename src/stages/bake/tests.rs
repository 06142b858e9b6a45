//! Tests of the bake's transport against independently derived values: inverse-square and Beer–Lambert
//! limits, the analytic irradiance of a rectangle, the closed-box geometric series of surface bounces,
//! the ordering of the modes, the table's own answer for an isolated connection, probe SH of a point
//! light, thread-count independence and the extreme cases of issue 6.

use std::f64::consts::PI;
use std::sync::OnceLock;

use super::transport::{MIN_DISTANCE, Transport, TransportOptions};
use super::*;
use crate::physics::medium::HomogeneousMedium;
use crate::scene::fixtures::{cuboid, empty, medium, point_light};
use crate::scene::{Boundary, Light, LightKind, Material, Mesh, Surface};
use crate::tables::phase_hg::GValues;
use crate::tables::zh_response::{Emitter, QueryOptions, Receiver, ZhResponse, ZhResponseTable};

/// A small table (all emitter profiles, g ∈ {0, 0.5}, 48 distances, B = 6), generated once.
fn table() -> &'static ZhResponseTable {
    static T: OnceLock<ZhResponseTable> = OnceLock::new();
    T.get_or_init(|| {
        let def = ZhResponse {
            g: GValues::List(vec![0.0, 0.5]),
            distance_bins: 48,
            quadrature_nodes: 4,
            theta_bins: 4,
            bounces: 6,
            ..ZhResponse::default()
        };
        assert!(def.validate().is_empty(), "{:?}", def.validate());
        let generated = def.generate(&[3; 32], &|_| {}).unwrap();
        ZhResponseTable::from_arrays(&def, &generated.arrays, &generated.values).unwrap()
    })
}

fn opts(mode: BakeMode, samples: u32, bounces: u32) -> TransportOptions {
    TransportOptions { mode, samples, scatter_samples: samples, bounces, backscatter: false, seed: 1 }
}

/// A one-sided quad in the plane y = `y` facing +y, from (x0, z0) to (x1, z1).
fn floor_quad(name: &str, y: f32, x0: f32, x1: f32, z0: f32, z1: f32) -> Mesh {
    let mut m = cuboid(name, [x0, y - 0.01, z0], [x1, y, z1]);
    // Keep the top face only (the two triangles whose vertices all lie at y).
    m.triangles.retain(|t| t.iter().all(|&i| m.positions[i as usize][1] == y));
    m
}

const UP: [f64; 3] = [0.0, 1.0, 0.0];

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(1e-300)
}

#[test]
fn point_light_in_vacuum_is_inverse_square_and_cosine() {
    let mut s = empty("v.gltf");
    s.lights.push(point_light("L", [0.3, 2.0, -0.4], 5.0));
    let bvh = SceneBvh::build(&s);
    let tr = Transport::new(&s, &bvh, None, opts(BakeMode::Surface, 1, 0)).unwrap();
    for x in [[0.0, 0.0, 0.0], [1.5, 0.0, 2.0], [-3.0, 0.0, 0.1]] {
        let e = tr.receiver(x, UP, UP, 0).unwrap();
        let d = [0.3 - x[0], 2.0 - x[1], -0.4 - x[2]];
        let r2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        let expected = 5.0 * (d[1] / r2.sqrt()) / r2;
        for c in 0..3 {
            assert!(rel(e.irradiance[c], expected) < 1e-9, "{x:?}: {} vs {expected}", e.irradiance[c]);
        }
    }
}

#[test]
fn shadow_mode_is_beer_lambert_and_sigma_s_zero_full_equals_shadow() {
    let mut s = empty("v.gltf");
    s.lights.push(point_light("L", [0.0, 3.0, 0.0], 2.0));
    let mut m = medium("fog", 0.0, Boundary::Global);
    m.sigma_a = [0.1, 0.2, 0.4];
    s.media.push(m);
    let bvh = SceneBvh::build(&s);
    let shadow = Transport::new(&s, &bvh, None, opts(BakeMode::Shadow, 1, 0)).unwrap();
    let e = shadow.receiver([0.0; 3], UP, UP, 0).unwrap();
    for (c, sa) in [0.1f64, 0.2, 0.4].iter().enumerate() {
        // The ray starts eps above the receiver, so the path in the medium is 3 - eps.
        let expected = 2.0 / 9.0 * (-sa * 3.0f64).exp();
        assert!(rel(e.irradiance[c], expected) < 1e-4, "channel {c}: {} vs {expected}", e.irradiance[c]);
    }
    // σ_s = 0: nothing scatters, Full adds nothing to Shadow (no table needed either way).
    let full = Transport::new(&s, &bvh, Some(table()), opts(BakeMode::Full, 1, 0)).unwrap();
    let f = full.receiver([0.0; 3], UP, UP, 0).unwrap();
    assert_eq!(f.irradiance, e.irradiance);
}

#[test]
fn full_mode_connection_equals_the_tables_answer_for_that_segment() {
    // One point light, a receiver in a global homogeneous fog, no geometry: the transport's answer is
    // the table's irradiance for (σ_s, σ_a, g, d) with intensity per channel, direct + single + multiple.
    let mut s = empty("v.gltf");
    s.lights.push(Light {
        name: "L".into(),
        kind: LightKind::Point { position: [0.0, 2.0, 1.0] },
        radiance: [3.0, 2.0, 1.0],
    });
    let mut m = medium("fog", 0.3, Boundary::Global);
    m.sigma_a = [0.05; 3];
    m.g = [0.25; 3];
    s.media.push(m);
    let bvh = SceneBvh::build(&s);
    let tr = Transport::new(&s, &bvh, Some(table()), opts(BakeMode::Full, 1, 0)).unwrap();
    let e = tr.receiver([0.0; 3], UP, UP, 0).unwrap();
    let q = table()
        .irradiance(
            &HomogeneousMedium { sigma_s: 0.3, sigma_a: 0.05, g: 0.25 },
            &Emitter::Point { intensity: 1.0, position: [0.0, 2.0, 1.0] },
            &Receiver { position: [0.0; 3], normal: UP },
            &QueryOptions { backscatter: false, similarity: true, ..QueryOptions::default() },
        )
        .unwrap();
    assert!(q.single > 0.0 && q.multiple > 0.0);
    for (c, i) in [3.0, 2.0, 1.0].iter().enumerate() {
        assert!(rel(e.irradiance[c], i * q.total) < 1e-4, "channel {c}: {} vs {}", e.irradiance[c], i * q.total);
    }
    // The Shadow mode keeps exactly the table's direct part.
    let sh =
        Transport::new(&s, &bvh, None, opts(BakeMode::Shadow, 1, 0)).unwrap().receiver([0.0; 3], UP, UP, 0).unwrap();
    assert!(rel(sh.irradiance[0], 3.0 * q.direct) < 1e-4);
}

/// Irradiance at the centre below a parallel rectangle of radiance L, half-sides a, b at height h:
/// E = L · 4 · [ a/√(a²+h²) · atan(b/√(a²+h²)) + b/√(b²+h²) · atan(a/√(b²+h²)) ] / 2 (the form factor of
/// a quadrant rectangle from a point on its corner normal, times four).
fn rect_irradiance(l: f64, a: f64, b: f64, h: f64) -> f64 {
    let quadrant = |a: f64, b: f64| {
        let ra = (a * a + h * h).sqrt();
        let rb = (b * b + h * h).sqrt();
        0.5 * (a / ra * (b / ra).atan() + b / rb * (a / rb).atan())
    };
    l * 4.0 * quadrant(a, b)
}

#[test]
fn rect_light_matches_the_analytic_form_factor() {
    let mut s = empty("v.gltf");
    s.lights.push(Light {
        name: "panel".into(),
        kind: LightKind::Rect {
            center: [0.0, 1.0, 0.0],
            half_u: [0.5, 0.0, 0.0],
            half_v: [0.0, 0.0, 0.3],
            normal: [0.0, -1.0, 0.0],
        },
        radiance: [10.0; 3],
    });
    let bvh = SceneBvh::build(&s);
    let tr = Transport::new(&s, &bvh, None, opts(BakeMode::Surface, 4096, 0)).unwrap();
    let e = tr.receiver([0.0; 3], UP, UP, 7).unwrap();
    let expected = rect_irradiance(10.0, 0.5, 0.3, 1.0);
    let stderr = e.rel_stderr * e.irradiance[0];
    assert!(
        (e.irradiance[0] - expected).abs() < 4.0 * stderr.max(1e-4 * expected),
        "{} vs {expected} ± {stderr}",
        e.irradiance[0]
    );
    assert!(rel(e.irradiance[0], expected) < 0.01, "{} vs {expected}", e.irradiance[0]);
}

#[test]
fn closed_emissive_box_gives_the_geometric_series_of_bounces() {
    // Inside a closed box whose walls all emit L and reflect ρ, the radiance after k bounces is
    // L Σ_{j ≤ k} ρ^j everywhere, so E = π L Σ_{j=0}^{B} ρ^j with B surface bounces.
    let mut s = empty("box.gltf");
    let mut b = cuboid("box", [0.0; 3], [2.0, 1.0, 1.5]);
    // Face inward: reverse the winding (normals are per-hit; the emissive side is the front).
    for t in &mut b.triangles {
        t.swap(1, 2);
    }
    b.normals.clear();
    b.material = Some(0);
    s.meshes.push(b);
    let rho = 0.5;
    s.materials.push(Material {
        name: "w".into(),
        base_color: [rho; 3],
        emission: [1.0; 3],
        surface: Surface::Opaque,
        roughness: 1.0,
    });
    s.lights.push(Light { name: "box".into(), kind: LightKind::EmissiveMesh { mesh: 0 }, radiance: [1.0; 3] });
    let bvh = SceneBvh::build(&s);
    for bounces in [0u32, 1, 3] {
        let tr = Transport::new(&s, &bvh, None, opts(BakeMode::Surface, 2048, bounces)).unwrap();
        let e = tr.receiver([1.0, 0.0, 0.75], UP, UP, 3).unwrap();
        let expected = PI * (0..=bounces).map(|j| rho.powi(j as i32)).sum::<f64>();
        let stderr = e.rel_stderr * e.irradiance[0];
        assert!(
            (e.irradiance[0] - expected).abs() < 4.0 * stderr + 1e-3 * expected,
            "B = {bounces}: {} vs {expected} ± {stderr}",
            e.irradiance[0]
        );
    }
}

/// The fixture room: floor, emissive lamp, point light, global fog.
fn room() -> Scene {
    let mut s = crate::scene::fixtures::fog_room();
    s.meshes[0] = floor_quad("/Room/Floor", 0.0, 0.0, 4.0, 0.0, 4.0);
    s.meshes[0].material = Some(0);
    s
}

#[test]
fn modes_are_ordered_surface_over_shadow_and_full_over_shadow() {
    let s = room();
    let bvh = SceneBvh::build(&s);
    let points = [[1.0, 0.0, 1.0], [2.0, 0.0, 2.0], [3.5, 0.0, 0.5]];
    for p in points {
        let e =
            |mode| Transport::new(&s, &bvh, Some(table()), opts(mode, 16, 1)).unwrap().receiver(p, UP, UP, 5).unwrap();
        let (su, sh, fu) = (e(BakeMode::Surface), e(BakeMode::Shadow), e(BakeMode::Full));
        for c in 0..3 {
            // Same random numbers in every mode: attenuation can only remove light, scattering only add.
            assert!(su.irradiance[c] > sh.irradiance[c], "{p:?}: {su:?} vs {sh:?}");
            assert!(fu.irradiance[c] > sh.irradiance[c], "{p:?}: {fu:?} vs {sh:?}");
        }
    }
}

#[test]
fn bake_is_identical_for_one_and_two_threads() {
    let s = room();
    let bvh = SceneBvh::build(&s);
    let tr = Transport::new(&s, &bvh, Some(table()), opts(BakeMode::Full, 4, 2)).unwrap();
    let points: Vec<TexelPoint> = (0..40)
        .map(|i| {
            let f = i as f64 / 40.0;
            TexelPoint { position: [4.0 * f, 0.0, 3.9 - 3.8 * f], normal: UP, geometric_normal: UP, cell: i }
        })
        .collect();
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| bake_points(&tr, &points, false, "t").unwrap())
    };
    let (a, b) = (run(1), run(2));
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(x.irradiance.map(f64::to_bits), y.irradiance.map(f64::to_bits));
    }
}

#[test]
fn extreme_receivers_stay_finite() {
    let mut s = room();
    // A receiver touching the point light (d → 0), a light very far away (beyond the table's distances),
    // a receiver facing away from everything, and an albedo-1 thick fog.
    s.lights.push(point_light("far", [1e5, 1e4, 0.0], 1e9));
    s.media[0].sigma_s = [2.0; 3];
    s.media[0].sigma_a = [0.0; 3];
    let bvh = SceneBvh::build(&s);
    for mode in [BakeMode::Surface, BakeMode::Shadow, BakeMode::Full] {
        let tr = Transport::new(&s, &bvh, Some(table()), opts(mode, 8, 2)).unwrap();
        for (x, n) in
            [([2.0, 2.0, 2.0], UP), ([2.0, 2.0 - 1e-9, 2.0], [0.0, -1.0, 0.0]), ([1.0, 0.0, 1.0], [0.0, -1.0, 0.0])]
        {
            let e = tr.receiver(x, n, n, 0).unwrap();
            assert!(e.irradiance.iter().all(|v| v.is_finite() && *v >= 0.0), "{mode:?} {x:?}: {e:?}");
            assert!(e.rel_stderr.is_finite());
        }
        // The inverse square is capped at MIN_DISTANCE: a receiver on the light sees at most I / d_min².
        let e = tr.receiver([2.0, 2.0, 2.0], UP, UP, 0).unwrap();
        assert!(e.irradiance[0] <= 1.0 / (MIN_DISTANCE * MIN_DISTANCE) * 1.01 + 1e3);
    }
}

#[test]
fn probe_of_a_point_light_in_vacuum_is_its_delta_projected() {
    let mut s = empty("v.gltf");
    s.lights.push(point_light("L", [1.0, 2.0, 2.0], 9.0));
    let bvh = SceneBvh::build(&s);
    let tr = Transport::new(&s, &bvh, None, opts(BakeMode::Surface, 4, 0)).unwrap();
    let sh: [[f64; super::transport::PROBE_SH]; 3] = tr.probe([0.0; 3], 0).unwrap();
    // Distance 3, direction (1, 2, 2)/3: coefficients 9/9 · y_i(ω).
    let y = crate::physics::sh::sh_eval(3, [1.0 / 3.0, 2.0 / 3.0, 2.0 / 3.0]);
    for (c, coefs) in sh.iter().enumerate() {
        for (i, (got, want)) in coefs.iter().zip(&y).enumerate() {
            assert!((got - want).abs() < 1e-12, "c {c} i {i}: {got} vs {want}");
        }
    }
    // y_0 = 1/(2√π): the DC term of a unit delta.
    assert!((sh[0][0] - 0.5 / PI.sqrt()).abs() < 1e-12);
}

#[test]
fn querying_scattered_light_on_a_subset_of_samples_keeps_the_mean() {
    // Terms with several table queries (scattered light from a surface that was itself lit by
    // scattered light) must carry the subset's weight once: the mean with 1/8 of the samples queried
    // equals the mean with all queried, within the combined standard errors.
    let s = room();
    let bvh = SceneBvh::build(&s);
    let run = |scatter| {
        let o = TransportOptions { scatter_samples: scatter, ..opts(BakeMode::Full, 2048, 2) };
        Transport::new(&s, &bvh, Some(table()), o).unwrap().receiver([1.0, 0.0, 3.0], UP, UP, 11).unwrap()
    };
    let (all, some) = (run(2048), run(256));
    let (a, b) = (all.irradiance[1], some.irradiance[1]);
    let sigma = (all.rel_stderr * a).hypot(some.rel_stderr * b);
    assert!((a - b).abs() < 4.0 * sigma, "{a} vs {b} ± {sigma}");
    assert!(some.rel_stderr > all.rel_stderr);
}

/// A closed, index-matched box of fog from `lo` to `hi` (outward triangles), medium index 0.
fn fog_box(s: &mut Scene, lo: [f32; 3], hi: [f32; 3], sigma_s: f64, sigma_a: f64) {
    let mut b = cuboid("fogbox", lo, hi);
    b.normals.clear();
    b.material = Some(s.materials.len());
    s.materials.push(Material {
        name: "matched".into(),
        base_color: [1.0; 3],
        emission: [0.0; 3],
        surface: Surface::Dielectric { ior: 1.0 },
        roughness: 0.0,
    });
    let mesh = s.meshes.len();
    b.medium = Some(s.media.len());
    s.meshes.push(b);
    let mut m = medium("box fog", sigma_s, Boundary::Mesh(mesh));
    m.sigma_a = [sigma_a; 3];
    m.g = [0.0; 3];
    s.media.push(m);
}

#[test]
fn light_outside_a_fog_box_is_attenuated_by_the_chord_only() {
    // Receiver inside a 2 m fog box at its centre, light 3 m above outside it: the segment crosses
    // 1 m of fog (σ_t = 0.5) and 2 m of vacuum.
    let mut s = empty("box.gltf");
    fog_box(&mut s, [-1.0, -1.0, -1.0], [1.0, 1.0, 1.0], 0.3, 0.2);
    s.lights.push(point_light("L", [0.0, 3.0, 0.0], 4.0));
    let bvh = SceneBvh::build(&s);
    let sh =
        Transport::new(&s, &bvh, None, opts(BakeMode::Shadow, 1, 0)).unwrap().receiver([0.0; 3], UP, UP, 0).unwrap();
    let expected = 4.0 / 9.0 * (-0.5f64).exp();
    assert!(rel(sh.irradiance[0], expected) < 1e-4, "{} vs {expected}", sh.irradiance[0]);
    // Full queries the table with the segment's effective coefficients (σ_s = 0.3/3, σ_a = 0.2/3 per m):
    // direct equal to Shadow, scattered light added.
    let fu = Transport::new(&s, &bvh, Some(table()), opts(BakeMode::Full, 1, 0))
        .unwrap()
        .receiver([0.0; 3], UP, UP, 0)
        .unwrap();
    let q = table()
        .irradiance(
            &HomogeneousMedium { sigma_s: 0.1, sigma_a: 0.2 / 3.0, g: 0.0 },
            &Emitter::Point { intensity: 1.0, position: [0.0, 3.0, 0.0] },
            &Receiver { position: [0.0; 3], normal: UP },
            &QueryOptions { backscatter: false, similarity: true, ..QueryOptions::default() },
        )
        .unwrap();
    assert!(rel(fu.irradiance[0], 4.0 * q.total) < 1e-3, "{} vs {}", fu.irradiance[0], 4.0 * q.total);
    // A light inside the box and a receiver outside: the same chord, the same transmittance.
    let mut s2 = empty("box2.gltf");
    fog_box(&mut s2, [-1.0, -1.0, -1.0], [1.0, 1.0, 1.0], 0.3, 0.2);
    s2.lights.push(point_light("L", [0.0, 0.0, 0.0], 4.0));
    let bvh2 = SceneBvh::build(&s2);
    let down = [0.0, -1.0, 0.0];
    let e = Transport::new(&s2, &bvh2, None, opts(BakeMode::Shadow, 1, 0))
        .unwrap()
        .receiver([0.0, 3.0, 0.0], down, down, 0)
        .unwrap();
    assert!(rel(e.irradiance[0], expected) < 1e-4, "{} vs {expected}", e.irradiance[0]);
}

#[test]
fn texels_inside_a_closed_opaque_box_see_only_what_is_inside() {
    // A receiver on the floor inside a closed opaque box with the light outside gets nothing in every
    // mode (the light is occluded, so no scattered light is connected either); a receiver on the box's
    // outer face, facing the light, is lit.
    let mut s = room();
    s.meshes.push(cuboid("crate", [0.5, 0.0, 0.5], [1.5, 1.0, 1.5]));
    let bvh = SceneBvh::build(&s);
    for mode in [BakeMode::Surface, BakeMode::Shadow, BakeMode::Full] {
        let tr = Transport::new(&s, &bvh, Some(table()), opts(mode, 16, 2)).unwrap();
        let inside = tr.receiver([1.0, 0.0, 1.0], UP, UP, 1).unwrap();
        assert_eq!(inside.irradiance, [0.0; 3], "{mode:?}");
        let top = tr.receiver([1.0, 1.0, 1.0], UP, UP, 1).unwrap();
        assert!(top.irradiance.iter().all(|&v| v > 0.0), "{mode:?}: {top:?}");
        // The underside of the crate's lid seen from below (a back face toward the light) is dark too.
        let lid = tr.receiver([1.0, 1.0 - 1e-4, 1.0], [0.0, -1.0, 0.0], [0.0, -1.0, 0.0], 1).unwrap();
        assert_eq!(lid.irradiance, [0.0; 3], "{mode:?}");
    }
}

/// dubouchet2019 Fig. 8's failure case, measured: a binary density jump (a dense fog box, σ_s = 3 /m,
/// albedo 1, inside the room's thin global fog) between the lights and the floor. The table sees each
/// segment as homogeneous with its effective σ, so single and multiple scattering are approximate there.
/// Run with `cargo test --release -- --ignored binary_density_jump --nocapture` to print the errors.
#[test]
#[ignore = "measurement (≈ 1 min): errors of every mode against volpath at a binary density jump"]
fn binary_density_jump_error_against_the_reference() {
    use crate::reference::volpath::{SurfacePoint, VolPathOptions, irradiance};
    let mut s = room();
    fog_box(&mut s, [1.0, 0.5, 1.0], [3.0, 1.5, 3.0], 3.0, 0.0);
    let bvh = SceneBvh::build(&s);
    let points: Vec<TexelPoint> = (0u32..64)
        .map(|i| {
            let (a, b) = (f64::from(i % 8), f64::from(i / 8));
            TexelPoint {
                position: [0.25 + 0.5 * a, 0.0, 0.25 + 0.5 * b],
                normal: UP,
                geometric_normal: UP,
                cell: u64::from(i),
            }
        })
        .collect();
    let sp: Vec<SurfacePoint> = points.iter().map(|p| SurfacePoint { position: p.position, normal: UP }).collect();
    let (truth, _) = irradiance(&s, &bvh, &sp, &VolPathOptions { samples: 16384, ..VolPathOptions::default() });
    let truth: Vec<[f64; 3]> = truth.iter().map(|e| e.mean).collect();
    let mut ratios = Vec::new();
    for mode in [BakeMode::Surface, BakeMode::Shadow, BakeMode::Full] {
        let tr = Transport::new(&s, &bvh, Some(table()), opts(mode, 512, 5)).unwrap();
        let est: Vec<[f64; 3]> = bake_points(&tr, &points, false, "").unwrap().iter().map(|e| e.irradiance).collect();
        let e = super::report::rel_rmse(&est, &truth);
        let ratio = super::report::mean_luminance(&est) / super::report::mean_luminance(&truth);
        eprintln!("binary density jump, {mode:?}: relative RMSE {e:.4}, mean ratio {ratio:.4}");
        assert!(e.is_finite() && ratio.is_finite());
        ratios.push(ratio);
    }
    // Shadow drops all scattered light, so it lies below the truth; Full's infinite-medium responses see
    // the finite dense box as unbounded albedo-1 fog that returns all its light, so they overshoot
    // (measured: Surface 2.12, Shadow 0.29, Full 2.13 × the reference mean). The failure is reported,
    // not hidden: the truth is bracketed by the two modes.
    assert!(ratios[1] < 1.0 && ratios[2] > 1.0, "{ratios:?}");
}
