//! The Fenwick half tree of baran2010 Sec. 5: prefix sums of `N`-vectors with `O(log n)` update and
//! query, `1.5·n` storage (the half tree plus the complete leaf level for the fractional query).
//!
//! **Input → output.** `n` leaves of `lanes` values each → prefix sums `Σ_{k<q} b[k]` per lane,
//! under point updates (the sweep's "set to zero").
//!
//! **Stability (mitigation of the floating-point residue).** Setting an entry to zero by subtracting
//! its value in floating point leaves residue in every ancestor, and thousands of updates accumulate
//! it into drifting or negative sums. Here values are **integer-scaled**: each lane's values are
//! quantised once to `i64` with a power-of-two scale chosen so that `n · max|value|` stays below 2⁶²
//! (relative resolution ≈ 2⁻⁵⁰·n of the lane's largest value). Integer additions are exact and
//! associative, so a prefix sum always equals the brute-force sum of the current leaves, an entry set
//! to zero is exactly zero, and sums of non-negative leaves are never negative — after any number of
//! updates. Converting back multiplies by the inverse scale (one rounding).

/// Integer-scaled Fenwick tree of `lanes`-vectors (module doc).
#[derive(Debug, Clone, PartialEq)]
pub struct FenwickTree {
    n: usize,
    lanes: usize,
    /// 1-based half tree: node `i` holds the sum of leaves `(i − lowbit(i), i]`, lane-interleaved.
    tree: Vec<i64>,
    /// Current leaf values (0-based), lane-interleaved.
    leaf: Vec<i64>,
    /// Per lane: quantisation scale (value = integer / scale).
    scale: Vec<f64>,
}

impl FenwickTree {
    /// A tree over `values` (`n · lanes`, leaf-major: `values[k · lanes + lane]`), built in `O(n)`.
    /// Non-finite values count as 0.
    pub fn new(values: &[f64], lanes: usize) -> FenwickTree {
        let lanes = lanes.max(1);
        let n = values.len() / lanes;
        let mut maxabs = vec![0.0f64; lanes];
        for k in 0..n {
            for (l, m) in maxabs.iter_mut().enumerate() {
                let v = values[k * lanes + l];
                if v.is_finite() {
                    *m = m.max(v.abs());
                }
            }
        }
        let bound = 2f64.powi(62) / (n.max(1) as f64);
        let scale: Vec<f64> =
            maxabs.iter().map(|&m| if m > 0.0 { 2f64.powi((bound / m).log2().floor() as i32) } else { 1.0 }).collect();
        let mut leaf = vec![0i64; n * lanes];
        for k in 0..n {
            for l in 0..lanes {
                let v = values[k * lanes + l];
                // Truncation (|error| < 1 unit, i.e. 2⁻⁶²·n·max): cheaper than rounding.
                leaf[k * lanes + l] = if v.is_finite() { (v * scale[l]) as i64 } else { 0 };
            }
        }
        let mut tree = vec![0i64; (n + 1) * lanes];
        tree[lanes..].copy_from_slice(&leaf);
        for i in 1..=n {
            let j = i + (i & i.wrapping_neg());
            if j <= n {
                for l in 0..lanes {
                    tree[j * lanes + l] += tree[i * lanes + l];
                }
            }
        }
        FenwickTree { n, lanes, tree, leaf, scale }
    }

    /// Number of leaves.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether there are no leaves.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Values per leaf.
    pub fn lanes(&self) -> usize {
        self.lanes
    }

    /// Current integer leaf `k`, lane `l`.
    pub fn leaf_int(&self, k: usize, l: usize) -> i64 {
        self.leaf[k * self.lanes + l]
    }

    /// All current integer leaves, leaf-major (`k · lanes + lane`).
    pub fn leaves(&self) -> &[i64] {
        &self.leaf
    }

    /// Adds the integers `delta` (per lane) to leaf `k`.
    pub fn add_int(&mut self, k: usize, delta: &[i64]) {
        for (lf, d) in self.leaf[k * self.lanes..(k + 1) * self.lanes].iter_mut().zip(delta) {
            *lf += d;
        }
        let mut i = k + 1;
        while i <= self.n {
            let row = &mut self.tree[i * self.lanes..(i + 1) * self.lanes];
            for (t, d) in row.iter_mut().zip(delta) {
                *t += d;
            }
            i += i & i.wrapping_neg();
        }
    }

    /// Sets leaf `k` to zero exactly.
    pub fn zero(&mut self, k: usize) {
        let delta: Vec<i64> = (0..self.lanes).map(|l| -self.leaf[k * self.lanes + l]).collect();
        self.add_int(k, &delta);
    }

    /// Subtracts the fraction `w ∈ [0, 1]` of `original` (the leaf's integer values at build time) from
    /// leaf `k`; with `exact_rest` the whole remaining value is subtracted instead (the leaf becomes
    /// exactly 0).
    pub fn remove_fraction(&mut self, k: usize, original: &[i64], w: f64, exact_rest: bool, scratch: &mut Vec<i64>) {
        scratch.clear();
        for (&cur, &orig) in self.leaf[k * self.lanes..(k + 1) * self.lanes].iter().zip(original) {
            let d = if exact_rest { cur } else { (orig as f64 * w).round() as i64 };
            scratch.push(-d);
        }
        let delta = std::mem::take(scratch);
        self.add_int(k, &delta);
        *scratch = delta;
    }

    /// Integer prefix sums `Σ_{k<q} leaf[k]` per lane into `out` (`q` clamped to `n`).
    pub fn prefix_int(&self, q: usize, out: &mut [i64]) {
        out.iter_mut().for_each(|o| *o = 0);
        let mut i = q.min(self.n);
        while i > 0 {
            let row = &self.tree[i * self.lanes..(i + 1) * self.lanes];
            for (o, t) in out.iter_mut().zip(row) {
                *o += t;
            }
            i &= i - 1;
        }
    }

    /// Prefix sum up to the fractional leaf position `x ≥ 0` (Sec. 5: the query at `⌊x⌋` plus the
    /// fraction of leaf `⌊x⌋`, i.e. the lerp of the queries at `⌊x⌋` and `⌈x⌉`), per lane, as `f64`.
    pub fn prefix_frac(&self, x: f64, ints: &mut [i64], out: &mut [f64]) {
        let x = if x.is_finite() { x.max(0.0) } else { self.n as f64 };
        let q = (x.floor() as usize).min(self.n);
        let f = if q < self.n { x - q as f64 } else { 0.0 };
        self.prefix_int(q, ints);
        for l in 0..self.lanes {
            let mut v = ints[l] as f64;
            if f > 0.0 {
                v += f * self.leaf[q * self.lanes + l] as f64;
            }
            out[l] = v / self.scale[l];
        }
    }

    /// Lane `l`'s quantisation scale.
    pub fn scale(&self, l: usize) -> f64 {
        self.scale[l]
    }
}
