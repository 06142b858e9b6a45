//! One photon's random walk and the symmetry-averaged next-event kernels of `reference::walk`.
//!
//! **Input → output.** A validated [`Problem`] (geometry in mean free paths, albedo, HG `g`, receiver
//! normal) and a random stream → the photon's scores added into a [`Tally`] by scattering order,
//! plus the weight removed by the far rule and a count of non-finite values. The parent module doc
//! derives the estimator (rotation-averaged point detector; plane-integrated detector) and why it
//! is unbiased with finite variance; this file is the arithmetic.
//!
//! **Independent of** `crate::physics::hg` and the table generators: the HG phase and sampler, the
//! frames and all geometry are written here (vector arithmetic is glam's `DVec3`, in the same
//! operation order as the scalar formulas, so results are bit-identical to them).

use std::f64::consts::{PI, TAU};

use glam::DVec3;

use crate::physics::rng::StreamKey;

/// Russian roulette below this weight (survival probability `w / ROULETTE`).
const ROULETTE: f64 = 0.1;
/// Relative floor of `|a − d|` in the point kernel (reached only when `a == d` in floating point).
const TINY_GAP: f64 = 1.0 / (1u64 << 60) as f64;
/// Floor of the optical height in the plane kernel.
const MIN_TAU: f64 = 1e-300;
/// Hard cap on collisions per photon (never reached in practice; counted as removed weight).
const MAX_COLLISIONS: usize = 1 << 32;

/// Emitter geometry in mean free paths; the receiver is at the origin.
#[derive(Debug, Clone, Copy)]
pub(super) enum Geometry {
    /// Point source at `d·l`.
    Point { d: f64, l: DVec3 },
    /// Cosine-weighted differential area at `d·l` with unit normal `ne`.
    Area { d: f64, l: DVec3, ne: DVec3 },
    /// Half-space `{p·l ≤ depth}` lit along `−l`.
    Slab { depth: f64, l: DVec3 },
}

/// Everything a photon needs, validated.
#[derive(Debug, Clone, Copy)]
pub(super) struct Problem {
    geometry: Geometry,
    albedo: f64,
    g: f64,
    normal: DVec3,
    k_max: usize,
    far: f64,
    /// Direction toward the light.
    l: DVec3,
    /// Orthonormal pair perpendicular to `l`.
    frame: (DVec3, DVec3),
    /// Emitter–receiver distance: `d` (point) or `D` (half-space).
    span: f64,
    /// Rate `β` of the stretched first-flight component.
    beta: f64,
}

impl Problem {
    /// Bundles validated parameters (lengths in mean free paths).
    pub(super) fn new(geometry: Geometry, albedo: f64, g: f64, normal: DVec3, k_max: usize, far: f64) -> Self {
        let (l, span) = match geometry {
            Geometry::Point { l, d } | Geometry::Area { l, d, .. } => (l, d),
            Geometry::Slab { l, depth } => (l, depth),
        };
        let beta = 1.0 / (1.0 + span.min(far));
        Self { geometry, albedo, g, normal, k_max, far, l, frame: basis(l), span, beta }
    }
}

/// Where a photon is: relative to the source (point), or its depth below the boundary (half-space:
/// by translation invariance the lateral coordinates do not matter and are not tracked). Both keep
/// full precision near the emitter whatever the emitter–receiver distance.
#[derive(Debug, Clone, Copy)]
enum Place {
    FromSource(DVec3),
    Depth(f64),
}

/// Per-batch accumulators.
#[derive(Debug, Clone)]
pub(super) struct Tally {
    /// Score sums (in mean-free-path units) for orders `1..=K`, then the tail.
    pub(super) sums: Vec<f64>,
    /// Weight removed by the far rule.
    pub(super) truncated: f64,
    /// Non-finite scores or positions discarded.
    pub(super) nonfinite: u64,
}

impl Tally {
    /// Zeroed tally with `buckets` score bins.
    pub(super) fn new(buckets: usize) -> Self {
        Self { sums: vec![0.0; buckets], truncated: 0.0, nonfinite: 0 }
    }
}

/// Successive uniforms of one photon's stream: the draw counter's high half is the sample index,
/// its low half the dimension.
struct Draws {
    key: StreamKey,
    counter: u64,
}

