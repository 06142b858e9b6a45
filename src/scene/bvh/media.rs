//! The media along a ray and their optical thickness.
//!
//! **Input → output.** A ray and the boundary BVH → [`MediumSegment`]s: consecutive intervals of the
//! ray with the medium filling each (the innermost closed medium, the [`Boundary::Global`] medium
//! outside all closed media, `None` for vacuum). Segments and a scene → per channel the optical
//! thickness `τ = ∫σ_t ρ ds` (homogeneous exactly, exponential height fog in closed form, iser2018 Eq. 4)
//! and the effective extinction `τ / length` (dubouchet2019 Sec. 4.4).
//!
//! **Entering and leaving.** Every boundary hit is entering when the ray arrives against the
//! triangle's geometric normal (outward for counter-clockwise triangles, the importers' convention),
//! leaving otherwise; the sign comes from the triangle's orientation in the ray frame, the same
//! arithmetic that decided the hit. Rays through an edge or a vertex follow the rule in
//! `bvh/triangle.rs`, so each crossing is counted once.
//!
//! **Where the ray starts.** One traversal collects the boundary hits at `t ∈ (0, ∞)`. Space far along
//! the ray is outside every closed mesh, so walking the hits backwards from infinity (a leaving hit
//! means "inside before it") gives, per mesh, how deep the origin lies inside it, and the order of the
//! closed media around it (the one left first is the innermost). Nesting is a count per mesh, so a ray
//! grazing a silhouette (entering and leaving one mesh at the same `t`) is neutral in any order.
//! Along the ray a medium entered becomes the innermost and leaving removes it; where closed media
//! overlap without nesting, the one entered last fills the overlap. A ray starting exactly on a
//! boundary gets the medium on the side it moves into. Hits at exactly the same `t` on
//! different meshes (coincident boundaries) are ordered leaving-before-entering, and the mesh with
//! the higher index counts as the inner one. A mesh that is not closed can leave a count unbalanced;
//! space where a mesh's count is not positive is outside it.

use glam::DVec3;

use super::{Query, Ray, SceneBvh, intersect};
use crate::scene::{Boundary, Density, Scene};

/// One interval `[t0, t1]` of a ray (parameters in units of the direction's length) and what fills it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MediumSegment {
    /// Start.
    pub t0: f64,
    /// End (`+∞` for an unbounded ray).
    pub t1: f64,
    /// Index into [`Scene::media`]; `None` for vacuum.
    pub medium: Option<usize>,
}

/// A boundary crossing.
#[derive(Debug, Clone, Copy)]
struct Crossing {
    t: f32,
    mesh: usize,
    gid: u32,
    entering: bool,
}

/// Per-mesh nesting counts and the order of the media the ray is inside (outermost first).
#[derive(Debug, Default)]
struct Nesting {
    counts: Vec<(usize, i64)>,
    inside: Vec<usize>,
}

impl Nesting {
    /// Adds `step` to `mesh`'s count; a count becoming positive makes the mesh the innermost, one
    /// dropping to zero removes it.
    fn step(&mut self, mesh: usize, step: i64) {
        let i = match self.counts.iter().position(|c| c.0 == mesh) {
            Some(i) => i,
            None => {
                self.counts.push((mesh, 0));
                self.counts.len() - 1
            }
        };
        let before = self.counts[i].1;
        let after = before + step;
        self.counts[i].1 = after;
        if before <= 0 && after > 0 {
            self.inside.push(mesh);
        } else if before > 0 && after <= 0 {
            self.inside.retain(|&m| m != mesh);
        }
    }
}

