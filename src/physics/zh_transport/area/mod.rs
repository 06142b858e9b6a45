//! ZH impulse responses of a differential-area (cosine-weighted) emitter, bounce by bounce, each fitted
//! about its best axis by Brent's method (dubouchet2019 Sec. 4.2 with Eq. 16 and Fig. 5, Sec. 5.1
//! recursion; derivations below and in `docs/design/zh-response.md`).
//!
//! **Input → output.** An [`AreaConfig`] (HG `g`, ZH order `N`, bounces `B`, sorted distances `d` in mean
//! free paths, sorted patch angles `θ ∈ [0, π]`, quadrature sizes) → an [`AreaResponse`]: for every
//! `(d, θ)` the unscattered irradiance factor and, for every bounce `b = 1..=B`, an [`AreaEntry`]: the `N`
//! ZH coefficients of the radiance incident at the receiver after exactly `b` scattering events, about
//! the best-fit axis at angle `theta_fit` from the light axis, with the relative L² error of that fit.
//! [`AreaResponse::lobe_at`] interpolates lobe and axis, [`AreaResponse::irradiance`] turns them into
//! irradiance (direct, single, multiple) on a receiver of any orientation.
//!
//! **Canonical setup.** Receiver at the origin, medium `σ_s = 1`, `σ_a = 0`, HG `g`. A differential patch
//! at `s = d a`, `a = +z`, with unit normal `n_e = (sin θ, 0, −cos θ)`: `θ` is the angle between `n_e` and
//! the direction `−a` from the patch toward the receiver (`θ > π/2`: the patch faces away, no direct
//! light, scattered light still arrives). Its radiant intensity is `max(0, n_e·u)` W/sr in direction `u`
//! (1 W/sr along the normal, total power `π`). `ω` points from the receiver toward where light comes from.
//! The configuration is mirror-symmetric about the `xz`-plane.
//!
//! **Single scattering** (Eq. 16 without the direct delta). Along the ray `x_t = tω` the light
//! scattered toward the receiver is `e^{−t} p(cos γ) max(0, n_e·v) e^{−r}/r²`, `r = |x_t − s|`,
//! `v = (x_t − s)/r`. With `ω = cos ψ a + sin ψ e_φ`, `e_φ = (cos φ, sin φ, 0)`, the point emitter's
//! equi-angular variables (module doc of [`super`]: `β ∈ [ψ/2, π/2]`, `t = d sin(2β − ψ)/sin 2β`,
//! `r = d sin ψ/sin 2β`, `cos γ = cos 2β`) give `v = −cos α a + sin α e_φ` with `α = 2β − ψ ∈ [0, π − ψ]`
//! the angle at the patch between `−a` and `v`. So the emission factor is
//! `n_e·v = cos θ cos α + sin θ cos φ sin α = R cos(α − α₀)`, positive on one sub-interval of `α`
//! (computed in closed form): integrating only over it removes the kink of `max(0, ·)` from the rule.
//! `sin ψ L₁(ψ, φ) = (2/d) ∫ e^{−(t + r)} p(cos 2β) max(0, n_e·v) dβ`, bounded everywhere.
//!
//! **Projection and fit (Sec. 4.2).** The full SH vector `L_lm = ∫ L y_lm dω` (order `N`) is integrated
//! over `ψ ∈ [0, π]` (graded Gauss rule) and `φ ∈ [0, π]` (Gauss), doubled: `L(ψ, −φ) = L(ψ, φ)`, so every
//! `m < 0` coefficient (odd in `y`) is exactly zero and is set so. The ZH about a unit axis `u` is
//! `c_l(u) = sqrt(4π/(2l+1)) Σ_m L_lm y_l^m(u)` (`sh::zh_project_about`), and since the `y_l^0(ω·u)` are
//! orthonormal, `‖L − Σ_l c_l y_l^0(·u)‖² = ‖L‖² − Σ_l c_l(u)²`: the best axis maximises
//! `J(u) = Σ_l c_l(u)²`. By the mirror symmetry the maximiser lies in the `xz`-plane,
//! `u(ϑ) = (sin ϑ, 0, cos ϑ)`, a 1-D problem, and `J(ϑ + π) = J(ϑ)` (`c_l(−u) = (−1)^l c_l(u)`). The search:
//! a scan of `J` at [`FIT_SCAN`] equally spaced angles of one period plus `ϑ = 0` (the axis `a`) and the
//! angle of the optimal linear direction (`sh::optimal_linear_direction`, which lies in the plane); the
//! best scanned point and its two neighbouring scan points bracket the maximum (so when the maximum lies
//! between `a` and the optimal linear direction, so does the bracket, and the scan guards against a
//! second, higher maximum elsewhere); then Brent's method ([`brent_max`]: parabolic interpolation through
//! the three best points, falling back to golden-section steps when the parabola's step is not
//! acceptable) to an absolute angle tolerance of `1e-10`. The result is stored as `theta_fit ∈ (−π/2, π/2]`
//! (the antipodal axis is the same fit with odd `c_l` negated), measured from `+z` toward `+x`, the side of
//! the tangential part of `n_e`. The paper stores `d_fit = sin θ_fit`; the angle is stored here because the
//! sine loses half the range (it cannot tell `ϑ` from `π − ϑ`) and its precision near `ϑ = π/2`, and
//! because the angle is what is interpolated linearly between `θ` nodes. `fit_error =
//! sqrt(max(0, ‖L‖² − J))/‖L‖`.
//!
//! **Bounces `b ≥ 2`** (Sec. 5.1 recursion). The bounce-`(b − 1)` radiance at `x_t` is the table itself at
//! `(r, θ_t)`: the patch sees `x_t` in direction `v`, so `cos θ_t = n_e·v`, and the local light axis is
//! `a_t = −v`; the local fitted axis is `u_t = cos θ_fit a_t + sin θ_fit τ`, `τ = (n_e + cos θ_t a_t)/sin θ_t`
//! the unit tangential part of `n_e`. Scattering it toward the receiver is the Funk–Hecke convolution with
//! HG (`c_l → g^l c_l`): `S = Σ_l g^l c_l(r, θ_t) y_l^0(ω·u_t)`, with `ω·a_t = cos 2β` and
//! `ω·τ = (ω·n_e + cos θ_t cos 2β)/sin θ_t` (`τ` is undefined at `sin θ_t = 0`, where the table is
//! symmetric about `a_t` and `ω·τ = 0` is used). Then `sin ψ L_b = (2/d) ∫ e^{−t} r² S dβ` over the full
//! `β` range, projected and fitted as above. `t`, `r`, `cos 2β` do not depend on `φ` or `θ`, so for each
//! `(ψ, β)` node the table is read once in `r` for all `θ` nodes and then reused for every `(φ, θ)`.
//!
//! **Table reading** ([`AreaResponse::lobe_at`]). In `d`, per `θ` node, exactly as the point table
//! (`Response::zh_at`): `ln(e^{d} c_0)` and the shape `c_l/c_0` linear in `ln d` between nodes (fallback:
//! `d e^{d} c` linear when `c_0 ≤ 0`), the power law `(d/d₀)^k`, `k ∈ [−1, 0]` fitted to `c_0` at the first
//! two nodes, below the first node, `e^{−(d − d_last)}` beyond the last one (never adds energy);
//! `theta_fit` linear in `ln d`, held at the ends. Then linear in `cos θ` between `θ` nodes (coefficients,
//! and the axis as the normalised blend of the two unit axes), clamped to the first/last node outside
//! them. The fitted axis is a *line* (`theta_fit` and `theta_fit ± π` are the same fit, with the odd
//! coefficients negated), and it does cross the `±π/2` cut of the stored range (near the patch the light
//! comes from around `n_e`, at `π − θ` from `+z`): every interpolation therefore first replaces the second
//! node by its antipodal representative when the two stored axes are more than `π/2` apart.
//!
//! **Quadrature (deterministic).** Composite Gauss–Legendre rules graded geometrically toward both ends
//! (panels shrinking by 8, [`AreaConfig::levels`] levels) over `ψ` ([`AreaConfig::psi_nodes`] per panel)
//! and along the ray ([`AreaConfig::t_nodes`] per panel; for `b = 1` on the emitting sub-interval), and
//! [`AreaConfig::phi_nodes`] midpoint nodes over `φ ∈ [0, π]` (with their mirror images: equally spaced
//! points on the circle, exact for `cos mφ` with `m < 2·phi_nodes`, so an axially symmetric radiance leaks
//! nothing into `m ≠ 0`, which Gauss–Legendre nodes in `φ` would). No random numbers. Every distance is computed
//! independently (all its `θ` at once) and collected in order, bounces one after another: bit-identical
//! for any rayon thread count.
//!
//! **Measured** (tests in `tests.rs`; walk = `crate::reference::walk` with its `Area` emitter; release).
//! Single scattering, `g = 0.5`, `d = 1`, `θ ∈ {0, π/3, π/2, 2π/3}`, normals `+z`, `+x`, `−z`: the
//! transport (quadrature radiance integrated exactly against the clamped cosine) within 2 % + 4 σ of the
//! walk (0.0–2 % on the cases carrying light; up to 4.7 % = 1.5 σ on a facing-away case of 7e-6). The
//! order-11 ZH about the fitted axis is the approximation of the paper and it shows: within 2 % on the
//! facing normal, but −17 % to −37 % on the side normal `+x` for `θ ≥ π/3` and up to several times a tiny
//! value on normals facing away; `fit_error` reaches 0.35 (production grid), largest near the patch where
//! the light mixes the peak toward the patch with the patch's own emission lobe. All orders at `d = 1`,
//! `g = 0.5`, on the angle nodes `0, 3π/7, 5π/7` (64 distances, 8 angles): order 1 on the facing normal
//! within 1.8 %; orders 2–10 summed within −11 % … +8 % of the walk (per order +2 % … +20 % at `θ = 0`,
//! growing with `b`): the recursion reads the previous bounce's ZH approximation through the 8-node
//! angle interpolation, which is convex (order 1 read half-way between two nodes overestimates by 27 % on
//! the facing normal at `θ = π/2`). Dipole identity (exact, see the tests): bounce 1 within `3e-5` of
//! `c_0`, bounce 2 within `8e-3`. Brent: the fitted `J` is the maximum of a 20 001-point scan, the angle
//! within `2e-4` of the scan's, and the axis lies between `a` and the optimal linear direction in every
//! tested cell. Doubling the quadrature changes `c_0` by `3.4e-4` (bounce 1) and `1.7e-3` (bounce 2; worst
//! at `d = 1e-3`, `θ = π`; `1.3e-3` for `d ≥ 0.01`). Production size (256 distances in `[1e-3, 64]`,
//! 8 angles, `B = 10`, order 11, defaults): 132 s per `g` on 2 threads.
//!
//! **Domain handling.** `d → 0`, `d → ∞` (underflow to 0), `θ = 0, π`, `|g| → 1` and order 1 (no band 1:
//! `theta_fit = 0`) give finite results; query distances are clamped to `[1e-150, ∞]` (NaN → ∞, zero
//! radiance), query angles to the node range (NaN → the first node). Irradiance parts are clamped at 0
//! (ZH ringing); a zero or non-finite receiver normal gives zeros.

