//! The object's light on the scene: the caustic and the glow a translucent object throws on the
//! opaque surfaces around it (beyond wang2018, whose renderer shades the scene with shadowed direct
//! light only; docs/design/translucent.md, "The object's light on the scene").
//!
//! **Input → output.** The light rays of [`super::points`] → two photon maps on the scene's opaque
//! diffuse surfaces → the irradiance `E(p, n)` they add to the direct light wherever a camera path or
//! an indirect ray of a surface sample meets an opaque surface.
//!
//! - **Caustic photons.** At every exit facet a light ray meets, its Fresnel-transmitted flux
//!   `Φ·e^{−σ_t s}·(1 − F)` refracts out and is followed to the first surface it meets; an opaque,
//!   non-black one stores a photon. A nearly transparent medium (Oil) focuses the lamp into a bright
//!   spot inside its own shadow, which a shadow ray through the object (blocked) cannot see.
//! - **Glow photons.** Each volume sample scatters `Φ_c(1 − e^{−σ_t,c L})α_c` of its flux. One walk
//!   per volume sample starts at a point of the interval drawn from `σ̄ e^{−σ̄ t}` (σ̄ the smallest
//!   `σ_t`) in a direction drawn from the HG lobe, and goes on by free flights of `σ̄` with
//!   per-channel weights `σ_s,c e^{−σ_t,c t}/(σ̄ e^{−σ̄ t})` (`e^{−(σ_t,c − σ̄)d}` for the flight that
//!   reaches the boundary), Fresnel reflection or refraction chosen with probability `F`, for at most
//!   [`GLOW_EVENTS`] further scattering events (a walk still inside then is dropped: the glow of very
//!   thick, bright media such as Wax is low by the part that needs more events). The photon lands
//!   where the refracted walk meets an opaque surface. Every random number comes from a
//!   counter-based stream keyed by (surface sample, volume sample, dimension).
//! - **Density estimate.** `E(p) = Σ_{i<k} Φ_i/(π r_k²)` over the `k − 1` nearest photons whose
//!   stored normal faces within 60° of the query's and that lie within `r_max/4` of its tangent plane,
//!   `r_k` the distance to the `k`-th; with fewer than `k` within `r_max`, their sum over `π r_max²`.
//!   The caustic map uses `k = 16` (a focused spot), the glow map `k = 64` (a smooth field).
//!   `r_max` is a quarter of the object's bounding-box diagonal. Photons sit in a hash grid of
//!   `r_max/2` cells; a query outside the photons' bounding box (grown by `r_max`) costs one box test.
//!
//! Emitters between the object and the surface do not block photons, and light that leaves the
//! object toward another part of the object is dropped (both are nothing for a convex object above a
//! floor, the bundled scene).

use std::collections::HashMap;
use std::f64::consts::PI;

use glam::DVec3;

use super::points::VolumeSample;
use crate::physics::hg;
use crate::physics::medium::{extinguished, free_flight};
use crate::physics::rng::{Draws, SampleStream};
use crate::render::dielectric::Setup;
use crate::render::optics::{fresnel, reflect, refract};
use crate::scene::Surface;
use crate::scene::bvh::Ray;

/// Most scattering events a glow walk takes after its first.
pub const GLOW_EVENTS: u32 = 16;
/// Photons gathered per estimate in the caustic map.
pub const CAUSTIC_K: usize = 16;
/// Photons gathered per estimate in the glow map.
pub const GLOW_K: usize = 64;

/// Flux that reached an opaque surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Photon {
    /// Where it landed \[m\].
    pub position: DVec3,
    /// Unit normal of the surface, on the side the photon arrived from.
    pub normal: DVec3,
    /// Flux \[W\] per channel.
    pub flux: [f64; 3],
}

/// Photons with a hash grid for their nearest-neighbour density estimate (module doc).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PhotonMap {
    photons: Vec<Photon>,
    k: usize,
    r_max: f64,
    cell: f64,
    lo: DVec3,
    hi: DVec3,
    grid: HashMap<[i64; 3], Vec<u32>>,
}

