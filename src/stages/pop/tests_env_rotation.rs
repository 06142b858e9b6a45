//! Rotated environment maps (a USD `DomeLight`'s transform, `EnvMap::with_rotation`): the unrotated
//! convention is OpenEXR's latitude–longitude map (which UsdLux quotes for domes), directions follow the
//! rotation exactly, the energy does not change, and `dome_map` turns a scene's dome into a map.

#![allow(clippy::needless_range_loop)] // per-channel loops over parallel arrays read clearer indexed

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use glam::{DMat3, DQuat, DVec3};

use super::environment::{self, OrdinateSet};
use crate::render::color::Rgb;
use crate::render::environment::{
    self as env_map, EnvMap, EnvMapError, EnvSampler, UNIFORM_DOME_SIZE, dome_map, procedural_sky,
};
use crate::scene::EnvironmentLight;

/// OpenEXR's latitude–longitude map as the UsdLux DomeLight documentation quotes it, written here from
/// that text alone: pixel x runs from longitude +π (left edge) to −π (right edge), y from latitude +π/2
/// (top) to −π/2 (bottom), and the direction of latitude φ, longitude λ is `(cos φ sin λ, sin φ,
/// cos φ cos λ)` (longitude 0 → +Z, π/2 → +X, latitude +π/2 → +Y). Texel centres.
fn openexr_direction(col: usize, row: usize, w: usize, h: usize) -> DVec3 {
    let lon = PI - TAU * (col as f64 + 0.5) / w as f64;
    let lat = FRAC_PI_2 - PI * (row as f64 + 0.5) / h as f64;
    DVec3::new(lat.cos() * lon.sin(), lat.sin(), lat.cos() * lon.cos())
}

/// USD's `rotateY` by `deg` degrees (right-handed about +Y: +Z turns toward +X).
fn rotate_y(deg: f64) -> DMat3 {
    let (s, c) = deg.to_radians().sin_cos();
    DMat3::from_cols(DVec3::new(c, 0.0, -s), DVec3::Y, DVec3::new(s, 0.0, c))
}

/// `rotate_y(90)` spelled exactly: +X → −Z, +Z → +X.
const RY90: DMat3 = DMat3::from_cols(DVec3::NEG_Z, DVec3::Y, DVec3::X);

fn arbitrary_rotation() -> DMat3 {
    DMat3::from_quat(DQuat::from_axis_angle(DVec3::new(1.0, 2.0, -0.5).normalize(), 0.7))
}

/// A rotation composed with a mirror (x → −x): orthogonal with determinant −1.
fn mirrored() -> DMat3 {
    arbitrary_rotation() * DMat3::from_diagonal(DVec3::new(-1.0, 1.0, 1.0))
}

fn sky(w: usize, h: usize) -> EnvMap {
    let sun = DVec3::new(0.3, 0.8, -0.4).normalize();
    EnvMap::from_fn(w, h, |d| procedural_sky(d, Some((sun, 0.05, [400.0, 380.0, 340.0])))).unwrap()
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(1e-300)
}

/// `Σ_t L_t ∫_t ω dω` per channel: the net flux vector of the map (exact texel integrals).
fn flux(env: &EnvMap) -> [DVec3; 3] {
    let mut f = [DVec3::ZERO; 3];
    for t in 0..env.width * env.height {
        let m = env.texel_moment(t % env.width, t / env.width);
        for c in 0..3 {
            f[c] += m * env.radiance[t][c];
        }
    }
    f
}

#[test]
fn the_unrotated_map_is_openexr_latlong() {
    let (w, h) = (16, 8);
    let env = EnvMap::uniform(w, h, [1.0; 3]).unwrap();
    for t in 0..w * h {
        let (c, r) = (t % w, t / w);
        let d = env.texel_direction(c, r);
        assert!((d - openexr_direction(c, r, w, h)).length() < 1e-14, "texel ({c}, {r}): {d}");
    }
    assert_eq!(env.rotation(), DMat3::IDENTITY);
}

