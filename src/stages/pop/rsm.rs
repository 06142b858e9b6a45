//! Reflective shadow maps → VPLs for the light the scene's surfaces reflect into the medium (elek2014
//! Sec. 6, "Instant radiosity": "we generate VPLs using a reflective shadow map (RSM) for every primary
//! light. We importance-sample these RSMs according to surface albedo and (attenuated) irradiance").
//!
//! **Input → output.** The scene's surfaces (its BVH and Lambertian materials), POP's voxel medium and
//! the primary lights POP propagates (directional lights, and point, spot, sphere lights and the VPLs of
//! area lights) → per light a reflective shadow map ([`directional_rsm`], [`point_rsm`]): per texel the
//! first surface the light reaches, its normal turned toward the light, and the flux it reflects,
//! `Φ_c = ρ_c Φ_in,c T_c` (`ρ` the surface's albedo, `Φ_in` the light's flux through the texel, `T` the
//! medium's transmittance from the light to the surface) → [`sample_vpls`]: `k` Lambertian VPLs drawn
//! from all maps together in proportion to the reflected flux's luminance, each carrying `1/k` of the
//! total luminance (its colour its texel's), with intensity `Φ/π` along its normal — a Lambertian
//! reflector of flux `Φ`. They then propagate on radial grids like any point light; the ray marcher
//! takes their uncollided light from the grid's cell means
//! ([`super::radial_propagate::uncollided_toward_eye`]), which bounds the glow around each VPL without
//! losing energy (the paper clamps instead).
//!
//! **Texels.** A directional light's map is a `side × side` orthographic grid over the medium box's
//! projection onto the plane facing the light; each texel's flux is `E_c · A_texel` (`E` the light's
//! irradiance, `A` the texel's projected area). A point light's map is the `side × side` equal-area
//! octahedral grid around it ([`super::octa`]); each texel's flux is `I_c profile(ω) · 4π/side²`.
//! Texels whose ray meets no surface, a refractive or index-matched surface (POP's surfaces only
//! reflect diffusely), a black one, or a surface facing out of the medium's box (the outside of a
//! room's walls: its light never enters the medium) reflect nothing.
//!
//! **Sampling.** Texels are ordered along a Morton curve within each map and the maps concatenated, and
//! the `k` VPLs take the texels at the stratified points `(j + ½)/k` of the cumulative luminance: the
//! strata are contiguous runs of the curve, so the VPLs spread over the lit surfaces the way the flux
//! does, deterministically. The VPLs' total flux equals the maps' (per channel exactly when every texel
//! has the same chromaticity, in luminance always).
//!
//! **Scope.** One bounce of direct light: surfaces lit by the medium's scattered light, by the
//! environment, or by other surfaces reflect nothing here (the stage's path-traced reference is
//! restricted to the same single reflection, `surface_bounces = 1`). Albedo is the material's base
//! colour (textures ignored; a mesh without material is 0.8 grey), as in voltab's path tracer.

use glam::{DVec2, DVec3};
use rayon::prelude::*;

use super::octa;
use super::radial_propagate::PointLight;
use crate::render::color::Rgb;
use crate::render::color::luminance;
use crate::render::voxel::{DirectionalLight, VoxelMedium};
use crate::scene::Scene;
use crate::scene::bvh::{Ray, SceneBvh, SurfaceResponse};

/// One texel of a reflective shadow map: the surface point the light reaches and what it reflects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RsmTexel {
    /// Surface point \[m\].
    pub position: DVec3,
    /// Unit normal on the side facing the light.
    pub normal: DVec3,
    /// Reflected flux per channel \[W\].
    pub flux: Rgb,
}

/// Diffuse albedo of each mesh ([`SceneBvh::surface_response`], as voltab's path tracer reads it);
/// `None` for refractive or index-matched surfaces (and meshes bounding a medium without a material),
/// which reflect nothing diffusely.
pub fn albedos(scene: &Scene, bvh: &SceneBvh) -> Vec<Option<Rgb>> {
    (0..scene.meshes.len())
        .map(|i| match bvh.surface_response(scene, i) {
            SurfaceResponse::Lambert(k) => Some(k),
            SurfaceResponse::PassThrough | SurfaceResponse::Dielectric(_) => None,
        })
        .collect()
}