mod fit;
#[cfg(test)]
mod tests;

use std::f64::consts::{FRAC_PI_2, PI};

use rayon::prelude::*;

pub use fit::{FIT_SCAN, brent_max};
use fit::{antipode_nearest, fit_axis};

use crate::physics::sh::gauss_legendre;
use crate::physics::{hg, sh};

/// `4π`.
const FOUR_PI: f64 = 4.0 * PI;

/// Largest number of nodes per panel (or over `φ`) accepted in an [`AreaConfig`].
pub const MAX_NODES: usize = 64;

/// Largest number of grading levels accepted in an [`AreaConfig`].
pub const MAX_LEVELS: usize = 12;

/// Ratio between the lengths of consecutive panels of the graded rule.
const GRADING: f64 = 0.125;

/// What to compute.
#[derive(Debug, Clone, PartialEq)]
pub struct AreaConfig {
    /// HG mean cosine, `|g| < 1`.
    pub g: f64,
    /// ZH bands `N` (coefficients `l = 0..N`), in `[1, sh::MAX_ORDER]`; default 11.
    pub order: usize,
    /// Number of bounces `B` tabulated (`b = 1..=B`); default 10.
    pub bounces: usize,
    /// Distances in mean free paths: finite, `> 0`, strictly increasing.
    pub distances: Vec<f64>,
    /// Patch angles `θ` (radians): in `[0, π]`, strictly increasing, at least one.
    pub thetas: Vec<f64>,
    /// Gauss nodes per panel of the graded rule over `ψ`, in `[1, 64]`; default 6.
    pub psi_nodes: usize,
    /// Midpoint nodes over `φ ∈ [0, π]`, in `[1, 64]`; default 10.
    pub phi_nodes: usize,
    /// Gauss nodes per panel of the graded rule along the ray, in `[1, 64]`; default 6.
    pub t_nodes: usize,
    /// Geometric refinement levels of the graded rules toward each end, in `[0, 12]`; default 4
    /// (smallest panel `8⁻⁴ ≈ 2.4e-4` of a half-interval).
    pub levels: usize,
}