impl PhotonMap {
    /// Builds the map of `photons` gathering `k` (≥ 2) per estimate within `r_max` (> 0).
    pub fn build(photons: Vec<Photon>, k: usize, r_max: f64) -> PhotonMap {
        let cell = 0.5 * r_max;
        let mut grid: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
        let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        for (i, p) in photons.iter().enumerate() {
            grid.entry(cell_of(p.position, cell)).or_default().push(i as u32);
            lo = lo.min(p.position);
            hi = hi.max(p.position);
        }
        PhotonMap { photons, k: k.max(2), r_max, cell, lo: lo - r_max, hi: hi + r_max, grid }
    }

    /// The photons.
    pub fn photons(&self) -> &[Photon] {
        &self.photons
    }

    /// Irradiance \[W/m²\] at `p` on a surface of unit normal `n` (module doc).
    pub fn irradiance(&self, p: DVec3, n: DVec3) -> [f64; 3] {
        if self.photons.is_empty() || !(p.cmpge(self.lo).all() && p.cmple(self.hi).all()) {
            return [0.0; 3];
        }
        let c = cell_of(p, self.cell);
        let reach = (self.r_max / self.cell).ceil() as i64;
        let r2_max = self.r_max * self.r_max;
        let mut near: Vec<(f64, u32)> = Vec::new();
        for dx in -reach..=reach {
            for dy in -reach..=reach {
                for dz in -reach..=reach {
                    let Some(ids) = self.grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) else { continue };
                    for &i in ids {
                        let ph = &self.photons[i as usize];
                        let v = ph.position - p;
                        let d2 = v.length_squared();
                        if d2 <= r2_max && ph.normal.dot(n) > 0.5 && v.dot(n).abs() <= 0.25 * self.r_max {
                            near.push((d2, i));
                        }
                    }
                }
            }
        }
        let order = |a: &(f64, u32), b: &(f64, u32)| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1));
        let (used, r2) = if near.len() >= self.k {
            near.select_nth_unstable_by(self.k - 1, order);
            let r2 = near[self.k - 1].0;
            near.truncate(self.k - 1);
            (near, r2)
        } else {
            (near, r2_max)
        };
        // Coincident photons: the smallest radius a photon's position can resolve.
        let r2 = r2.max((1e-6 * self.r_max).powi(2));
        let mut used = used;
        used.sort_unstable_by(order);
        let mut e = [0.0; 3];
        for (_, i) in used {
            let f = self.photons[i as usize].flux;
            (0..3).for_each(|c| e[c] += f[c]);
        }
        e.map(|v| v / (PI * r2))
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        self.photons.len() * (std::mem::size_of::<Photon>() + 4) + self.grid.len() * 48
    }
}

fn cell_of(p: DVec3, cell: f64) -> [i64; 3] {
    let q = (p / cell).floor();
    [q.x as i64, q.y as i64, q.z as i64]
}

/// The caustic and glow maps of one object.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ObjectLight {
    /// Ballistic light through the object.
    pub caustic: PhotonMap,
    /// Light scattered in the object on its way out.
    pub glow: PhotonMap,
}

impl ObjectLight {
    /// Irradiance \[W/m²\] the object sends to `p` (unit normal `n`): the caustic, plus the glow when
    /// `glow` is set.
    pub fn irradiance(&self, p: DVec3, n: DVec3, glow: bool) -> [f64; 3] {
        let mut e = self.caustic.irradiance(p, n);
        if glow {
            let g = self.glow.irradiance(p, n);
            (0..3).for_each(|c| e[c] += g[c]);
        }
        e
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        self.caustic.memory_bytes() + self.glow.memory_bytes()
    }
}

/// Whether mesh `mesh` is an opaque surface with a non-black base colour (where photons are stored).
pub(crate) fn receives(setup: &Setup, mesh: usize) -> bool {
    mesh != setup.object
        && setup
            .scene
            .meshes
            .get(mesh)
            .and_then(|m| m.material)
            .and_then(|mi| setup.scene.materials.get(mi))
            .is_some_and(|m| matches!(m.surface, Surface::Opaque))
        && setup.albedo_of(mesh).iter().any(|&r| r > 0.0)
}

