//! Per-slice incremental hierarchical integration (baran2010 Sec. 4–5, Fig. 6) with visibility
//! prefiltering into depth modes (Sec. 7) and textured light (Sec. 6, last paragraph).
//!
//! **Input → output.** One [`Slice`] (view-ray angles `β`, rectified depths `γ_end`), the frame's
//! [`Factorization`], the shadow map, light and medium → the in-scatter at each of the slice's `β`
//! samples.
//!
//! Steps: (1) rectify the shadow map: for each `γ` bin, sample the blocker on the light ray at 4
//! sub-positions (1 without prefiltering), convert each blocker to the first view ray `β_k` at or
//! past it (compared as `cot β`, monotone, so no angles are formed), cluster these into modes
//! (terminations at most one `β` step apart merge; then the closest modes merge until at most
//! `depth_modes` remain), each with its weight (fraction of sub-samples; `M` is read at the bin's
//! centre sub-sample); (2) build the Fenwick tree of `N`-vectors `Γ_i(γ)·M(α, γ)·Δγ` (`M` = light texture ×
//! spot falloff along the light ray, × the directional light's entry attenuation `e^{−σ_t a_entry}`); (3) sweep `β` upwards: remove each mode's fraction of its bin
//! when the sweep passes the mode's angle (the last mode of a fully blocked bin removes the exact
//! remainder, so the bin becomes exactly 0), query the prefix sum up to the fractional `γ_end`, and
//! combine with `B_i(β)`.

use std::time::Instant;

use glam::DVec3;

use super::factor::Factorization;
use super::rectify::{Geo, Setup, Slice};
use super::tree::FenwickTree;
use super::{EpiLight, EpiMedium, EpipolarOptions, MAX_LIGHT_GAIN, ShadowMap, modulation};

/// Results of one slice.
#[derive(Debug, Clone, PartialEq)]
pub struct SliceResult {
    /// In-scatter per `β` sample.
    pub values: Vec<[f32; 3]>,
    /// CPU time of shadow rectification and depth modes \[ns\].
    pub prefilter_ns: u64,
    /// CPU time of the tree build and sweep \[ns\].
    pub integrate_ns: u64,
    /// Whether a light ray of the slice needs a gain above [`MAX_LIGHT_GAIN`] (its `values` are then
    /// empty and its pixels ray marched).
    pub over_gain: bool,
}

/// Where the light ray `γ` of the slice with axis `u` is blocked, as `cot β` of the view ray through
/// the blocker (`cot` decreases with `β`, so no angle is formed), `None` when nothing blocks it; and
/// a point on the light ray (where the texture and falloff are read).
pub fn blocker_cot(geo: Geo, shadow: &ShadowMap, eye: DVec3, u: DVec3, gamma: f64) -> (Option<f64>, DVec3) {
    let t = geo.toward();
    match geo {
        Geo::Directional { .. } => {
            let q = eye + gamma * u;
            let cot = match shadow.blocker_and_depth(q) {
                // The blocker is at q − (b + bias − z)·t: along t by −(b + bias − z), along u by γ.
                Some((b, z)) if b.is_finite() && gamma > 0.0 => Some(-(b + shadow.bias - z) / gamma),
                _ => None,
            };
            (cot, q)
        }
        Geo::Spot { pos, .. } => {
            let w = gamma.cos() * (-t) + gamma.sin() * u;
            let q = pos + w;
            let cot = match shadow.blocker_and_depth(q) {
                Some((b, _)) if b.is_finite() => {
                    let rel = pos + (b + shadow.bias) * w - eye;
                    let bu = rel.dot(u);
                    (bu > 0.0).then(|| rel.dot(t) / bu)
                }
                _ => None,
            };
            (cot, q)
        }
    }
}

/// A point on the light ray `γ` of the slice with axis `u` (module doc of [`super::rectify`]).
pub fn light_point(geo: Geo, eye: DVec3, u: DVec3, gamma: f64) -> DVec3 {
    match geo {
        Geo::Directional { .. } => eye + gamma * u,
        Geo::Spot { pos, t, .. } => pos + gamma.cos() * (-t) + gamma.sin() * u,
    }
}

