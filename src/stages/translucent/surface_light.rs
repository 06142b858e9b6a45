//! Diffuse light the boundary sends into the object, with every internal reflection (wang2018
//! Sec. 3.5.5, extended from one reflection to the whole series).
//!
//! **Input → output.** The surface samples (position, outward normal, area, the scene's indirect
//! irradiance from outside), their octree, the irradiance each receives from inside from the volume
//! samples, the material and its lobe slices → per surface sample the exitance `S` \[W/m²\] it emits
//! diffusely into the object, and the length of its chord along the inward normal.
//!
//! **Model.** A surface sample emits `S = (1 − F_dr,out) E_indirect + F_dr,in E_inner` (Lambertian,
//! radiance `S/π`), where `E_inner` is the irradiance reaching it from inside. wang2018 takes `E_inner`
//! from the volume samples only, i.e. one internal reflection. Inside an ior-1.5 object `F_dr,in ≈ 0.6`,
//! so diffuse light is reflected back many times; the series is summed here: the light emitted by the
//! surface samples reaches other surface samples (`E_inner` gains that share), is reflected again, and
//! so on until a further reflection adds less than [`SERIES_TOLERANCE`] of the emitted power (at most
//! [`SERIES_MAX`] terms).
//!
//! **Transport from a surface sample to another** (per unit emitted flux `Φ = S A`): unscattered,
//! `cos_e cos_r e^{−σ_t q}/(π q²)`; scattered at least once, the irradiance of an isotropic field
//! `φ/4` with `φ` the fluence of light scattered at least once from a beam along the inward normal
//! (the table's scattering-event density of orders ≥ 2 is `σ_s φ`): `(Φ ψ(start) − Φ e^{−σ_t d} ψ(end))/(4 σ_s)`,
//! `d` the chord. The beam stands for the cosine-distributed emission (its first collisions lie within
//! a mean free path of the surface; the orders after it are smooth). Transfers are computed once over a
//! solid-angle tree cut (`epsilon_multiple`, node data area-weighted, so the cut does not depend on
//! `S`), then each term of the series is a sparse product.

use glam::DVec3;
use rayon::prelude::*;

use super::octree::{CutEntry, Octree};
use super::points::SurfaceSample;
use super::render::solid_angle;
use crate::render::dielectric::{Material, Setup};
use crate::scene::bvh::Ray;
use crate::tables::ms_lobes::{LobeQueryError, LobeSlice};

/// A further internal reflection stops the series once it adds less than this share of the power
/// emitted so far (every channel).
pub const SERIES_TOLERANCE: f64 = 1e-4;
/// Most terms of the series.
pub const SERIES_MAX: usize = 200;

/// Area-weighted geometry of surface samples (a node or one sample).
#[derive(Debug, Clone, Copy, Default)]
struct Geo {
    area: f64,
    /// Area-weighted sums.
    pos: DVec3,
    inward: DVec3,
    end: DVec3,
    /// Area-weighted `e^{−σ_t d}` per channel.
    att: [f64; 3],
    lo: DVec3,
    hi: DVec3,
}

impl Geo {
    fn merge(parts: &[Geo]) -> Geo {
        let mut g = Geo { lo: DVec3::INFINITY, hi: DVec3::NEG_INFINITY, ..Geo::default() };
        for p in parts {
            g.area += p.area;
            g.pos += p.pos;
            g.inward += p.inward;
            g.end += p.end;
            for c in 0..3 {
                g.att[c] += p.att[c];
            }
            g.lo = g.lo.min(p.lo);
            g.hi = g.hi.max(p.hi);
        }
        g
    }
}

/// The result of [`emission`].
#[derive(Debug, Clone)]
pub struct Emission {
    /// Per surface sample, the exitance into the object per channel \[W/m²\].
    pub exitance: Vec<[f64; 3]>,
    /// Per surface sample, the chord along the inward normal \[m\] (∞ when the ray leaves no hit).
    pub chord: Vec<f64>,
    /// Terms of the series summed (1 = wang2018's single reflection).
    pub terms: usize,
}

/// Chord from a surface sample along the unit direction `d` (into the object) to the far side of the
/// object (∞ when the ray hits nothing).
pub(super) fn chord(setup: &Setup, s: &SurfaceSample, d: DVec3) -> f64 {
    let o = s.position + d * 1e-6;
    setup.bvh.closest_hit(&Ray::new(o.to_array(), d.to_array())).map_or(f64::INFINITY, |h| h.t.max(0.0))
}