/// Follows light that left the object at `o` along unit `d` with `flux` to the first surface; a photon
/// if that is a receiving one (see [`receives`]).
pub(crate) fn land(setup: &Setup, o: DVec3, d: DVec3, flux: [f64; 3]) -> Option<Photon> {
    if !flux.iter().all(|f| f.is_finite()) || flux.iter().all(|&f| f <= 0.0) {
        return None;
    }
    let h = setup.bvh.closest_hit(&Ray::new(o.to_array(), d.to_array()))?;
    if !receives(setup, h.mesh) {
        return None;
    }
    let mut n = DVec3::from_array(h.geometric_normal);
    if n.dot(d) > 0.0 {
        n = -n;
    }
    let position = o + d * h.t;
    position.is_finite().then_some(Photon { position, normal: n, flux })
}

/// A unit direction at cosine `mu` to unit `axis` and azimuth `phi`.
fn around(axis: DVec3, mu: f64, phi: f64) -> DVec3 {
    let (t, b) = axis.any_orthonormal_pair();
    let s = (1.0 - mu * mu).max(0.0).sqrt();
    (mu * axis + s * (phi.cos() * t + phi.sin() * b)).normalize()
}

/// The glow walk of one volume sample (module doc): the photon it lands, if any. `eps` offsets rays
/// from the boundary.
pub(crate) fn glow_photon(setup: &Setup, v: &VolumeSample, stream: SampleStream, eps: f64) -> Option<Photon> {
    let m = setup.material;
    let sig = m.sigma_t.iter().copied().fold(f64::INFINITY, f64::min);
    let a = extinguished(sig, v.length);
    if !(a > 0.0 && sig > 0.0) || m.albedo.iter().all(|&x| x <= 0.0) {
        return None;
    }
    let mut draws = Draws::new(stream);
    // First scattering point in the interval, pdf σ̄e^{−σ̄t}/a on [0, L].
    let t = free_flight(draws.draw() * a, sig).clamp(0.0, v.length);
    let pdf = sig * (-sig * t).exp() / a;
    let mut w: [f64; 3] = std::array::from_fn(|c| v.flux[c] * m.sigma_s(c) * (-m.sigma_t[c] * t).exp() / pdf);
    let mut x = v.start + v.direction * t;
    let mut d = around(v.direction, hg::sample_mu(draws.draw(), m.g), 2.0 * PI * draws.draw());
    let mut events = 0u32;
    loop {
        if !w.iter().all(|x| x.is_finite()) || w.iter().all(|&x| x <= 0.0) {
            return None;
        }
        let h = setup.bvh.closest_hit(&Ray::new(x.to_array(), d.to_array()))?;
        if h.mesh != setup.object || h.front_face {
            return None;
        }
        let flight = free_flight(draws.draw(), sig);
        if flight >= h.t {
            (0..3).for_each(|c| w[c] *= (-(m.sigma_t[c] - sig) * h.t).exp());
            let nb = DVec3::from_array(h.geometric_normal);
            let nb = if nb.dot(d) < 0.0 { -nb } else { nb };
            let xb = x + d * h.t;
            let f = fresnel(d.dot(nb).abs(), m.ior, 1.0);
            if draws.draw() >= f
                && let Some(out) = refract(d, nb, m.ior, 1.0)
            {
                return land(setup, xb + nb * eps, out, w);
            }
            // Reflected (counted as an event so total internal reflection cannot loop forever).
            d = reflect(d, nb).normalize();
            x = xb - nb * eps;
        } else {
            x += d * flight;
            (0..3).for_each(|c| w[c] *= m.sigma_s(c) / sig * (-(m.sigma_t[c] - sig) * flight).exp());
            d = around(d, hg::sample_mu(draws.draw(), m.g), 2.0 * PI * draws.draw());
        }
        events += 1;
        if events > GLOW_EVENTS {
            return None;
        }
    }
}