impl AreaConfig {
    /// Configuration with the defaults: order 11, 10 bounces, 6 × 10 × 6 nodes, 4 levels (converged to
    /// better than `1e-3` of `c_0` when doubled, see the tests).
    pub fn new(g: f64, distances: Vec<f64>, thetas: Vec<f64>) -> Self {
        Self { g, order: 11, bounces: 10, distances, thetas, psi_nodes: 6, phi_nodes: 10, t_nodes: 6, levels: 4 }
    }
}

/// One tabulated lobe.
#[derive(Debug, Clone, PartialEq)]
pub struct AreaEntry {
    /// ZH coefficients `c_l`, `l < N`, about the fitted axis `(sin theta_fit, 0, cos theta_fit)`.
    pub zh: Vec<f64>,
    /// Angle of the fitted axis from `+z` toward `+x` (the side of the tangential part of `n_e`), in
    /// `(−π/2, π/2]` (radians).
    pub theta_fit: f64,
    /// Relative L² error of the ZH approximation against the full SH projection:
    /// `sqrt(max(0, ‖L‖² − Σ_l c_l²))/‖L‖` (0 when `L = 0`).
    pub fit_error: f64,
}

/// Largest ZH order [`AreaResponse::lobe_at`] interpolates on the stack (larger orders allocate).
const MAX_QUERY_ORDER: usize = 32;

/// Tabulated response of the differential-area emitter.
#[derive(Debug, Clone, PartialEq)]
pub struct AreaResponse {
    /// Tabulated distances, as configured.
    pub distances: Vec<f64>,
    /// Tabulated patch angles, as configured.
    pub thetas: Vec<f64>,
    /// `direct[i][j] = e^{−d}/d² · max(0, cos θ)`: unscattered irradiance per unit `max(0, n·a)`.
    pub direct: Vec<Vec<f64>>,
    /// `bounces[b − 1][i][j]`: the bounce-`b` lobe at `distances[i]`, `thetas[j]`.
    pub bounces: Vec<Vec<Vec<AreaEntry>>>,
    /// `cos θ` of every angle node (the interpolation variable).
    cos_thetas: Vec<f64>,
}