impl SceneBvh {
    /// The media along `origin + t·direction` for `t ∈ [0, t_max]` (`t_max = +∞` allowed; the ray's own
    /// `t_min`/`t_max` are not used): consecutive, non-empty intervals covering `[0, t_max]`, adjacent
    /// intervals with the same medium merged. `scene` must be the scene this BVH was built from (its
    /// media and global medium are read from it). Empty for an invalid ray or `t_max <= 0`.
    pub fn media_segments(&self, scene: &Scene, ray: &Ray, t_max: f64) -> Vec<MediumSegment> {
        let Some(q) = Query::new(ray.origin, ray.direction, 0.0, f64::INFINITY) else { return Vec::new() };
        if !positive(t_max) {
            return Vec::new();
        }
        let global = scene.media.iter().position(|m| m.boundary == Boundary::Global);
        let medium_of = |mesh: usize| self.medium_bounded_by(mesh).filter(|&i| i < scene.media.len());
        let tris = &self.boundary.tris;
        let mut hits = Vec::new();
        self.boundary.traverse(&q.node, f32::INFINITY, |slot, _| {
            if let Some(h) = intersect(&tris[slot], &q.pr)
                && q.in_range(h.t)
            {
                let (mesh, _) = self.locate(tris[slot].gid);
                if medium_of(mesh).is_some() {
                    hits.push(Crossing { t: h.t, mesh, gid: tris[slot].gid, entering: h.front });
                }
            }
            false
        });
        // Leaving before entering at equal t; leaving by descending, entering by ascending mesh index,
        // so that walking backwards pushes coincident media in the same order as walking forwards.
        hits.sort_by(|a, b| {
            a.t.total_cmp(&b.t).then(a.entering.cmp(&b.entering)).then_with(|| {
                if a.entering { a.mesh.cmp(&b.mesh) } else { b.mesh.cmp(&a.mesh) }.then(a.gid.cmp(&b.gid))
            })
        });
        let mut nest = Nesting::default();
        for h in hits.iter().rev() {
            nest.step(h.mesh, if h.entering { -1 } else { 1 });
        }
        let current = |n: &Nesting| n.inside.last().and_then(|&m| medium_of(m)).or(global);
        let mut out: Vec<MediumSegment> = Vec::new();
        let mut push = |t0: f64, t1: f64, medium: Option<usize>| {
            if t1 <= t0 {
                return;
            }
            match out.last_mut() {
                Some(last) if last.medium == medium && last.t1 == t0 => last.t1 = t1,
                _ => out.push(MediumSegment { t0, t1, medium }),
            }
        };
        let mut t_prev = 0.0f64;
        for h in &hits {
            let t = f64::from(h.t) / q.unit;
            if t >= t_max {
                break;
            }
            push(t_prev, t, current(&nest));
            t_prev = t_prev.max(t);
            nest.step(h.mesh, if h.entering { 1 } else { -1 });
        }
        push(t_prev, t_max, current(&nest));
        out
    }
}

/// `x > 0` (false for NaN).
fn positive(x: f64) -> bool {
    x > 0.0
}

/// Length of `v`, scaled so that large or tiny components neither overflow nor underflow (unlike glam's
/// `length`, which squares the components as they are).
fn scaled_length(v: DVec3) -> f64 {
    let m = 0.0f64.max(v.x.abs()).max(v.y.abs()).max(v.z.abs());
    if !(m > 0.0 && m.is_finite()) {
        return if m.is_nan() { 0.0 } else { m };
    }
    m * (v / m).length()
}

/// iser2018 Eq. 4: `∫₀ᴰ ρ' e^{−b(h₀ + s μ)} ds = ρ' e^{−b h₀} (1 − e^{−b D μ}) / (b μ)` for the density
/// `ρ(x) = ρ' e^{−b⟨x − o, n⟩}` along a ray that starts at height `h₀ = ⟨c − o, n⟩` with direction
/// cosine `μ = ⟨ω, n⟩` (unit `ω`, `n`) and runs a length `D` (metres); `D = +∞` allowed.
///
/// Written as `ρ' D e^{max(a₀, a₁)} φ(|x|)` with the log-densities `a₀ = −b h₀`, `a₁ = a₀ − x` at the
/// two ends, `x = b D μ` and `φ(y) = (1 − e^{−y}) / y = −expm1(−y)/y` (`φ(0) = 1`): no cancellation as
/// `μ → 0`, and the exponential is taken at the denser end, so it never overflows on its own; when
/// it does, the product is formed in log space, so the result is `+∞` only if the integral itself
/// exceeds `f64::MAX`. Never NaN for finite `ρ' ≥ 0`, `b`, `h₀`, `μ` and `D ≥ 0` (0 for `D <= 0`).
pub fn exponential_density_integral(rho: f64, falloff: f64, h0: f64, mu: f64, d: f64) -> f64 {
    if !positive(d) || !positive(rho) {
        return 0.0;
    }
    let a0 = -falloff * h0;
    if !a0.is_finite() {
        // The density at the start is infinite or zero (b·h₀ beyond f64).
        return if a0 > 0.0 { f64::INFINITY } else { 0.0 };
    }
    let k = falloff * mu; // decay rate of the log-density along the ray [1/m]
    if d == f64::INFINITY {
        return if k > 0.0 { from_log(|| rho.ln() + a0 - k.ln(), rho * a0.exp() / k) } else { f64::INFINITY };
    }
    let x = k * d;
    let a1 = a0 - x;
    let amax = a0.max(a1);
    let y = x.abs();
    // D·φ(y) directly for y < 1; (1 − e^{−y})/|k| for y ≥ 1 (D/y would lose D when y overflows).
    let factor = if y < 1.0 { d * if y == 0.0 { 1.0 } else { -(-y).exp_m1() / y } } else { -(-y).exp_m1() / k.abs() };
    from_log(|| rho.ln() + amax + factor.ln(), rho * amax.exp() * factor)
}