/// The exitance of every surface sample (module doc). `e_vol` is the irradiance from the volume
/// samples, `f_out` and `f_in` the diffuse Fresnel reflectances from outside and inside, `clamp` the
/// `1/q²` clamp per channel \[m\].
#[allow(clippy::too_many_arguments)]
pub fn emission(
    setup: &Setup,
    samples: &[SurfaceSample],
    tree: &Octree,
    slices: &[LobeSlice],
    e_vol: &[[f64; 3]],
    (f_out, f_in): (f64, f64),
    epsilon: f64,
    clamp: [f64; 3],
    max_terms: usize,
) -> Result<Emission, LobeQueryError> {
    let m: Material = setup.material;
    let chord: Vec<f64> = samples.par_iter().map(|s| chord(setup, s, -s.normal)).collect();
    let first: Vec<[f64; 3]> = samples
        .iter()
        .zip(e_vol)
        .map(|(s, e)| std::array::from_fn(|c| (1.0 - f_out) * s.indirect[c] + f_in * e[c]))
        .collect();
    if f_in <= 0.0 || tree.nodes.is_empty() || max_terms <= 1 {
        return Ok(Emission { exitance: first, chord, terms: 1 });
    }
    let items: Vec<Geo> = samples
        .iter()
        .zip(&chord)
        .map(|(s, &d)| {
            let a = s.area;
            let end = if d.is_finite() { s.position - s.normal * d } else { s.position };
            Geo {
                area: a,
                pos: s.position * a,
                inward: -s.normal * a,
                end: end * a,
                att: std::array::from_fn(|c| a * (-m.sigma_t[c] * d).exp()),
                lo: s.position,
                hi: s.position,
            }
        })
        .collect();
    let nodes =
        tree.bottom_up(|ids| Geo::merge(&ids.iter().map(|&i| items[i as usize]).collect::<Vec<_>>()), Geo::merge);
    let geo = |e: &CutEntry| match *e {
        CutEntry::Node(n) => &nodes[n as usize],
        CutEntry::Item(i) => &items[i as usize],
    };
    // Transfers: per receiver, (cut entry, irradiance per unit flux per channel).
    let transfers: Vec<Vec<(CutEntry, [f64; 3])>> = samples
        .par_iter()
        .map(|s| -> Result<Vec<(CutEntry, [f64; 3])>, LobeQueryError> {
            let p = s.position;
            let mut cut = Vec::new();
            tree.cut(
                &[0],
                |n| {
                    let g = &nodes[n as usize];
                    let centre = g.pos / g.area.max(f64::MIN_POSITIVE);
                    let radius = 0.5 * (g.hi - g.lo).length();
                    let dist = (p - centre).length();
                    if tree.nodes[n as usize].is_leaf() { dist < radius } else { solid_angle(radius, dist) > epsilon }
                },
                &mut cut,
            );
            let mut out = Vec::with_capacity(cut.len());
            for e in cut {
                let g = geo(&e);
                if g.area <= 0.0 {
                    continue;
                }
                let x = g.pos / g.area;
                let q = p - x;
                let r = q.length();
                if r <= 0.0 {
                    continue;
                }
                let qh = q / r;
                let nin = g.inward / g.area; // shorter than 1 where the normals spread
                let dir = nin.try_normalize().unwrap_or(-s.normal);
                let y = g.end / g.area;
                let cos = nin.dot(qh).max(0.0) * qh.dot(s.normal).max(0.0);
                let mut k = [0.0; 3];
                for (c, kc) in k.iter_mut().enumerate() {
                    let st = m.sigma_t[c];
                    let rc = r.max(clamp[c]);
                    *kc = cos * (-st * r).exp() / (std::f64::consts::PI * rc * rc);
                    let ss = m.albedo[c] * st;
                    if ss <= 0.0 {
                        continue;
                    }
                    let psi = |origin: DVec3| -> Result<f64, LobeQueryError> {
                        let v = p - origin;
                        let z = v.dot(dir);
                        let rho = (v - z * dir).length();
                        slices[c].density(st * rho, st * z)
                    };
                    let att = g.att[c] / g.area;
                    let scattered = psi(x)? - att * psi(y)?;
                    *kc += 0.25 * st * st * st / ss * scattered.max(0.0);
                }
                out.push((e, k));
            }
            Ok(out)
        })
        .collect::<Result<_, LobeQueryError>>()?;
    // The series.
    let mut total = first.clone();
    let mut term = first;
    let mut terms = 1;
    let power = |v: &[[f64; 3]], c: usize| v.iter().zip(samples).map(|(x, s)| x[c] * s.area).sum::<f64>();
    while terms < max_terms.min(SERIES_MAX) {
        let flux_items: Vec<[f64; 3]> =
            term.iter().zip(samples).map(|(x, s)| std::array::from_fn(|c| x[c] * s.area)).collect();
        let flux_nodes = tree.bottom_up(
            |ids| {
                let mut f = [0.0; 3];
                for &i in ids {
                    for c in 0..3 {
                        f[c] += flux_items[i as usize][c];
                    }
                }
                f
            },
            |parts| {
                let mut f = [0.0; 3];
                for p in parts {
                    for c in 0..3 {
                        f[c] += p[c];
                    }
                }
                f
            },
        );
        let next: Vec<[f64; 3]> = transfers
            .par_iter()
            .map(|list| {
                let mut e = [0.0; 3];
                for (entry, k) in list {
                    let f = match *entry {
                        CutEntry::Node(n) => flux_nodes[n as usize],
                        CutEntry::Item(i) => flux_items[i as usize],
                    };
                    for c in 0..3 {
                        e[c] += k[c] * f[c];
                    }
                }
                e.map(|x| f_in * x)
            })
            .collect();
        terms += 1;
        for (t, n) in total.iter_mut().zip(&next) {
            for c in 0..3 {
                t[c] += n[c];
            }
        }
        let done = (0..3).all(|c| power(&next, c) <= SERIES_TOLERANCE * power(&total, c));
        term = next;
        if done {
            break;
        }
    }
    Ok(Emission { exitance: total, chord, terms })
}

#[cfg(test)]
mod tests;