/// Computes the table; bounce `b` reads the table of bounce `b − 1`.
///
/// # Errors
/// A message naming the offending parameter when `g`, `order`, the node counts, `levels`, the distances
/// or the angles are out of range (see [`AreaConfig`]).
pub fn compute(cfg: &AreaConfig) -> Result<AreaResponse, String> {
    hg::validate_g(cfg.g)?;
    if !(1..=sh::MAX_ORDER).contains(&cfg.order) {
        return Err(format!("order = {} is out of range: valid range is [1, {}]", cfg.order, sh::MAX_ORDER));
    }
    for (name, n) in [("psi_nodes", cfg.psi_nodes), ("phi_nodes", cfg.phi_nodes), ("t_nodes", cfg.t_nodes)] {
        if !(1..=MAX_NODES).contains(&n) {
            return Err(format!("{name} = {n} is out of range: valid range is [1, {MAX_NODES}]"));
        }
    }
    if cfg.levels > MAX_LEVELS {
        return Err(format!("levels = {} is out of range: valid range is [0, {MAX_LEVELS}]", cfg.levels));
    }
    super::validate_distances(&cfg.distances)?;
    if cfg.thetas.is_empty() {
        return Err("thetas must not be empty".to_string());
    }
    if let Some(bad) = cfg.thetas.iter().find(|t| !(0.0..=PI).contains(*t)) {
        return Err(format!("theta {bad} is out of range: thetas must lie in [0, pi]"));
    }
    if cfg.thetas.windows(2).any(|w| w[0] >= w[1]) {
        return Err("thetas must be strictly increasing".to_string());
    }
    let direct = cfg
        .distances
        .iter()
        .map(|&d| {
            let unit = (-d).exp() / (d * d);
            cfg.thetas.iter().map(|&t| unit * t.cos().max(0.0)).collect()
        })
        .collect();
    let mut response = AreaResponse {
        distances: cfg.distances.clone(),
        thetas: cfg.thetas.clone(),
        direct,
        bounces: Vec::new(),
        cos_thetas: cfg.thetas.iter().map(|t| t.cos()).collect(),
    };
    let ctx = Context::new(cfg);
    for b in 1..=cfg.bounces {
        let table: Vec<Vec<AreaEntry>> = cfg.distances.par_iter().map(|&d| ctx.cells(&response, b, d)).collect();
        response.bounces.push(table);
    }
    Ok(response)
}

/// A node of a graded rule on `[0, len]`: distances to both ends (each accurate) and weight.
#[derive(Debug, Clone, Copy)]
struct Node {
    lo: f64,
    hi: f64,
    w: f64,
}

/// Composite Gauss–Legendre rule on `[0, len]` graded toward both ends: each half split into `levels + 1`
/// panels shrinking by [`GRADING`] toward its end, each carrying the `base` rule on `[−1, 1]`.
fn graded(len: f64, base: &[(f64, f64)], levels: usize) -> Vec<Node> {
    let half = 0.5 * len;
    let mut out = Vec::with_capacity(2 * base.len() * (levels + 1));
    let mut upper = half;
    for level in 0..=levels {
        let lower = if level == levels { 0.0 } else { half * GRADING.powi(level as i32 + 1) };
        let (mid, rad) = (0.5 * (upper + lower), 0.5 * (upper - lower));
        for &(x, w) in base {
            let u = mid + rad * x;
            out.push(Node { lo: u, hi: len - u, w: rad * w });
            out.push(Node { lo: len - u, hi: u, w: rad * w });
        }
        upper = lower;
    }
    out
}

/// A receiver direction node: the index of its `ψ` node and its `cos φ`.
struct Direction {
    /// Index of its `ψ` node.
    psi: usize,
    /// `cos φ`.
    cos_phi: f64,
}

/// Quantities shared by every distance of a computation.
struct Context {
    g: f64,
    order: usize,
    levels: usize,
    thetas: Vec<f64>,
    /// `(cos θ, sin θ)` of every `θ` node.
    trig: Vec<(f64, f64)>,
    psi: Vec<Node>,
    /// Gauss rule on `[−1, 1]` per panel along the ray.
    ray_rule: Vec<(f64, f64)>,
    /// `φ` nodes on `[0, π]`: `(cos φ, weight)`.
    phi: Vec<(f64, f64)>,
    /// Direction nodes, `ψ`-major.
    dirs: Vec<Direction>,
    /// `2 w_ψ w_φ y_i(ω)` per direction node, `order²` values each (`m < 0` entries unused).
    weighted_sh: Vec<f64>,
    /// `g^l sqrt((2l+1)/(4π))`.
    scatter: Vec<f64>,
}

