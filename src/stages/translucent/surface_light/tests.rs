use super::*;
use crate::render::dielectric::Emitter;
use crate::scene::bvh::SceneBvh;
use crate::scene::bvh::procedural::icosphere;
use crate::scene::fixtures::empty;
use crate::stages::translucent::octree::Item;
use crate::tables::ms_lobes::{MediumChannel, MsLobes, MsLobesTable};

/// Inside a sphere of radius `R` every pair of points sees each other with
/// `cos_e cos_r / q² = 1/(4R²)`, so a uniform Lambertian exitance `S` on the inner surface irradiates
/// each of `N` equal-area samples with `S (N − 1)/N` (the other samples' share of `4πR²`). In a medium
/// that neither scatters nor attenuates noticeably each reflection returns `f (N − 1)/N` of the
/// light, so the series sums to `S₀ / (1 − f (N − 1)/N)` (less the tolerance's tail). The cut
/// aggregates distant samples into nodes (area-weighted centroid and normal), which is the error
/// measured here.
#[test]
fn series_of_reflections_in_a_sphere_is_geometric() {
    let def = MsLobes {
        materials: Vec::new(),
        g: vec![0.0],
        albedo_grid: 0,
        albedos: vec![0.0, 0.5],
        rho_max: 4.0,
        z_min: -2.0,
        z_max: 4.0,
        rho_bins: 8,
        z_bins: 12,
        theta_bins: 5,
        photons: 1 << 10,
        max_order: 8,
        ..MsLobes::default()
    };
    let g = def.generate(&[4; 32], &|_| {}).unwrap();
    let table = MsLobesTable::from_arrays(&def, &g.arrays, &g.values).unwrap();
    let r = 0.1;
    let mut scene = empty("surface_light.usda");
    scene.meshes = vec![icosphere("Ball", [0.0; 3], r, 3)];
    let bvh = SceneBvh::build(&scene);
    let material = Material { sigma_t: [1e-6; 3], albedo: [0.0; 3], g: 0.0, ior: 1.5 };
    let em: [Emitter; 0] = [];
    let setup = Setup { scene: &scene, bvh: &bvh, object: 0, material, emitters: &em };
    // Fibonacci points on a sphere just inside the mesh's facets, equal areas, outward normals.
    let rs = 0.995 * r;
    let n = 1024;
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let samples: Vec<SurfaceSample> = (0..n)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let rr = (1.0 - y * y).sqrt();
            let u = DVec3::new(rr * (golden * i as f64).cos(), y, rr * (golden * i as f64).sin());
            SurfaceSample {
                position: u * rs,
                normal: u,
                area: 4.0 * std::f64::consts::PI * rs * rs / n as f64,
                triangle: 0,
                direct: [0.0; 3],
                indirect: [1.0, 2.0, 0.0],
            }
        })
        .collect();
    let items: Vec<Item> =
        samples.iter().map(|s| Item { position: s.position, bounds: (s.position, s.position) }).collect();
    let tree = Octree::build(&items, 8, 24);
    let slices: Vec<_> =
        (0..3).map(|_| table.slice(&MediumChannel { albedo: 0.0, sigma_t: 1e-6, g: 0.0 }).unwrap()).collect();
    let e_vol = vec![[0.0; 3]; n];
    let (f_out, f_in) = (0.1, 0.6);
    // One reflection: what wang2018 keeps.
    let one = emission(&setup, &samples, &tree, &slices, &e_vol, (f_out, f_in), 0.5, [0.0; 3], 1).unwrap();
    assert_eq!(one.terms, 1);
    assert!(one.exitance.iter().all(|e| e[0] == 0.9 && e[1] == 1.8 && e[2] == 0.0));
    // Two terms: the first reflection's irradiance is (N − 1)/N of the exitance.
    let two = emission(&setup, &samples, &tree, &slices, &e_vol, (f_out, f_in), 0.5, [0.0; 3], 2).unwrap();
    let view = (n as f64 - 1.0) / n as f64;
    let mut worst: f64 = 0.0;
    for e in &two.exitance {
        worst = worst.max(((e[0] - 0.9) / (0.9 * f_in) / view - 1.0).abs());
        assert_eq!(e[2], 0.0);
    }
    assert!(worst < 0.02, "view factor off by {worst}");
    let all = emission(&setup, &samples, &tree, &slices, &e_vol, (f_out, f_in), 0.5, [0.0; 3], SERIES_MAX).unwrap();
    let exact = 0.9 / (1.0 - f_in * view);
    let mean = all.exitance.iter().map(|e| e[0]).sum::<f64>() / n as f64;
    assert!(all.terms > 10 && all.terms < SERIES_MAX, "{} terms", all.terms);
    assert!((mean / exact - 1.0).abs() < 0.02, "series {mean} vs {exact}");
    // Chords cross the ball: between the inner and the outer diameter of the faceted mesh.
    assert!(
        all.chord.iter().all(|&d| d > 1.98 * r && d < 2.0 * r),
        "{:?}",
        all.chord.iter().fold(f64::INFINITY, |a, &b| a.min(b))
    );
}