impl Draws {
    fn next(&mut self) -> f64 {
        let u = self.key.uniform(self.counter >> 32, self.counter as u32);
        self.counter += 1;
        u
    }

    /// Exponential variate with mean 1 (`−ln(1 − ξ)`, finite since `ξ < 1`).
    fn exp1(&mut self) -> f64 {
        -(1.0 - self.next()).ln()
    }
}

/// Traces photon `key` to termination, adding its scores to `tally`.
pub(super) fn trace(p: &Problem, key: StreamKey, tally: &mut Tally) {
    let mut rng = Draws { key, counter: 0 };
    let (mut place, mut dir) = match p.geometry {
        Geometry::Point { .. } | Geometry::Area { .. } => {
            let mu = 1.0 - 2.0 * rng.next();
            (Place::FromSource(DVec3::ZERO), direction(mu, TAU * rng.next(), basis(p.l), p.l))
        }
        Geometry::Slab { .. } => (Place::Depth(0.0), p.l * -1.0),
    };
    // First flight: defensive mixture of Exp(1) and the stretched Exp(β), weighted by the density
    // ratio e^{−t}/(½e^{−t} + ½βe^{−βt}) ≤ 2.
    let beta = p.beta;
    let t0 = if rng.next() < 0.5 { rng.exp1() } else { rng.exp1() / beta };
    let mut weight = 1.0 / (0.5 + 0.5 * beta * ((1.0 - beta) * t0).exp());
    let mut flight = t0;
    // Emission direction, read by the area kernel (the walk itself emits isotropically).
    let emitted = dir;
    for order in 1..=MAX_COLLISIONS {
        place = match place {
            Place::FromSource(r) => Place::FromSource(r + dir * flight),
            Place::Depth(z) => Place::Depth(z - flight * dir.dot(p.l)),
        };
        let kernel = match place {
            Place::FromSource(r) => {
                if !r.is_finite() {
                    tally.nonfinite += 1;
                    return;
                }
                let a = r.length();
                if a > p.far && (a - p.span).abs() > p.far {
                    tally.truncated += weight;
                    return;
                }
                match p.geometry {
                    Geometry::Area { ne, .. } => area_kernel(p, r, dir, emitted, ne, &mut rng),
                    _ => point_kernel(p, r, dir, &mut rng),
                }
            }
            Place::Depth(z) => {
                if !z.is_finite() {
                    tally.nonfinite += 1;
                    return;
                }
                if z < 0.0 {
                    return; // escaped through the boundary into vacuum
                }
                if (p.span - z).abs() > p.far && z > p.far {
                    tally.truncated += weight;
                    return;
                }
                plane_kernel(p, p.span - z, dir, &mut rng)
            }
        };
        let score = weight * p.albedo * kernel;
        if score.is_finite() {
            tally.sums[order.min(p.k_max + 1) - 1] += score;
        } else {
            tally.nonfinite += 1;
        }
        weight *= p.albedo;
        if weight < ROULETTE {
            if rng.next() * ROULETTE >= weight {
                return;
            }
            weight = ROULETTE;
        }
        let mu = hg_sample(p.g, rng.next());
        dir = direction(mu, TAU * rng.next(), basis(dir), dir);
        flight = rng.exp1();
    }
    tally.truncated += weight;
}

/// A vertex rotated about the source (one importance sample of the Haar rotation, module doc).
struct Rotated {
    /// Distance from the rotated vertex to the receiver.
    r: f64,
    /// Importance weight `ln((a+d)/|a−d|)/(2ad)` of the sampled rotation.
    weight: f64,
    /// Unit direction from the receiver toward the rotated vertex.
    omega: DVec3,
    /// `n·ω` (> 0).
    cos_n: f64,
    /// Image of the radial direction `(y − s)/a`.
    radial: DVec3,
    /// Orthonormal pair perpendicular to `radial` (the spin frame).
    spin: (DVec3, DVec3),
}