impl Context {
    fn new(cfg: &AreaConfig) -> Self {
        let psi = graded(PI, &gauss_legendre(cfg.psi_nodes), cfg.levels);
        let nphi = cfg.phi_nodes as f64;
        let phi: Vec<(f64, f64)> =
            (0..cfg.phi_nodes).map(|k| ((PI * (k as f64 + 0.5) / nphi).cos(), PI / nphi)).collect();
        let count = cfg.order * cfg.order;
        let mut dirs = Vec::with_capacity(psi.len() * phi.len());
        let mut weighted_sh = vec![0.0; psi.len() * phi.len() * count];
        let mut k = 0;
        for (i, n) in psi.iter().enumerate() {
            let (sin_psi, cos_psi) = psi_trig(n);
            for &(cos_phi, w_phi) in &phi {
                let sin_phi = (1.0 - cos_phi * cos_phi).max(0.0).sqrt();
                let dir = [sin_psi * cos_phi, sin_psi * sin_phi, cos_psi];
                let slot = &mut weighted_sh[k * count..(k + 1) * count];
                sh::sh_eval_into(cfg.order, dir, slot);
                for y in slot.iter_mut() {
                    *y *= 2.0 * n.w * w_phi;
                }
                dirs.push(Direction { psi: i, cos_phi });
                k += 1;
            }
        }
        let scatter = (0..cfg.order).map(|l| cfg.g.powi(l as i32) * ((2 * l + 1) as f64 / FOUR_PI).sqrt()).collect();
        Self {
            g: cfg.g,
            order: cfg.order,
            levels: cfg.levels,
            thetas: cfg.thetas.clone(),
            trig: cfg.thetas.iter().map(|t| (t.cos(), t.sin())).collect(),
            psi,
            ray_rule: gauss_legendre(cfg.t_nodes),
            phi,
            dirs,
            weighted_sh,
            scatter,
        }
    }

    /// Full SH vectors (order², `m < 0` exactly 0) of the bounce-`b` radiance at distance `d` for every
    /// `θ` node.
    fn projections(&self, table: &AreaResponse, b: usize, d: f64) -> Vec<Vec<f64>> {
        let nt = self.thetas.len();
        let nphi = self.phi.len();
        // sin ψ · L(ψ, φ) for every direction node and θ: [dir][θ].
        let mut radiance = vec![0.0; self.dirs.len() * nt];
        if b == 1 {
            for (k, dir) in self.dirs.iter().enumerate() {
                let n = self.psi[dir.psi];
                for (j, &(cos_t, sin_t)) in self.trig.iter().enumerate() {
                    radiance[k * nt + j] = self.single(d, n, dir.cos_phi, cos_t, sin_t);
                }
            }
        } else {
            let mut rows = vec![0.0; nt * self.order];
            let mut fits = vec![(1.0, 0.0); nt];
            let mut lobe = vec![0.0; self.order];
            for (i, n) in self.psi.iter().enumerate() {
                let (sin_psi, cos_psi) = psi_trig(n);
                let block = &mut radiance[i * nphi * nt..(i + 1) * nphi * nt];
                for x in graded(0.5 * n.hi, &self.ray_rule, self.levels) {
                    let sin_2b = (2.0 * x.hi).sin();
                    let cos_2b = -(2.0 * x.hi).cos();
                    let t = d * (2.0 * x.lo).sin() / sin_2b;
                    let r = d * sin_psi / sin_2b;
                    let decay = (-t).exp();
                    if decay == 0.0 || !r.is_finite() || r <= 0.0 {
                        continue;
                    }
                    table.rows_into(b - 1, r, 0..fits.len(), &mut rows, &mut fits);
                    let (sin_a, cos_a) = (2.0 * x.lo).sin_cos();
                    let factor = 2.0 / d * x.w * decay * r * r;
                    for (jp, &(cos_phi, _)) in self.phi.iter().enumerate() {
                        for (j, &(cos_t, sin_t)) in self.trig.iter().enumerate() {
                            // cos θ_t = n_e·v, ω·n_e, then the local fitted axis (module doc).
                            let cos_local = (cos_t * cos_a + sin_t * cos_phi * sin_a).clamp(-1.0, 1.0);
                            let omega_ne = sin_t * sin_psi * cos_phi - cos_t * cos_psi;
                            let sin_local = ((1.0 - cos_local) * (1.0 + cos_local)).sqrt();
                            let omega_tau = if sin_local > 1e-12 {
                                ((omega_ne + cos_local * cos_2b) / sin_local).clamp(-1.0, 1.0)
                            } else {
                                0.0
                            };
                            let (cf, sf) = table.theta_interp(cos_local, &rows, &fits, &mut lobe);
                            let x_axis = (cf * cos_2b + sf * omega_tau).clamp(-1.0, 1.0);
                            let value = factor * self.convolved(&lobe, x_axis);
                            if value.is_finite() {
                                block[jp * nt + j] += value;
                            }
                        }
                    }
                }
            }
        }
        // Projection on the full SH basis per θ.
        let count = self.order * self.order;
        (0..nt)
            .map(|j| {
                let mut coeffs = vec![0.0; count];
                for k in 0..self.dirs.len() {
                    let v = radiance[k * nt + j];
                    if v == 0.0 {
                        continue;
                    }
                    for (c, y) in coeffs.iter_mut().zip(&self.weighted_sh[k * count..(k + 1) * count]) {
                        *c += v * y;
                    }
                }
                for l in 1..self.order {
                    for m in 1..=l {
                        coeffs[l * (l + 1) - m] = 0.0;
                    }
                }
                coeffs
            })
            .collect()
    }

    /// Entries of bounce `b` at distance `d` for every `θ` node: projection, then the axis fit.
    fn cells(&self, table: &AreaResponse, b: usize, d: f64) -> Vec<AreaEntry> {
        self.projections(table, b, d).iter().map(|c| fit_axis(c, self.order)).collect()
    }