/// `exp(−σ_t,c ∫ρ ds)` from `a` to `b` through the voxel medium: the segment clipped to the medium's box,
/// then the midpoint rule on steps of at most a quarter of the smallest voxel (at most 4096 steps;
/// exact in a homogeneous medium).
pub fn transmittance(medium: &VoxelMedium, a: DVec3, b: DVec3) -> Rgb {
    let len = (b - a).length();
    if !(len > 0.0 && len.is_finite()) {
        return [1.0; 3];
    }
    let d = (b - a) / len;
    let inv = d.recip();
    let (t0, t1) = ((medium.min - a) * inv, (medium.max - a) * inv);
    let enter = t0.min(t1).max_element().max(0.0);
    let exit = t0.max(t1).min_element().min(len);
    if exit.is_nan() || enter.is_nan() || exit <= enter {
        return [1.0; 3];
    }
    let step = 0.25 * medium.voxel_size().min_element();
    let n = (((exit - enter) / step).ceil() as usize).clamp(1, 4096);
    let h = (exit - enter) / n as f64;
    let depth: f64 = (0..n).map(|k| medium.density_at(a + d * (enter + (k as f64 + 0.5) * h))).sum::<f64>() * h;
    [0, 1, 2].map(|c| (-(medium.coefficients.sigma_s[c] + medium.coefficients.sigma_a[c]) * depth).exp())
}

/// The texel a ray from `origin` along unit `dir` produces carrying incident flux `flux_in` (module doc).
fn texel(
    scene_albedo: &[Option<Rgb>],
    bvh: &SceneBvh,
    medium: &VoxelMedium,
    (origin, dir): (DVec3, DVec3),
    flux_in: Rgb,
) -> Option<RsmTexel> {
    if flux_in.iter().all(|f| *f <= 0.0) {
        return None;
    }
    let hit = bvh.closest_hit(&Ray::new(origin.to_array(), dir.to_array()))?;
    let albedo = (*scene_albedo.get(hit.mesh)?)?;
    let p = origin + dir * hit.t;
    let ng = DVec3::from_array(hit.geometric_normal).try_normalize()?;
    let normal = if ng.dot(dir) < 0.0 { ng } else { -ng };
    // Light reflected off the medium's box (e.g. by the outside of a room's walls) never enters it.
    let inside = p + normal * (1e-6 * (medium.max - medium.min).length());
    if inside.cmplt(medium.min).any() || inside.cmpgt(medium.max).any() {
        return None;
    }
    let t = transmittance(medium, origin, p);
    let flux = [0, 1, 2].map(|c| albedo[c] * flux_in[c] * t[c]);
    (p.is_finite() && flux.iter().all(|f| f.is_finite()) && flux.iter().any(|f| *f > 0.0)).then_some(RsmTexel {
        position: p,
        normal,
        flux,
    })
}

/// Texel order along a Morton (Z-order) curve over an `side × side` map: `(x, y)` per position.
fn morton_order(side: usize) -> Vec<(usize, usize)> {
    let spread = |v: usize| {
        let mut x = v as u64 & 0xffff_ffff;
        x = (x | (x << 16)) & 0x0000_ffff_0000_ffff;
        x = (x | (x << 8)) & 0x00ff_00ff_00ff_00ff;
        x = (x | (x << 4)) & 0x0f0f_0f0f_0f0f_0f0f;
        x = (x | (x << 2)) & 0x3333_3333_3333_3333;
        (x | (x << 1)) & 0x5555_5555_5555_5555
    };
    let mut cells: Vec<(usize, usize)> = (0..side * side).map(|i| (i % side, i / side)).collect();
    cells.sort_by_key(|&(x, y)| spread(x) | (spread(y) << 1));
    cells
}