/// Clusters sorted termination indices (`≥ never` = never) into at most `max_modes` modes
/// `(index, count)` written to `out`, returning how many: indices at most one `β` step apart join a
/// mode, then the closest modes merge; a mode terminates at the rounded mean of its members.
fn modes(sorted: &[usize], never: usize, max_modes: usize, out: &mut [(usize, u32); 4]) -> usize {
    // (sum of indices, count, last index) per cluster; "never" forms its own cluster.
    let mut cl = [(0usize, 0u32, 0usize); 4];
    let mut n = 0;
    for &k in sorted.iter().take(4) {
        let k = k.min(never);
        if n > 0 && (k == never) == (cl[n - 1].2 == never) && k <= cl[n - 1].2 + 1 {
            cl[n - 1].0 += k;
            cl[n - 1].1 += 1;
            cl[n - 1].2 = k;
        } else {
            cl[n] = (k, 1, k);
            n += 1;
        }
    }
    let mean = |c: &(usize, u32, usize)| c.0 as f64 / f64::from(c.1);
    while n > max_modes.max(1) {
        let k = (0..n - 1)
            .min_by(|&a, &b| (mean(&cl[a + 1]) - mean(&cl[a])).total_cmp(&(mean(&cl[b + 1]) - mean(&cl[b]))))
            .unwrap_or(0);
        let next = cl[k + 1];
        cl[k].0 += next.0;
        cl[k].1 += next.1;
        cl[k].2 = next.2;
        cl.copy_within(k + 2..n, k + 1);
        n -= 1;
    }
    for (o, c) in out.iter_mut().zip(&cl[..n]) {
        *o = if c.2 == never { (never, c.1) } else { (mean(c).round() as usize, c.1) };
    }
    n
}

/// First index `p` with `cots[p] ≤ c` (`cots` decreasing), searched from the guess `g` outwards (the
/// blockers of neighbouring bins usually terminate at nearby view rays).
fn first_at_or_below(cots: &[f64], c: f64, g: usize) -> usize {
    let n = cots.len();
    let mut p = g.min(n);
    if p < n && cots[p] > c {
        // Gallop upwards, then bisect.
        let mut step = 1;
        let mut lo = p + 1;
        loop {
            let hi = (p + step).min(n);
            if hi == n || cots[hi] <= c {
                return lo + cots[lo..hi].partition_point(|&x| x > c);
            }
            lo = hi + 1;
            p = hi;
            step *= 2;
        }
    }
    // cots[p] ≤ c (or p = n): gallop downwards.
    let mut step = 1;
    let mut hi = p;
    loop {
        let lo = hi.saturating_sub(step);
        if lo == 0 || cots[lo] > c {
            return lo + cots[lo..hi].partition_point(|&x| x > c);
        }
        hi = lo;
        step *= 2;
    }
}

/// Step (1) of [`integrate_slice`]: the slice's rectified shadow map as depth-mode events.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Prefiltered {
    /// `(β index, γ bin, sub-sample count)` per mode that terminates inside the slice, bins in
    /// increasing order and modes by increasing `β` within a bin.
    pub events: Vec<(u32, u32, u32)>,
    /// Whether the event removes its bin's exact remainder (the last mode of a fully blocked bin).
    pub exact_last: Vec<bool>,
    /// Light modulation at each bin's centre (texture × spot falloff; for a directional light times
    /// the per-light-ray attenuation `e^{−σ_t a_entry}`, 0 where the light ray misses the medium).
    pub modul: Vec<[f64; 3]>,
    /// Largest directional entry gain over the bins (1 for spot lights).
    pub gain: f64,
}

/// Rectifies the shadow map of slice `s` over its first `nb` bins of width `dg` into depth modes
/// (module doc, step 1).
#[allow(clippy::too_many_arguments)]
pub(crate) fn prefilter_slice(
    setup: &Setup,
    s: &Slice,
    nb: usize,
    dg: f64,
    light: &EpiLight,
    shadow: &ShadowMap,
    medium: &EpiMedium,
    opts: &EpipolarOptions,
) -> Prefiltered {
    let nbeta = s.betas.len();
    let sub = if opts.depth_modes > 1 { 4 } else { 1 };
    let cots: Vec<f64> = s.betas.iter().map(|b| b.cos() / b.sin()).collect();
    let directional = matches!(light, EpiLight::Directional { .. });
    let mut gain = 1.0f64;
    let mut events: Vec<(u32, u32, u32)> = Vec::new();
    let mut exact_last: Vec<bool> = Vec::new();
    let mut modul = vec![[1.0f64; 3]; nb];
    let mut ks = [0usize; 4];
    let mut md = [(0usize, 0u32); 4];
    let mut guess = 0usize;
    for (j, m) in modul.iter_mut().enumerate() {
        for (q, k) in ks.iter_mut().enumerate().take(sub) {
            let g = (j as f64 + (q as f64 + 0.5) / sub as f64) * dg;
            let (cot, _) = blocker_cot(setup.geo, shadow, setup.eye, s.u, g);
            // First view ray at or past the blocker: cot β_k ≤ cot β_blocker.
            *k = match cot {
                Some(c) => {
                    guess = first_at_or_below(&cots, c, guess);
                    guess
                }
                None => nbeta,
            };
        }
        let q = light_point(setup.geo, setup.eye, s.u, (j as f64 + 0.5) * dg);
        *m = modulation(light, &shadow.frame, q);
        if directional {
            let att = match medium.light_entry(q, setup.geo.toward()) {
                Some(a) => medium.light_attenuation(a),
                None => [0.0; 3],
            };
            gain = att.iter().fold(gain, |g, &x| g.max(x));
            for c in 0..3 {
                m[c] *= att[c];
            }
        }
        let k = &mut ks[..sub];
        k.sort_unstable();
        let nm = modes(k, nbeta, opts.depth_modes, &mut md);
        let first = events.len();
        let mut applied = 0;
        for &(k, count) in &md[..nm] {
            if k < nbeta {
                events.push((k as u32, j as u32, count));
                exact_last.push(false);
                applied += count;
            }
        }
        if applied as usize == sub && events.len() > first {
            let last = exact_last.len() - 1;
            exact_last[last] = true;
        }
    }
    Prefiltered { events, exact_last, modul, gain }
}