    /// `sin ψ · L₁(ψ, φ)` for the patch at angle `θ` (module doc): `(2/d) ∫ e^{−(t+r)} p(cos 2β) n_e·v dβ`
    /// over the emitting sub-interval of `α = 2β − ψ ∈ [0, π − ψ]`.
    fn single(&self, d: f64, psi: Node, cos_phi: f64, cos_t: f64, sin_t: f64) -> f64 {
        let (ca, sa) = (cos_t, sin_t * cos_phi);
        if ca == 0.0 && sa == 0.0 {
            return 0.0;
        }
        let mut alpha0 = sa.atan2(ca);
        if alpha0 < -FRAC_PI_2 {
            alpha0 += 2.0 * PI;
        }
        let top = psi.hi; // π − ψ
        let (lo, hi) = ((alpha0 - FRAC_PI_2).max(0.0), (alpha0 + FRAC_PI_2).min(top));
        if hi.is_nan() || hi <= lo {
            return 0.0;
        }
        let sin_half = (0.5 * psi.lo).sin();
        let mut sum = 0.0;
        for x in graded(hi - lo, &self.ray_rule, self.levels) {
            let alpha = lo + x.lo;
            // β − ψ/2 = α/2, π/2 − β = ((π − ψ) − α)/2 with π − ψ − α = (top − hi) + x.hi.
            let half_lo = 0.5 * alpha;
            let half_hi = 0.5 * ((top - hi) + x.hi);
            let emission = (ca * alpha.cos() + sa * alpha.sin()).max(0.0);
            let excess = 2.0 * d * sin_half * half_lo.sin() / half_hi.sin();
            let cos_2b = -(2.0 * half_hi).cos();
            // dβ = dα/2.
            sum += 0.5 * x.w * (-(d + excess)).exp() * hg::phase(cos_2b, self.g) * emission;
        }
        let value = 2.0 / d * sum;
        if value.is_finite() { value } else { 0.0 }
    }

    /// `Σ_l c_l g^l y_l^0(x)`.
    fn convolved(&self, c: &[f64], x: f64) -> f64 {
        let (mut p0, mut p1) = (1.0, x);
        let mut sum = 0.0;
        for (l, (cl, s)) in c.iter().zip(&self.scatter).enumerate() {
            let p = match l {
                0 => 1.0,
                1 => x,
                _ => {
                    let lf = (l - 1) as f64;
                    let p2 = ((2.0 * lf + 1.0) * x * p1 - lf * p0) / (lf + 1.0);
                    (p0, p1) = (p1, p2);
                    p2
                }
            };
            sum += cl * s * p;
        }
        sum
    }
}

/// `(sin ψ, cos ψ)` of a graded node on `[0, π]` (`lo = ψ`, `hi = π − ψ`), accurate at both ends.
fn psi_trig(n: &Node) -> (f64, f64) {
    if n.lo <= n.hi { (n.lo.sin(), n.lo.cos()) } else { (n.hi.sin(), -n.hi.cos()) }
}

impl AreaResponse {
    /// Rebuilds a response from stored parts (a table file), checking what the lookups index: at least
    /// one distance (positive, strictly increasing), angles in `[0, π]` strictly increasing, `direct`
    /// `[d][θ]`, `bounces[b − 1][d][θ]` with lobes of one common order ≥ 1, all values finite.
    ///
    /// # Errors
    /// A message naming the first inconsistency.
    pub fn from_parts(
        distances: Vec<f64>,
        thetas: Vec<f64>,
        direct: Vec<Vec<f64>>,
        bounces: Vec<Vec<Vec<AreaEntry>>>,
    ) -> Result<Self, String> {
        let (nd, nt) = (distances.len(), thetas.len());
        if nd == 0 || !distances.iter().all(|d| d.is_finite() && *d > 0.0) || distances.windows(2).any(|w| w[0] >= w[1])
        {
            return Err("area distances must be positive and strictly increasing".into());
        }
        if nt == 0 || !thetas.iter().all(|t| (0.0..=PI).contains(t)) || thetas.windows(2).any(|w| w[0] >= w[1]) {
            return Err("area angles must lie in [0, pi] and increase strictly".into());
        }
        if direct.len() != nd || direct.iter().any(|r| r.len() != nt || r.iter().any(|v| !v.is_finite())) {
            return Err("area direct term has the wrong shape or a non-finite value".into());
        }
        let order = bounces.first().and_then(|t| t.first()).and_then(|r| r.first()).map_or(1, |e| e.zh.len());
        for table in &bounces {
            if table.len() != nd
                || table.iter().any(|row| {
                    row.len() != nt
                        || row.iter().any(|e| {
                            e.zh.len() != order
                                || order == 0
                                || !e.theta_fit.is_finite()
                                || e.zh.iter().any(|c| !c.is_finite())
                        })
                })
            {
                return Err("area lobes have the wrong shape or a non-finite value".into());
            }
        }
        let cos_thetas = thetas.iter().map(|t| t.cos()).collect();
        Ok(Self { distances, thetas, direct, bounces, cos_thetas })
    }

    fn order(&self) -> usize {
        self.bounces.first().and_then(|t| t.first()).and_then(|r| r.first()).map_or(0, |e| e.zh.len())
    }