/// `direct` when it is a normal finite number, else `exp(log())` (the same value formed in log space;
/// the logarithms are only taken then, which keeps the common case cheap for per-pixel use).
fn from_log(log: impl FnOnce() -> f64, direct: f64) -> f64 {
    if direct.is_normal() { direct } else { log().exp() }
}

/// `∫ ρ ds` over `[t0, t1]` of `ray` for one density field.
fn density_integral(density: &Density, ray: &Ray, t0: f64, t1: f64) -> f64 {
    let dir = DVec3::from_array(ray.direction);
    let len = scaled_length(dir);
    let d = if t1 == f64::INFINITY { f64::INFINITY } else { (t1 - t0) * len };
    if !positive(d) || !len.is_finite() {
        return 0.0;
    }
    match density {
        Density::Homogeneous => d,
        Density::ExponentialHeight { rho, falloff, direction, offset } => {
            let direction = DVec3::from_array(*direction);
            let nlen = scaled_length(direction);
            if !(nlen > 0.0 && nlen.is_finite()) {
                return 0.0;
            }
            let n = direction / nlen;
            let omega = dir / len;
            let c = DVec3::from_array(ray.origin) + t0 * dir;
            let h0 = (c - DVec3::from_array(*offset)).dot(n);
            exponential_density_integral(*rho, *falloff, h0, omega.dot(n), d)
        }
    }
}

/// Per channel, `σ · P` with `0 · ∞ = 0` (no extinction, or no density, contributes nothing).
fn scale(sigma_t: [f64; 3], p: f64) -> [f64; 3] {
    sigma_t.map(|s| if s == 0.0 || p == 0.0 { 0.0 } else { s * p })
}

/// Optical thickness per channel, `τ = Σ_segments σ_t ∫_{t0}^{t1} ρ(origin + t·direction) |direction| dt`:
/// homogeneous media exactly, exponential height fog by [`exponential_density_integral`]. Vacuum,
/// unknown media and empty or reversed segments add nothing; `+∞` only where the true value is (an
/// unbounded segment of a medium that does not thin out along the ray, or overflow).
pub fn optical_thickness(scene: &Scene, segments: &[MediumSegment], ray: &Ray) -> [f64; 3] {
    let mut tau = [0.0; 3];
    for s in segments {
        let Some(m) = s.medium.and_then(|i| scene.media.get(i)) else { continue };
        let add = scale(m.sigma_t(), density_integral(&m.density, ray, s.t0, s.t1));
        for c in 0..3 {
            tau[c] += add[c];
        }
    }
    tau
}

/// The effective extinction of a path, `τ / length` per channel (dubouchet2019 Sec. 4.4: the single σ
/// a homogeneous table is looked up with along a heterogeneous path); 0 for a path of zero length.
/// For an unbounded path it is the limit, `σ_t` times the density far along the last segment.
pub fn effective_sigma(scene: &Scene, segments: &[MediumSegment], ray: &Ray) -> [f64; 3] {
    let dir = DVec3::from_array(ray.direction);
    let len = scaled_length(dir);
    let total: f64 = segments.iter().map(|s| if s.t1 > s.t0 { (s.t1 - s.t0) * len } else { 0.0 }).sum();
    if !positive(total) || !len.is_finite() {
        return [0.0; 3];
    }
    if total.is_finite() {
        return optical_thickness(scene, segments, ray).map(|t| t / total);
    }
    let Some(last) = segments.iter().rfind(|s| s.t1 == f64::INFINITY && s.t1 > s.t0) else {
        return [0.0; 3]; // the length overflowed without an unbounded segment
    };
    let Some(m) = last.medium.and_then(|i| scene.media.get(i)) else { return [0.0; 3] };
    let far = match &m.density {
        Density::Homogeneous => 1.0,
        Density::ExponentialHeight { rho, falloff, direction, offset } => {
            let direction = DVec3::from_array(*direction);
            let nlen = scaled_length(direction);
            if !(positive(nlen) && nlen.is_finite() && positive(*rho)) {
                return [0.0; 3];
            }
            let n = direction / nlen;
            let k = falloff * (dir / len).dot(n);
            if k > 0.0 {
                0.0
            } else if k < 0.0 {
                f64::INFINITY
            } else {
                let c = DVec3::from_array(ray.origin) + last.t0 * dir - DVec3::from_array(*offset);
                rho * (-falloff * c.dot(n)).exp()
            }
        }
    };
    scale(m.sigma_t(), far)
}