/// The reflective shadow map of a directional light (module doc), texels in Morton order (`None`: no
/// reflecting surface).
pub fn directional_rsm(
    albedo: &[Option<Rgb>],
    bvh: &SceneBvh,
    medium: &VoxelMedium,
    light: &DirectionalLight,
    side: usize,
) -> Vec<Option<RsmTexel>> {
    let Some(d) = light.direction.try_normalize() else { return Vec::new() };
    let side = side.max(1);
    let (t1, t2) = d.any_orthonormal_pair();
    let (lo, hi) = (medium.min, medium.max);
    let corners = (0..8).map(|c| {
        DVec3::new(
            if c & 1 == 0 { lo.x } else { hi.x },
            if c & 2 == 0 { lo.y } else { hi.y },
            if c & 4 == 0 { lo.z } else { hi.z },
        )
    });
    let (mut umin, mut umax) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
    for p in corners {
        let q = DVec2::new(p.dot(t1), p.dot(t2));
        umin = umin.min(q);
        umax = umax.max(q);
    }
    let centre = (lo + hi) * 0.5;
    let back = centre - d * (hi - lo).length();
    let base = back - t1 * back.dot(t1) - t2 * back.dot(t2);
    let cell = (umax - umin) / side as f64;
    let area = cell.x * cell.y;
    let flux_in = light.irradiance.map(|e| e * area);
    morton_order(side)
        .into_par_iter()
        .map(|(x, y)| {
            let u = umin + cell * DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
            let origin = base + t1 * u.x + t2 * u.y;
            texel(albedo, bvh, medium, (origin, d), flux_in)
        })
        .collect()
}

/// The reflective shadow map of a point, spot or sphere light or an area light's VPL (module doc),
/// texels in Morton order over its octahedral map (`None`: no reflecting surface).
pub fn point_rsm(
    albedo: &[Option<Rgb>],
    bvh: &SceneBvh,
    medium: &VoxelMedium,
    light: &PointLight,
    side: usize,
) -> Vec<Option<RsmTexel>> {
    let side = side.max(1);
    let omega = 4.0 * std::f64::consts::PI / (side * side) as f64;
    morton_order(side)
        .into_par_iter()
        .map(|(x, y)| {
            let w = octa::decode(DVec2::new((x as f64 + 0.5) / side as f64, (y as f64 + 0.5) / side as f64));
            let f = light.profile(w) * omega;
            texel(albedo, bvh, medium, (light.position, w), light.intensity.map(|i| i * f))
        })
        .collect()
}

/// `k` Lambertian VPLs from the maps (module doc), each lifted `lift` off its surface along the normal so
/// the surface does not shadow it. No VPL when the maps reflect nothing.
pub fn sample_vpls(maps: &[Vec<Option<RsmTexel>>], k: usize, lift: f64) -> Vec<PointLight> {
    let texels: Vec<(RsmTexel, f64)> = maps
        .iter()
        .flatten()
        .flatten()
        .map(|t| (*t, luminance(t.flux)))
        .filter(|(_, w)| *w > 0.0 && w.is_finite())
        .collect();
    let total: f64 = texels.iter().map(|t| t.1).sum();
    if k == 0 || texels.is_empty() || !(total > 0.0 && total.is_finite()) {
        return Vec::new();
    }
    let share = total / k as f64;
    let (mut i, mut below) = (0, 0.0);
    (0..k)
        .map(|j| {
            let target = (j as f64 + 0.5) * share;
            while i + 1 < texels.len() && below + texels[i].1 < target {
                below += texels[i].1;
                i += 1;
            }
            let (t, w) = texels[i];
            let scale = share / w / std::f64::consts::PI;
            PointLight {
                position: t.position + t.normal * lift,
                intensity: t.flux.map(|f| f * scale),
                spot: None,
                normal: Some(t.normal),
            }
        })
        .collect()
}

/// Total reflected flux per channel of the maps \[W\].
pub fn total_flux(maps: &[Vec<Option<RsmTexel>>]) -> Rgb {
    let mut s = [0.0; 3];
    for t in maps.iter().flatten().flatten() {
        for (sc, f) in s.iter_mut().zip(t.flux) {
            *sc += f;
        }
    }
    s
}

#[cfg(test)]
mod tests;