    /// The rows of bounce `b` (`1 ≤ b ≤ B`) at distance `d` for every `θ` node, interpolated in `d` (module
    /// doc): `rows[j·N + l]`, and the fitted axis as `fits[j] = (cos θ_fit, sin θ_fit)`.
    ///
    /// Only the `θ` nodes in `nodes` are computed: `rows` and `fits` hold them from `nodes.start` on.
    fn rows_into(&self, b: usize, d: f64, nodes: std::ops::Range<usize>, rows: &mut [f64], fits: &mut [(f64, f64)]) {
        let table = &self.bounces[b - 1];
        let ds = &self.distances;
        let order = self.order();
        let d = if d.is_nan() { f64::INFINITY } else { d.max(1e-150) };
        let n = ds.len();
        // The distance bracket is the same for every θ row.
        let inner = n > 1 && d > ds[0] && d < ds[n - 1];
        let (i, lambda) = if inner {
            let i = ds.partition_point(|&x| x <= d) - 1;
            (i, (d / ds[i]).ln() / (ds[i + 1] / ds[i]).ln())
        } else {
            (0, 0.0)
        };
        for (k, (out, fit)) in rows.chunks_mut(order).zip(fits.iter_mut()).take(nodes.len()).enumerate() {
            let j = nodes.start + k;
            let entry = |i: usize| &table[i][j];
            if d <= ds[0] {
                let (e0, mut scale) = (entry(0), 1.0);
                if n > 1 && e0.zh[0] > 0.0 && entry(1).zh[0] > 0.0 {
                    let k = ((e0.zh[0] / entry(1).zh[0]).ln() / (ds[0] / ds[1]).ln()).clamp(-1.0, 0.0);
                    scale = (d / ds[0]).powf(k);
                }
                for (o, c) in out.iter_mut().zip(&e0.zh) {
                    *o = c * scale;
                }
                *fit = (e0.theta_fit.cos(), e0.theta_fit.sin());
                continue;
            }
            if d >= ds[n - 1] {
                let decay = (-(d - ds[n - 1])).exp();
                for (o, c) in out.iter_mut().zip(&entry(n - 1).zh) {
                    *o = c * decay;
                }
                *fit = (entry(n - 1).theta_fit.cos(), entry(n - 1).theta_fit.sin());
                continue;
            }
            let (d0, d1) = (ds[i], ds[i + 1]);
            let (e0, e1) = (entry(i), entry(i + 1));
            let (r0, r1) = (&e0.zh, &e1.zh);
            // The axis is a line: if the stored angles differ by more than π/2, the nearer representative
            // of the second is its antipode, with the odd coefficients negated.
            let (f1, flip) = antipode_nearest(e0.theta_fit, e1.theta_fit);
            let angle = (1.0 - lambda) * e0.theta_fit + lambda * f1;
            *fit = (angle.cos(), angle.sin());
            if r0[0] > 0.0 && r1[0] > 0.0 {
                let log_c0 = (1.0 - lambda) * (r0[0].ln() + (d0 - d)) + lambda * (r1[0].ln() + (d1 - d));
                let c0 = log_c0.exp();
                for (l, ((o, a), b)) in out.iter_mut().zip(r0).zip(r1).enumerate() {
                    let b = if flip && l % 2 == 1 { -b } else { *b };
                    *o = c0 * ((1.0 - lambda) * (a / r0[0]) + lambda * (b / r1[0]));
                }
                continue;
            }
            let w0 = (1.0 - lambda) * (-(d - d0)).exp() * d0 / d;
            let w1 = lambda * (d1 - d).min(700.0).exp() * d1 / d;
            for (l, ((o, c0), c1)) in out.iter_mut().zip(r0).zip(r1).enumerate() {
                let c1 = if flip && l % 2 == 1 { -c1 } else { *c1 };
                let second = if c1 == 0.0 { 0.0 } else { w1 * c1 };
                *o = w0 * c0 + second;
            }
        }
    }

    /// Linear interpolation in `cos θ` of rows from [`AreaResponse::rows_into`] into `lobe` (projectively:
    /// the second node's axis is replaced by its antipode, odd coefficients negated, when that is nearer);
    /// returns the unit axis as `(cos θ_fit, sin θ_fit)`. `cos_theta` outside the nodes reads the end node.
    fn theta_interp(&self, cos_theta: f64, rows: &[f64], fits: &[(f64, f64)], lobe: &mut [f64]) -> (f64, f64) {
        self.theta_interp_from(cos_theta, 0, rows, fits, lobe)
    }

    /// The `θ` nodes [`AreaResponse::theta_interp`] reads for `cos_theta` (one or two).
    fn theta_nodes(&self, cos_theta: f64) -> std::ops::Range<usize> {
        let n = self.thetas.len();
        if cos_theta.is_nan() || n == 1 || cos_theta >= self.cos_thetas[0] {
            return 0..1;
        }
        if cos_theta <= self.cos_thetas[n - 1] {
            return n - 1..n;
        }
        let j = self.cos_thetas.partition_point(|&c| c > cos_theta) - 1;
        j..j + 2
    }