/// Rows of `voltab stability` for the photon maps and the glow walk on extreme inputs.
pub fn stability_rows() -> Vec<crate::stability::Row> {
    use crate::scene::bvh::SceneBvh;
    use crate::stability::{Expect, Row};
    let kind = "translucent";
    let mut v = Vec::new();
    // 64 photons on one spot queried there: r_k = 0 is clamped, the estimate stays finite.
    let spot = Photon { position: DVec3::ZERO, normal: DVec3::Y, flux: [1.0; 3] };
    v.push(Row {
        kind,
        formula: "photon map, coincident photons",
        input: "64 photons at the query".into(),
        value: PhotonMap::build(vec![spot; 64], 16, 0.1).irradiance(DVec3::ZERO, DVec3::Y)[0],
        expect: Expect::Positive,
    });
    // Fraction of the entering flux the photons land on the floor (≤ 1 by conservation).
    let scene = ball_over_ground(0.05);
    let bvh = SceneBvh::build(&scene);
    let r = 0.005;
    let lamp = [crate::render::dielectric::Emitter {
        center: DVec3::new(0.0, 1.2, 0.0),
        radius: r,
        radiance: [1.0 / (PI * r * r); 3],
    }];
    let cases = [
        ("glow", "α = 1, g = 0.99, σ_t = 1e-3 /m", 1.0, 0.99, 1e-3, 0.0, 1e-3),
        ("glow", "α = 1, g = −0.99, σ_t = 1e4 /m", 1.0, -0.99, 1e4, 0.0, 1.0),
        ("glow", "α = 1, g = 0, σ_t = 10 /m", 1.0, 0.0, 10.0, 0.05, 1.0),
        ("caustic", "α = 0, σ_t = 1e-9 /m, η = 1", 0.0, 0.0, 1e-9, 0.95, 1.0),
    ];
    for (what, input, albedo, g, sigma, lo, hi) in cases {
        let material = crate::render::dielectric::Material {
            sigma_t: [sigma; 3],
            albedo: [albedo; 3],
            g,
            ior: if albedo > 0.0 { 1.5 } else { 1.0 },
        };
        let setup = Setup { scene: &scene, bvh: &bvh, object: 0, material, emitters: &lamp };
        let opts = super::points::PointOptions { surface_samples: 256, indirect_rays: 0, ..Default::default() };
        let value = match super::points::generate(&setup, &opts) {
            Ok(p) => {
                let map = if what == "glow" { &p.object_light.glow } else { &p.object_light.caustic };
                map.photons().iter().map(|ph| ph.flux[0]).sum::<f64>() / p.stats.entered_flux[0]
            }
            Err(_) => f64::NAN,
        };
        v.push(Row {
            kind,
            formula: if what == "glow" { "glow photons / entering flux" } else { "caustic photons / entering flux" },
            input: input.into(),
            value,
            expect: Expect::InRange(lo, hi),
        });
    }
    v
}

/// A ball of radius 0.1 m centred at `(0, 0.1 + gap, 0)` (mesh 0) above a 2 m × 2 m ground of
/// reflectance 0.5 at `y = 0` (mesh 1): the scene of the object-light tests and stability rows.
pub(crate) fn ball_over_ground(gap: f64) -> crate::scene::Scene {
    use crate::scene::bvh::procedural;
    let ball = procedural::icosphere("Ball", [0.0, 0.1 + gap, 0.0], 0.1, 4);
    let mut ground = procedural::mesh(
        "Ground",
        vec![[-1.0, 0.0, -1.0], [1.0, 0.0, -1.0], [1.0, 0.0, 1.0], [-1.0, 0.0, 1.0]],
        vec![[0.0, 1.0, 0.0]; 4],
        vec![[0, 2, 1], [0, 3, 2]],
    );
    ground.material = Some(0);
    let mut s = procedural::scene(vec![ball, ground]);
    s.materials = vec![crate::scene::Material {
        name: "Ground".into(),
        base_color: [0.5; 3],
        emission: [0.0; 3],
        surface: Surface::Opaque,
        roughness: 1.0,
    }];
    s
}

#[cfg(test)]
mod tests;
