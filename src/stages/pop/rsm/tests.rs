use super::*;
use crate::physics::medium::RgbMedium;
use crate::scene::fixtures::{cuboid, empty};
use crate::scene::{Material, Surface};

/// A 2 m × 2 m floor (top at y = 0, albedo `k`) and POP's medium box above it up to `top`.
fn floor(k: Rgb, top: f64, sigma_s: Rgb, sigma_a: Rgb) -> (Scene, SceneBvh, VoxelMedium) {
    let mut s = empty("rsm.usda");
    s.materials.push(Material {
        name: "Floor".into(),
        base_color: k,
        emission: [0.0; 3],
        surface: Surface::Opaque,
        roughness: 1.0,
    });
    let mut m = cuboid("Floor", [-1.0, -0.1, -1.0], [1.0, 0.0, 1.0]);
    m.material = Some(0);
    s.meshes.push(m);
    let bvh = SceneBvh::build(&s);
    let medium = VoxelMedium::homogeneous(
        DVec3::new(-1.0, -0.1, -1.0),
        DVec3::new(1.0, top, 1.0),
        RgbMedium { sigma_s, sigma_a, g: [0.0; 3] },
    )
    .unwrap();
    (s, bvh, medium)
}

/// Sun straight down through 1 m of an absorbing, scattering medium onto the floor: the map reflects
/// `k_c E_c A e^{−σ_t,c·1 m}` with `A = 4 m²` (the texels tile the box's projection, the floor fills
/// it; transmittance exact in a homogeneous medium).
#[test]
fn directional_map_reflects_albedo_times_attenuated_power() {
    let (k, e, ss, sa) = ([0.2, 0.5, 0.9], [3.0, 2.0, 1.0], [0.2, 0.3, 0.4], [0.1, 0.0, 0.05]);
    let (s, bvh, medium) = floor(k, 1.0, ss, sa);
    let light = DirectionalLight { direction: DVec3::new(0.0, -1.0, 0.0), irradiance: e };
    let map = directional_rsm(&albedos(&s, &bvh), &bvh, &medium, &light, 64);
    assert_eq!(map.len(), 64 * 64);
    let flux = total_flux(std::slice::from_ref(&map));
    for c in 0..3 {
        let want = k[c] * e[c] * 4.0 * (-(ss[c] + sa[c])).exp();
        // 1e-7: the hit points come from the BVH's f32 triangles.
        assert!((flux[c] - want).abs() < 1e-7 * want, "channel {c}: {} vs {want}", flux[c]);
    }
    for t in map.iter().flatten() {
        assert!(t.position.y.abs() < 1e-6 && t.normal == DVec3::Y, "{t:?}");
    }
}

/// A point light `I` 0.5 m above the floor's centre in vacuum: the map reflects `k I Ω` with `Ω` the
/// floor's solid angle, `4 asin(ab/√((a² + h²)(b² + h²)))` for half-sides `a = b = 1` at `h = 0.5`; the
/// floor's sides face out of the box and reflect nothing into it. Equal-area texels: the error is
/// the map's staircase along the floor's edges (measured +4.1e-4 at 256² texels; bound 3e-3).
#[test]
fn point_map_reflects_the_floor_solid_angle() {
    let (s, bvh, medium) = floor([0.5; 3], 1.0, [0.0; 3], [0.0; 3]);
    let i = 2.0;
    let light = PointLight { position: DVec3::new(0.0, 0.5, 0.0), intensity: [i; 3], spot: None, normal: None };
    let map = point_rsm(&albedos(&s, &bvh), &bvh, &medium, &light, 256);
    let omega = 4.0 * (1.0f64 / 1.25).asin();
    let want = 0.5 * i * omega;
    let flux = total_flux(&[map]);
    assert!((flux[0] - want).abs() < 3e-3 * want, "{} vs {want}", flux[0]);
}

/// Light the outside of the medium's box reflects never enters it: a floor whose top is the box's top
/// face reflects nothing (the stage would otherwise put VPLs on a room's roof).
#[test]
fn surfaces_facing_out_of_the_box_reflect_nothing() {
    let (s, bvh, medium) = floor([0.8; 3], 0.0, [0.1; 3], [0.0; 3]);
    let light = DirectionalLight { direction: DVec3::new(0.3, -1.0, 0.2), irradiance: [1.0; 3] };
    let map = directional_rsm(&albedos(&s, &bvh), &bvh, &medium, &light, 32);
    assert!(map.iter().all(Option::is_none));
    assert!(sample_vpls(&[map], 8, 1e-4).is_empty());
}

/// The VPLs carry the maps' flux: `π Σ I` equals the total per channel for grey texels and in
/// luminance for coloured ones; each sits on its texel, lifted along its normal; the placement is
/// deterministic and proportional to flux (a texel with 3/4 of the flux gets 3 of 4 VPLs).
#[test]
fn vpls_carry_the_reflected_flux() {
    let t = |x: f64, flux: Rgb| Some(RsmTexel { position: DVec3::new(x, 0.0, 0.0), normal: DVec3::Y, flux });
    let grey = vec![vec![t(0.0, [3.0; 3]), None, t(1.0, [1.0; 3])]];
    let v = sample_vpls(&grey, 4, 0.01);
    assert_eq!(v.len(), 4);
    assert_eq!(v.iter().filter(|p| p.position.x == 0.0).count(), 3);
    for p in &v {
        assert!((p.position.y - 0.01).abs() < 1e-15 && p.normal == Some(DVec3::Y) && p.spot.is_none());
    }
    for c in 0..3 {
        let sum: f64 = v.iter().map(|p| p.intensity[c] * std::f64::consts::PI).sum();
        assert!((sum - 4.0).abs() < 1e-12, "{sum}");
    }
    let coloured = vec![vec![t(0.0, [1.0, 0.2, 0.1])], vec![t(2.0, [0.1, 0.3, 2.0])]];
    let v = sample_vpls(&coloured, 16, 0.0);
    let lum: f64 = v.iter().map(|p| luminance(p.intensity) * std::f64::consts::PI).sum();
    let want = luminance(total_flux(&coloured));
    assert!((lum - want).abs() < 1e-12 * want, "{lum} vs {want}");
    assert_eq!(v, sample_vpls(&coloured, 16, 0.0));
    assert!(sample_vpls(&coloured, 0, 0.0).is_empty());
    assert!(sample_vpls(&[vec![None, t(0.0, [0.0; 3])]], 4, 0.0).is_empty());
}