    /// [`AreaResponse::theta_interp`] with `rows`/`fits` holding the nodes from `first` on (at least
    /// [`AreaResponse::theta_nodes`] of `cos_theta`).
    fn theta_interp_from(
        &self,
        cos_theta: f64,
        first: usize,
        rows: &[f64],
        fits: &[(f64, f64)],
        lobe: &mut [f64],
    ) -> (f64, f64) {
        let order = lobe.len();
        let row = |j: usize| &rows[(j - first) * order..(j - first + 1) * order];
        let fit = |j: usize| fits[j - first];
        // Nodes are increasing in θ, i.e. decreasing in cos θ.
        let nodes = self.theta_nodes(cos_theta);
        if nodes.len() == 1 {
            lobe.copy_from_slice(row(nodes.start));
            return fit(nodes.start);
        }
        let j = nodes.start;
        let (c0, c1) = (self.cos_thetas[j], self.cos_thetas[j + 1]);
        let w = ((c0 - cos_theta) / (c0 - c1)).clamp(0.0, 1.0);
        let (a, b) = (fit(j), fit(j + 1));
        let sign = if a.0 * b.0 + a.1 * b.1 < 0.0 { -1.0 } else { 1.0 };
        for (l, ((o, x), y)) in lobe.iter_mut().zip(row(j)).zip(row(j + 1)).enumerate() {
            let y = if l % 2 == 1 { sign * y } else { *y };
            *o = (1.0 - w) * x + w * y;
        }
        let axis = ((1.0 - w) * a.0 + w * sign * b.0, (1.0 - w) * a.1 + w * sign * b.1);
        let len = axis.0.hypot(axis.1);
        if len > 0.0 { (axis.0 / len, axis.1 / len) } else { a }
    }

    /// Lobe of bounce `b ≥ 1` at distance `d` and patch angle `theta` (module doc: interpolated in `ln d`
    /// and `θ`, extrapolated in `d`, clamped in `θ`), with its unit axis `(sin θ_fit, 0, cos θ_fit)`.
    /// `b = 0` or `b > B` gives zeros about `+z`; `d` is clamped to `[1e-150, ∞]` (NaN → ∞), a NaN `theta`
    /// reads the first node.
    pub fn lobe_at(&self, b: usize, d: f64, theta: f64) -> (Vec<f64>, [f64; 3]) {
        let order = self.order();
        let mut lobe = vec![0.0; order];
        if !(1..=self.bounces.len()).contains(&b) || order == 0 {
            return (lobe, [0.0, 0.0, 1.0]);
        }
        let cos_theta = if theta.is_nan() { f64::NAN } else { theta.clamp(0.0, PI).cos() };
        let nodes = self.theta_nodes(cos_theta);
        let first = nodes.start;
        let mut rows = [0.0; 2 * MAX_QUERY_ORDER];
        let mut fits = [(1.0, 0.0); 2];
        if order > MAX_QUERY_ORDER {
            let (mut rows, mut fits) = (vec![0.0; nodes.len() * order], vec![(1.0, 0.0); nodes.len()]);
            self.rows_into(b, d, nodes, &mut rows, &mut fits);
            let (c, s) = self.theta_interp_from(cos_theta, first, &rows, &fits, &mut lobe);
            return (lobe, [s, 0.0, c]);
        }
        let used = nodes.len();
        self.rows_into(b, d, nodes, &mut rows[..used * order], &mut fits[..used]);
        let (c, s) = self.theta_interp_from(cos_theta, first, &rows[..used * order], &fits[..used], &mut lobe);
        (lobe, [s, 0.0, c])
    }

    /// Irradiance `(direct, single, multiple)` at distance `d`, patch angle `theta`, on a receiver with
    /// normal `normal` (canonical frame: light axis `+z`, patch normal `(sin θ, 0, −cos θ)`; any finite
    /// non-zero vector, normalised): `b = 0` (`e^{−d}/d² max(0, cos θ) max(0, n·a)`), `b = 1` and
    /// `b = 2..=B`, each clamped at 0. A zero or non-finite normal gives zeros.
    pub fn irradiance(&self, d: f64, theta: f64, normal: [f64; 3]) -> (f64, f64, f64) {
        let len = normal.iter().map(|c| c * c).sum::<f64>().sqrt();
        if !(len.is_finite() && len > 0.0) {
            return (0.0, 0.0, 0.0);
        }
        let n = normal.map(|c| c / len);
        let d = if d.is_nan() { f64::INFINITY } else { d.max(1e-150) };
        let ts = &self.thetas;
        let theta_c = if theta.is_nan() { ts[0] } else { theta.clamp(0.0, PI) };
        let unit = if d.is_infinite() { 0.0 } else { (-d).exp() / (d * d) };
        let direct = unit * theta_c.cos().max(0.0) * n[2].max(0.0);
        let part = |b: usize| {
            let (lobe, axis) = self.lobe_at(b, d, theta);
            sh::zh_irradiance(&lobe, axis, n)
        };
        let single = if self.bounces.is_empty() { 0.0 } else { part(1) };
        let multiple: f64 = (2..=self.bounces.len()).map(part).sum();
        let clean = |x: f64| if x.is_finite() { x.max(0.0) } else { 0.0 };
        (clean(direct), clean(single), clean(multiple))
    }
}