/// Integrates one slice (module doc).
pub fn integrate_slice(
    setup: &Setup,
    fac: &Factorization,
    s: &Slice,
    light: &EpiLight,
    shadow: &ShadowMap,
    medium: &EpiMedium,
    opts: &EpipolarOptions,
) -> SliceResult {
    let t0 = Instant::now();
    let nbeta = s.betas.len();
    let dg = fac.dgamma;
    let gmax = s.gend.iter().copied().fold(0.0f64, f64::max);
    let nb = (((gmax / dg).ceil() as usize) + 1).clamp(1, fac.bins);
    let ch = if fac.kernels == 3 || light.texture().is_some() { 3 } else { 1 };
    let rank = fac.rank;
    let lanes = ch * rank;
    let sub = if opts.depth_modes > 1 { 4 } else { 1 };

    // (1) Rectified shadow map with depth modes → events (β index, bin, sub-sample count).
    let Prefiltered { events, exact_last, modul, gain } =
        prefilter_slice(setup, s, nb, dg, light, shadow, medium, opts);
    let t1 = Instant::now();
    if gain > MAX_LIGHT_GAIN {
        return SliceResult {
            values: Vec::new(),
            prefilter_ns: (t1 - t0).as_nanos() as u64,
            integrate_ns: 0,
            over_gain: true,
        };
    }

    // (2) Tree of Γ_i(γ)·M·Δγ.
    let mut vals = vec![0.0f64; nb * lanes];
    for j in 0..nb {
        for c in 0..ch {
            let k = c.min(fac.kernels - 1);
            let m = if ch == 1 { modul[j][0] } else { modul[j][c] };
            for i in 0..rank {
                vals[j * lanes + c * rank + i] = fac.gamma_fn[(k * rank + i) * fac.bins + j] * m * dg;
            }
        }
    }
    let mut tree = FenwickTree::new(&vals, lanes);
    let original: Vec<i64> = tree.leaves().to_vec();

    // Counting sort of the events by β index (stable: bins in increasing order within one β).
    let mut start = vec![0usize; nbeta + 1];
    for e in &events {
        start[e.0 as usize + 1] += 1;
    }
    for k in 0..nbeta {
        start[k + 1] += start[k];
    }
    let mut order = vec![0usize; events.len()];
    let mut fill = start.clone();
    for (idx, e) in events.iter().enumerate() {
        order[fill[e.0 as usize]] = idx;
        fill[e.0 as usize] += 1;
    }

    // (3) Sweep.
    let sig_s = medium.sigma_s_clean();
    let strength = light.strength();
    let scale: [f64; 3] =
        [0, 1, 2].map(|c| sig_s[c] * if strength[c].is_finite() { strength[c].max(0.0) } else { 0.0 });
    let mut ints = vec![0i64; lanes];
    let mut sums = vec![0.0f64; lanes];
    let mut scratch = Vec::with_capacity(lanes);
    let mut values = Vec::with_capacity(nbeta);
    let mut bvals = vec![0.0f64; fac.kernels * rank];
    for k in 0..nbeta {
        for &idx in &order[start[k]..start[k + 1]] {
            let (_, j, count) = events[idx];
            let j = j as usize;
            let w = f64::from(count) / sub as f64;
            tree.remove_fraction(j, &original[j * lanes..(j + 1) * lanes], w, exact_last[idx], &mut scratch);
        }
        let beta = s.betas[k];
        tree.prefix_frac(s.gend[k] / dg, &mut ints, &mut sums);
        fac.b_all(beta, &mut bvals);
        let mut px = [0.0f32; 3];
        for (c, p) in px.iter_mut().enumerate() {
            let cl = if ch == 1 { 0 } else { c };
            let kk = c.min(fac.kernels - 1);
            let acc: f64 = (0..rank).map(|i| bvals[kk * rank + i] * sums[cl * rank + i]).sum();
            let v = acc * scale[c];
            *p = if v.is_finite() && v > 0.0 { v as f32 } else { 0.0 };
        }
        values.push(px);
    }
    let t2 = Instant::now();
    SliceResult {
        values,
        prefilter_ns: (t1 - t0).as_nanos() as u64,
        integrate_ns: (t2 - t1).as_nanos() as u64,
        over_gain: false,
    }
}