#[test]
fn rotated_maps_turn_every_direction_and_keep_the_energy() {
    for rot in [RY90, arbitrary_rotation(), mirrored()] {
        let base = sky(64, 32);
        let env = base.clone().with_rotation(rot).unwrap();
        assert_eq!(env.rotation(), rot);
        assert_eq!(env.radiance, base.radiance, "no resampling");
        for t in 0..64 * 32 {
            let (c, r) = (t % 64, t / 64);
            let d = env.texel_direction(c, r);
            assert!((d - rot * base.texel_direction(c, r)).length() < 1e-14, "{rot} texel {t}");
            assert_eq!(env.texel_of(d), (c, r), "{rot} texel {t}");
            assert!((env.texel_moment(c, r) - rot * base.texel_moment(c, r)).length() < 1e-15);
        }
        // Energy: the same texels with the same solid angles; the flux vector turns with the map.
        assert_eq!(env.integral(), base.integral());
        let (fb, fr) = (flux(&base), flux(&env));
        for c in 0..3 {
            assert!((fr[c] - rot * fb[c]).length() < 1e-12 * fb[c].length(), "{rot} channel {c}");
        }
        // The sampler draws rotated directions with the unrotated density: ∫ L dω by importance
        // sampling through the rotated look-up is the map's integral.
        let (s, s_base) = (EnvSampler::new(&env), EnvSampler::new(&base));
        let n = 100_000u64;
        let mut est = [0.0; 3];
        for i in 0..n {
            let (u1, u2, u3) =
                ((i as f64 + 0.5) / n as f64, ((i * 7919) % n) as f64 / n as f64, (i as f64 * 0.618_034).fract());
            let (w, pdf) = s.sample(u1, u2, u3);
            let (wb, pdf_base) = s_base.sample(u1, u2, u3);
            assert_eq!(pdf, pdf_base);
            assert!((w - rot * wb).length() < 1e-14);
            let l = env.lookup(w);
            for c in 0..3 {
                est[c] += l[c] / pdf / n as f64;
            }
        }
        let exact = env.integral();
        for c in 0..3 {
            assert!(rel(est[c], exact[c]) < 2e-3, "{rot} channel {c}: {} vs {}", est[c], exact[c]);
        }
        // The ordinates of the rotated map are the rotated ordinates of the map, with the same energies.
        {
            let set = OrdinateSet::Importance;
            let (ob, or) = (environment::ordinates(&base, 16, set), environment::ordinates(&env, 16, set));
            assert_eq!(ob.len(), or.len());
            for (a, b) in ob.iter().zip(&or) {
                assert!((DVec3::from(b.direction) - rot * DVec3::from(a.direction)).length() < 1e-12, "{rot}");
                for c in 0..3 {
                    assert!(rel(b.irradiance[c], a.irradiance[c]) < 1e-12, "{rot}");
                }
                assert!((b.anisotropy - a.anisotropy).abs() < 1e-12);
            }
        }
    }
}

#[test]
fn a_bright_texel_lands_where_the_dome_rotation_puts_it() {
    // One bright texel at column 40, row 10 of a 64 × 32 map. By the OpenEXR text its centre has
    // longitude λ = π − 2π·40.5/64 = −17π/64 and latitude φ = π/2 − π·10.5/32 = 11π/64, so it looks
    // toward (cos φ sin λ, sin φ, cos φ cos λ); rotateY(90°) sends (x, y, z) to (z, y, −x):
    // (cos(11π/64) cos(17π/64), sin(11π/64), cos(11π/64) sin(17π/64)).
    let (lat, lon) = (11.0 * PI / 64.0, 17.0 * PI / 64.0);
    let want = DVec3::new(lat.cos() * lon.cos(), lat.sin(), lat.cos() * lon.sin());
    let mut l = vec![[0.0; 3]; 64 * 32];
    l[10 * 64 + 40] = [1000.0, 500.0, 250.0];
    for rot in [RY90, rotate_y(90.0)] {
        let env = EnvMap::new(64, 32, l.clone()).unwrap().with_rotation(rot).unwrap();
        assert!((env.texel_direction(40, 10) - want).length() < 1e-14);
        assert_eq!(env.texel_of(want), (40, 10));
        assert_eq!(env.lookup(want), [1000.0, 500.0, 250.0]);
        let ords = environment::ordinates(&env, 8, OrdinateSet::Importance);
        let bright = ords.iter().max_by(|a, b| a.irradiance[1].total_cmp(&b.irradiance[1])).unwrap();
        // The ordinate points along the texel's mean direction, within a thousandth of a radian of its
        // centre (the mean leans toward the equator by ~Δθ²·cot θ / 12 ≈ 5e-4).
        let angle = (-DVec3::from(bright.direction)).angle_between(want);
        assert!(angle < 1e-3, "{angle} rad off");
        // Its irradiance is the texel's radiance × its exact solid angle (2π/64)(cos(10π/32) − cos(11π/32)).
        let omega = TAU / 64.0 * ((10.0 * PI / 32.0).cos() - (11.0 * PI / 32.0).cos());
        assert!(rel(bright.irradiance[0], 1000.0 * omega) < 1e-12);
        assert!(rel(bright.irradiance[2], 250.0 * omega) < 1e-12);
    }
}