/// Samples the rotated vertex for a vertex at distance `a > 0` from the source with uniforms `x1, x2`;
/// `None` when it cannot score (receiver behind the normal, or degenerate).
fn rotate_vertex(p: &Problem, a: f64, x1: f64, x2: f64) -> Option<Rotated> {
    let (l, d) = (p.l, p.span);
    let (small, big) = if a < d { (a, d) } else { (d, a) };
    let gap = (a - d).abs().max(big * TINY_GAP);
    // r is log-uniform on [gap, gap + 2·small]; the weight is ln((a+d)/|a−d|)/(2ad) = (L/z)/(gap·big).
    let z = 2.0 * small / gap;
    let log_span = z.ln_1p();
    let weight = if z > 0.0 { log_span / z } else { 1.0 } / (gap * big);
    let dr = gap * (x1 * log_span).exp_m1();
    let r = gap + dr;
    // Polar angle θ at the source between (x − s) = −d·l and (y' − s), without cancellation.
    let two_ad = 2.0 * a * d;
    let one_minus_cos = (dr * (r + gap) / two_ad).clamp(0.0, 2.0);
    let one_plus_cos = ((2.0 * small - dr).max(0.0) * (a + d + r) / two_ad).clamp(0.0, 2.0);
    let cos_t = 1.0 - one_minus_cos;
    let sin_t = (one_minus_cos * one_plus_cos).sqrt().min(1.0);
    let (s1, c1) = (TAU * x2).sin_cos();
    let (e1, e2) = p.frame;
    let e_phi = e1 * c1 + e2 * s1;
    let e_perp = e2 * c1 - e1 * s1;
    // y' − x = s + a(cos θ (−l) + sin θ e_φ) = ((d − a) + a(1 − cos θ)) l + a sin θ e_φ.
    let y = l * ((d - a) + a * one_minus_cos) + e_phi * (a * sin_t);
    let ry = y.length();
    if ry.is_nan() || ry <= 0.0 {
        return None;
    }
    let omega = y * (1.0 / ry);
    let cos_n = p.normal.dot(omega);
    if cos_n.is_nan() || cos_n <= 0.0 {
        return None;
    }
    let radial = l * -cos_t + e_phi * sin_t;
    let polar = l * sin_t + e_phi * cos_t;
    Some(Rotated { r, weight, omega, cos_n, radial, spin: (polar, e_perp) })
}

/// Rotation-averaged point-detector kernel of a vertex at `rel` from the source reached along `dir`,
/// for a source at `d·l` and the receiver at the origin: one importance sample of the Haar average
/// of `p(u'·(−ω)) max(0, n·ω) e^{−r}/r²` over rotations about the source (module doc).
fn point_kernel(p: &Problem, rel: DVec3, dir: DVec3, rng: &mut Draws) -> f64 {
    let (x1, x2, x3) = (rng.next(), rng.next(), rng.next());
    let a = rel.length();
    if a.is_nan() || a <= 0.0 {
        return 0.0;
    }
    let u_radial = (dir.dot(rel) / a).clamp(-1.0, 1.0);
    let Some(v) = rotate_vertex(p, a, x1, x2) else {
        return 0.0;
    };
    // Rotated incoming direction: same radial component, uniform spin about the new radial axis.
    let u = direction(u_radial, TAU * x3, v.spin, v.radial);
    hg_phase(p.g, -u.dot(v.omega)) * v.cos_n * (-v.r).exp() * v.weight
}

/// Rotation-averaged kernel of the area emitter (module doc): the photon was emitted isotropically
/// along `emitted`; the rotation `R` maps `(y − s)/a` to the sampled radial direction and a fixed
/// perpendicular `p̂` to a uniformly spun one, and the score of the rotated path is the point kernel
/// times the emission reweighting `4 max(0, n_e·R u₀)` (mean 1 over isotropic `u₀`, at most 4).
fn area_kernel(p: &Problem, rel: DVec3, dir: DVec3, emitted: DVec3, ne: DVec3, rng: &mut Draws) -> f64 {
    let (x1, x2, x3) = (rng.next(), rng.next(), rng.next());
    let a = rel.length();
    if a.is_nan() || a <= 0.0 {
        return 0.0;
    }
    let Some(v) = rotate_vertex(p, a, x1, x2) else {
        return 0.0;
    };
    let r_hat = rel * (1.0 / a);
    let (p_hat, q_hat) = basis(r_hat);
    let (s3, c3) = (TAU * x3).sin_cos();
    let (f1, f2) = v.spin;
    let p_img = f1 * c3 + f2 * s3;
    let q_img = v.radial.cross(p_img);
    // (r̂, p̂, q̂ = r̂ × p̂) and (radial, p̂', q̂' = radial × p̂') are both right-handed: R ∈ SO(3).
    let rotate = |w: DVec3| v.radial * w.dot(r_hat) + (p_img * w.dot(p_hat) + q_img * w.dot(q_hat));
    let emission = 4.0 * ne.dot(rotate(emitted)).max(0.0);
    if emission == 0.0 {
        return 0.0;
    }
    let u = rotate(dir);
    hg_phase(p.g, -u.dot(v.omega)) * v.cos_n * (-v.r).exp() * v.weight * emission
}