#[test]
fn non_rotations_and_bad_tints_are_refused() {
    let base = EnvMap::uniform(8, 4, [1.0; 3]).unwrap();
    let e = base.clone().with_rotation(DMat3::from_diagonal(DVec3::splat(2.0))).unwrap_err();
    assert!(e.to_string().contains("not orthogonal"), "{e}");
    let e = base.clone().with_rotation(DMat3::from_cols(DVec3::X, DVec3::Y, DVec3::new(0.0, 0.1, 1.0))).unwrap_err();
    assert!(e.to_string().contains("not orthogonal"), "{e}");
    let e = base.clone().with_rotation(DMat3::from_diagonal(DVec3::new(f64::NAN, 1.0, 1.0))).unwrap_err();
    assert!(matches!(e, EnvMapError::RotationNotFinite(_)), "{e}");
    // The identity is no rotation: the map is unchanged bit for bit.
    assert_eq!(base.clone().with_rotation(DMat3::IDENTITY).unwrap(), base);
    assert!(base.clone().tinted([1.0, -1.0, 1.0]).unwrap_err().to_string().contains("non-negative"));
    assert!(base.clone().tinted([f64::INFINITY, 1.0, 1.0]).is_err());
    // A side too large is refused before anything is allocated.
    assert!(EnvMap::uniform(env_map::MAX_SIDE + 1, 1, [1.0; 3]).is_err());
}

#[test]
fn dome_maps_are_texture_times_scale_times_colour_rotated() {
    let d = tempfile::tempdir().unwrap();
    let path = d.path().join("dome.exr");
    let px: Vec<[f32; 3]> = (0..8 * 4).map(|i| [i as f32, 0.5, 2.0]).collect();
    crate::image_io::write_exr_rgb(&path, 8, 4, &px, &[]).unwrap();
    let rot = arbitrary_rotation();
    let dome = |texture: Option<std::path::PathBuf>| EnvironmentLight {
        name: "/Sky".into(),
        texture,
        scale: 0.25,
        color: [1.0, 2.0, 4.0],
        rotation: [rot.x_axis.to_array(), rot.y_axis.to_array(), rot.z_axis.to_array()],
    };
    let map = dome_map(&dome(Some(path.clone()))).unwrap();
    assert_eq!((map.width, map.height), (8, 4));
    assert_eq!(map.rotation(), rot);
    for (i, v) in map.radiance.iter().enumerate() {
        // Powers of two: exact.
        assert_eq!(*v, [i as f64 * 0.25, 0.5 * 0.25 * 2.0, 2.0 * 0.25 * 4.0], "texel {i}");
    }
    // Without a texture: a uniform map of colour × scale, whose integral is 4π times it.
    let uniform = dome_map(&dome(None)).unwrap();
    assert_eq!([uniform.width, uniform.height], UNIFORM_DOME_SIZE);
    let want: Rgb = [0.25, 0.5, 1.0];
    for c in 0..3 {
        assert!(rel(uniform.integral()[c], 4.0 * PI * want[c]) < 1e-12);
    }
    // A missing texture: the error names the file.
    let e = dome_map(&dome(Some(d.path().join("missing.exr")))).unwrap_err();
    assert!(e.to_string().contains("missing.exr"), "{e}");
    let bad = EnvironmentLight { scale: f64::NAN, ..dome(None) };
    assert!(matches!(dome_map(&bad), Err(EnvMapError::DomeScale(s)) if s.is_nan()));
}