/// Plane-integrated detector kernel of a vertex at height `h` above the receiver plane reached along
/// `dir`: one sample of `∫ dφ ∫_{|h|}^∞ p(u·(−ω)) max(0, n·ω) e^{−t}/t dt` (module doc).
fn plane_kernel(p: &Problem, h: f64, dir: DVec3, rng: &mut Draws) -> f64 {
    let (x1, x2, x3) = (rng.next(), rng.next(), rng.next());
    let l = p.l;
    let tau = h.abs().max(MIN_TAU);
    let (t, est) = if tau >= 1.0 {
        let t = tau - (1.0 - x2).ln();
        (t, (-tau).exp() / t)
    } else {
        let log_part = -tau.ln();
        let total = log_part + (-1.0f64).exp();
        if x1 * total < log_part {
            let t = ((1.0 - x2) * tau.ln()).exp();
            (t, (-t).exp() * total)
        } else {
            let t = 1.0 - (1.0 - x2).ln();
            (t, total / t)
        }
    };
    let mu = (tau / t).min(1.0);
    let omega = direction(if h >= 0.0 { mu } else { -mu }, TAU * x3, p.frame, l);
    let cos_n = p.normal.dot(omega);
    if cos_n.is_nan() || cos_n <= 0.0 {
        return 0.0;
    }
    TAU * hg_phase(p.g, -dir.dot(omega)) * cos_n * est
}

/// Henyey–Greenstein phase `(1 − g²) / (4π (1 + g² − 2gμ)^{3/2})`, the base written as a sum of
/// non-negative terms.
pub(super) fn hg_phase(g: f64, mu: f64) -> f64 {
    let base = if g >= 0.0 {
        (1.0 - g) * (1.0 - g) + 2.0 * g * (1.0 - mu)
    } else {
        (1.0 + g) * (1.0 + g) - 2.0 * g * (1.0 + mu)
    };
    (1.0 - g * g) / (4.0 * PI * base * base.sqrt())
}

/// Scattering cosine with HG density for uniform `xi`: inverse CDF, or its first-order expansion
/// `v + 1.5 g (1 − v²)`, `v = 2ξ − 1`, when `|g| < 1e-6`.
pub(super) fn hg_sample(g: f64, xi: f64) -> f64 {
    let mu = if g.abs() < 1e-6 {
        let v = 2.0 * xi - 1.0;
        v + 1.5 * g * (1.0 - v * v)
    } else {
        let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * xi);
        (1.0 + g * g - s * s) / (2.0 * g)
    };
    mu.clamp(-1.0, 1.0)
}

/// Unit vector with cosine `mu` to `axis` and azimuth `phi` in the frame `(e1, e2)` ⊥ `axis`.
fn direction(mu: f64, phi: f64, (e1, e2): (DVec3, DVec3), axis: DVec3) -> DVec3 {
    let st = ((1.0 - mu) * (1.0 + mu)).max(0.0).sqrt();
    let (s, c) = phi.sin_cos();
    let v = axis * mu + (e1 * (st * c) + e2 * (st * s));
    v * (1.0 / v.length())
}

/// Orthonormal pair perpendicular to the unit vector `u`.
fn basis(u: DVec3) -> (DVec3, DVec3) {
    let seed = if u.x.abs() < 0.6 { DVec3::X } else { DVec3::Y };
    let e1 = seed - u * seed.dot(u);
    let e1 = e1 * (1.0 / e1.length());
    (e1, u.cross(e1))
}
