//! Epipolar rectification and unrectification (baran2010 Sec. 3, slice distribution Sec. 8, spot
//! lights Sec. 9).
//!
//! **Input → output.** Camera, depth image, light and options → a [`Setup`]: the epipole, the
//! epipolar slices (screen direction, world-space half-plane axis `u`), per slice the view-ray
//! angles `β` (angle between the view ray and the direction from the eye to the light) and the
//! rectified depth `D[β]` expressed as the light-ray coordinate `γ` where the view ray ends
//! (directional: `γ = d·sin β`, the distance of the end point from the eye's light ray; spot: the
//! angle at the light between the eye and the end point). [`Setup::unrectify`] maps slice results back
//! to a pixel.
//!
//! **Slice distribution (Sec. 8).** For each screen edge the epipole lies strictly inside of (an
//! "exit edge"), with `h` the epipole's distance to the edge's line in pixels and `x` the position
//! along the edge from the foot of the perpendicular, slices pass through `x(α) = h·sinh(α)` for
//! `α` stepped by `1/(h·density)`: the orthogonal distance between neighbouring slices is at most one
//! pixel at the edge (and less nearer the epipole), so no pixel is more than half a pixel from a
//! slice. An epipole at infinity (light direction ⟂ view axis) is placed 10⁷ px away along the light's
//! screen direction; the world-space geometry of each slice is taken from its own pixels, so it stays
//! exact.

use glam::DVec3;
use rayon::prelude::*;

use super::integrate::SliceResult;
use super::{DistanceImage, EpiLight, EpipolarOptions, ViewCamera, sample_depth, view_segment};

/// The epipolar geometry of the light relative to the eye.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Geo {
    /// Directional light: `t` points to the light (against its travel direction).
    Directional {
        /// Unit direction to the light.
        t: DVec3,
    },
    /// Spot light at `pos`, `dist` from the eye, `t = (pos − eye)/dist`.
    Spot {
        /// Light position.
        pos: DVec3,
        /// Eye–light distance (at least 10⁻⁹ m).
        dist: f64,
        /// Unit direction from the eye to the light.
        t: DVec3,
    },
}

/// Angle between unit-ish vectors without the precision loss of `acos` near 0 and π.
pub fn angle(a: DVec3, b: DVec3) -> f64 {
    a.cross(b).length().atan2(a.dot(b))
}

impl Geo {
    /// The geometry of `light` seen from `eye`.
    pub fn new(eye: DVec3, light: &EpiLight) -> Geo {
        match light {
            EpiLight::Directional { direction, .. } => {
                let l = DVec3::from_array(*direction).try_normalize().unwrap_or(DVec3::NEG_Y);
                Geo::Directional { t: -l }
            }
            EpiLight::Spot { position, direction, .. } => {
                let pos = DVec3::from_array(*position);
                let r = pos - eye;
                let dist = r.length();
                let t = if dist > 1e-9 {
                    r / dist
                } else {
                    -DVec3::from_array(*direction).try_normalize().unwrap_or(DVec3::NEG_Y)
                };
                Geo::Spot { pos, dist: dist.max(1e-9), t }
            }
        }
    }

    /// Unit direction from the eye to the light.
    pub fn toward(&self) -> DVec3 {
        match *self {
            Geo::Directional { t } | Geo::Spot { t, .. } => t,
        }
    }

    /// `β` of view direction `v`.
    pub fn beta(&self, v: DVec3) -> f64 {
        angle(v, self.toward())
    }

    /// `γ` where the view ray `v` (angle `beta`) of length `d` ends.
    pub fn gamma_end(&self, eye: DVec3, v: DVec3, beta: f64, d: f64) -> f64 {
        match *self {
            Geo::Directional { .. } => d * beta.sin(),
            Geo::Spot { pos, .. } => {
                let p = eye + d * v;
                if d <= 0.0 {
                    return 0.0;
                }
                angle(p - pos, eye - pos)
            }
        }
    }
}

/// One epipolar slice.
#[derive(Debug, Clone, PartialEq)]
pub struct Slice {
    /// Screen angle relative to [`Setup::ref_dir`] \[rad\].
    pub angle: f64,
    /// World-space unit axis of the slice's half-plane, ⟂ the light direction.
    pub u: DVec3,
    /// View-ray angles, increasing.
    pub betas: Vec<f64>,
    /// Rectified depth: `γ` where each view ray ends.
    pub gend: Vec<f64>,
}

/// Where one slice lies before its depth is rectified: its screen angle, half-plane axis and the
/// `n` view-ray angles `β_k = lo + (hi − lo)·k/(n − 1)` it samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SliceLayout {
    /// Screen angle relative to [`Setup::ref_dir`] \[rad\].
    pub angle: f64,
    /// World-space unit axis of the slice's half-plane, ⟂ the light direction.
    pub u: DVec3,
    /// Smallest `β`.
    pub beta_lo: f64,
    /// Largest `β`.
    pub beta_hi: f64,
    /// Samples (at least 2).
    pub n: usize,
}

impl SliceLayout {
    /// `β` of sample `k`.
    pub fn beta(&self, k: usize) -> f64 {
        self.beta_lo + (self.beta_hi - self.beta_lo) * k as f64 / (self.n - 1) as f64
    }
}

/// The slices of one frame and what unrectification needs.
#[derive(Debug, Clone, PartialEq)]
pub struct Setup {
    /// Eye position.
    pub eye: DVec3,
    /// Light geometry.
    pub geo: Geo,
    /// Epipole in raster coordinates (projection of the direction to the light, or of its opposite
    /// when the light is behind the camera).
    pub epipole: [f64; 2],
    /// Reference screen direction angles are measured from.
    pub ref_dir: [f64; 2],
    /// Whether the epipole is inside the raster (slices then wrap around it).
    pub inside: bool,
    /// Ring radius \[px\].
    pub ring: f64,
    /// Slices sorted by angle.
    pub slices: Vec<Slice>,
    /// Smallest and largest `β` over all slices.
    pub beta_range: (f64, f64),
    /// Largest `γ` any view ray reaches.
    pub gamma_max: f64,
    width: usize,
    height: usize,
}

fn rel_angle(r: [f64; 2], d: [f64; 2]) -> f64 {
    (r[0] * d[1] - r[1] * d[0]).atan2(r[0] * d[0] + r[1] * d[1])
}

impl Setup {
    /// Lays out the slices and rectifies the depth map (parallel over slices); view rays end at their
    /// depth or where they leave the medium's `region`.
    pub fn new(
        cam: &ViewCamera,
        depth: &DistanceImage,
        light: &EpiLight,
        region: ([f64; 3], [f64; 3]),
        opts: &EpipolarOptions,
    ) -> Setup {
        let (mut setup, layout) = Setup::layout(cam, light, opts);
        let (eye, geo, t) = (setup.eye, setup.geo, setup.geo.toward());
        setup.slices = layout
            .par_iter()
            .map(|l| {
                let mut betas = Vec::with_capacity(l.n);
                let mut gend = Vec::with_capacity(l.n);
                for k in 0..l.n {
                    let beta = l.beta(k);
                    let v = beta.cos() * t + beta.sin() * l.u;
                    let dpx = match cam.project_dir(v) {
                        Some((q, true)) => sample_depth(depth, q),
                        _ => f32::INFINITY,
                    };
                    let (_, ext) = view_segment(eye, v, dpx, region);
                    betas.push(beta);
                    gend.push(geo.gamma_end(eye, v, beta, ext));
                }
                Slice { angle: l.angle, u: l.u, betas, gend }
            })
            .collect();
        setup.beta_range = setup.slices.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), s| {
            (lo.min(s.betas[0]), hi.max(*s.betas.last().unwrap_or(&0.0)))
        });
        setup.gamma_max = setup.slices.iter().flat_map(|s| s.gend.iter().copied()).fold(0.0f64, f64::max);
        setup
    }

    /// The slice layout alone (Sec. 8): a [`Setup`] without slices (`beta_range` from the layout,
    /// `gamma_max` 0) and the slices sorted by angle, before any depth is read. The GPU path
    /// rectifies the depth on the device from this.
    pub fn layout(cam: &ViewCamera, light: &EpiLight, opts: &EpipolarOptions) -> (Setup, Vec<SliceLayout>) {
        let eye = cam.position;
        let geo = Geo::new(eye, light);
        let t = geo.toward();
        let (w, h) = (cam.width as f64, cam.height as f64);
        let centre = [0.5 * w, 0.5 * h];
        let far = 1e7;
        let epipole = match cam.project_dir(t) {
            Some((e, _)) if (e[0] - centre[0]).hypot(e[1] - centre[1]) < far => e,
            _ => {
                let s = [t.dot(cam.right), -t.dot(cam.up)];
                let n = s[0].hypot(s[1]).max(1e-300);
                [centre[0] + far * s[0] / n, centre[1] + far * s[1] / n]
            }
        };
        // Around the anti-epipole (a directional light behind the camera) the kernel
        // e^{−σ_t γ tan(β/2)} is at its steepest, so the marched disc is twice as wide there.
        let behind = matches!(geo, Geo::Directional { .. }) && t.dot(cam.forward) < 0.0;
        let ring_deg = if behind { 4f64 } else { 2f64 };
        let ring = opts.ring_px.unwrap_or_else(|| ring_deg.to_radians().tan() / cam.tan_half_y * 0.5 * h).max(0.0);
        let (ex, ey) = (epipole[0] - centre[0], epipole[1] - centre[1]);
        let ref_dir = if ex.hypot(ey) > 1e-9 {
            let n = ex.hypot(ey);
            [-ex / n, -ey / n]
        } else {
            [1.0, 0.0]
        };
        let inside = epipole[0] >= 0.0 && epipole[0] <= w && epipole[1] >= 0.0 && epipole[1] <= h;

        // Slice directions by the sinh distribution on each exit edge.
        let density = if opts.slice_density.is_finite() { opts.slice_density.clamp(1e-3, 64.0) } else { 1.0 };
        let mut dirs: Vec<[f64; 2]> = Vec::new();
        // (distance to the edge line, foot, edge unit vector, segment [a, b] along it)
        let edges = [
            (epipole[0], [0.0, epipole[1]], [0.0, 1.0], (-epipole[1], h - epipole[1])),
            (w - epipole[0], [w, epipole[1]], [0.0, 1.0], (-epipole[1], h - epipole[1])),
            (epipole[1], [epipole[0], 0.0], [1.0, 0.0], (-epipole[0], w - epipole[0])),
            (h - epipole[1], [epipole[0], h], [1.0, 0.0], (-epipole[0], w - epipole[0])),
        ];
        for (hd, foot, along, (a, b)) in edges {
            if hd.partial_cmp(&1e-9) != Some(std::cmp::Ordering::Greater) {
                continue;
            }
            let (a0, a1) = ((a / hd).asinh(), (b / hd).asinh());
            let n = ((a1 - a0) * hd * density).ceil().max(1.0) as usize + 1;
            for k in 0..n {
                let alpha = a0 + (a1 - a0) * k as f64 / (n - 1) as f64;
                let x = hd * alpha.sinh();
                let p = [foot[0] + x * along[0], foot[1] + x * along[1]];
                let d = [p[0] - epipole[0], p[1] - epipole[1]];
                let len = d[0].hypot(d[1]);
                if len > 0.0 {
                    dirs.push([d[0] / len, d[1] / len]);
                }
            }
        }

        let spp = if opts.samples_per_pixel.is_finite() { opts.samples_per_pixel.clamp(1e-3, 64.0) } else { 1.0 };
        let mut slices: Vec<SliceLayout> = dirs
            .par_iter()
            .filter_map(|&d| {
                // Clip e + s·d, s ≥ ring, to the raster rectangle.
                let (mut s0, mut s1) = (ring, f64::INFINITY);
                for (o, v, hi) in [(epipole[0], d[0], w), (epipole[1], d[1], h)] {
                    if v.abs() < 1e-15 {
                        if o < 0.0 || o > hi {
                            return None;
                        }
                        continue;
                    }
                    let (ta, tb) = ((0.0 - o) / v, (hi - o) / v);
                    s0 = s0.max(ta.min(tb));
                    s1 = s1.min(ta.max(tb));
                }
                if s1 <= s0 {
                    return None;
                }
                let at = |s: f64| cam.ray_dir(epipole[0] + s * d[0], epipole[1] + s * d[1]);
                let vm = at(0.5 * (s0 + s1));
                let u = (vm - vm.dot(t) * t).try_normalize()?;
                let (b0, b1) = (geo.beta(at(s0)), geo.beta(at(s1)));
                let (lo, hi) = (b0.min(b1).max(1e-6), b0.max(b1).min(std::f64::consts::PI - 1e-6));
                if hi <= lo {
                    return None;
                }
                let n = (((s1 - s0) * spp).ceil() as usize + 1).max(2);
                Some(SliceLayout { angle: rel_angle(ref_dir, d), u, beta_lo: lo, beta_hi: hi, n })
            })
            .collect();
        slices.sort_by(|a, b| a.angle.total_cmp(&b.angle));
        let beta_range = slices
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), s| (lo.min(s.beta_lo), hi.max(s.beta_hi)));
        let setup = Setup {
            eye,
            geo,
            epipole,
            ref_dir,
            inside,
            ring,
            slices: Vec::new(),
            beta_range,
            gamma_max: 0.0,
            width: cam.width,
            height: cam.height,
        };
        (setup, slices)
    }

    /// Whether pixel `(x, y)` is ray marched (its centre within the ring, or no slice exists).
    pub fn in_ring(&self, x: usize, y: usize) -> bool {
        if self.slices.is_empty() {
            return true;
        }
        let (dx, dy) = (x as f64 + 0.5 - self.epipole[0], y as f64 + 0.5 - self.epipole[1]);
        dx.hypot(dy) < self.ring
    }

    /// The two slices bracketing the screen angle of pixel `(x, y)` and the weight of the second.
    fn bracket(&self, x: usize, y: usize) -> Option<(usize, usize, f64)> {
        let n = self.slices.len();
        if n == 0 || x >= self.width || y >= self.height {
            return None;
        }
        let (dx, dy) = (x as f64 + 0.5 - self.epipole[0], y as f64 + 0.5 - self.epipole[1]);
        let len = dx.hypot(dy);
        let th = if len > 0.0 { rel_angle(self.ref_dir, [dx / len, dy / len]) } else { 0.0 };
        let k = self.slices.partition_point(|s| s.angle <= th);
        Some(if self.inside {
            let lo = (k + n - 1) % n;
            let hi = k % n;
            let tau = std::f64::consts::TAU;
            let span = (self.slices[hi].angle - self.slices[lo].angle).rem_euclid(tau);
            let off = (th - self.slices[lo].angle).rem_euclid(tau);
            (lo, hi, if span > 0.0 { (off / span).clamp(0.0, 1.0) } else { 0.0 })
        } else if k == 0 {
            (0, 0, 0.0)
        } else if k >= n {
            (n - 1, n - 1, 0.0)
        } else {
            let span = self.slices[k].angle - self.slices[k - 1].angle;
            (k - 1, k, if span > 0.0 { ((th - self.slices[k - 1].angle) / span).clamp(0.0, 1.0) } else { 0.0 })
        })
    }

    /// Whether a slice bracketing pixel `(x, y)` was left to ray marching for its light gain
    /// ([`super::MAX_LIGHT_GAIN`]).
    pub fn over_gain(&self, results: &[SliceResult], x: usize, y: usize) -> bool {
        self.bracket(x, y).is_some_and(|(lo, hi, _)| results[lo].over_gain || results[hi].over_gain)
    }

    /// The result at pixel `(x, y)` with unit view direction `v` and view extent `extent`: the two
    /// slices bracketing its screen angle, each with its two `β` samples around the pixel's `β`,
    /// blended bilinearly (angle × `β`) over the samples whose rectified depth matches the pixel's
    /// (`|γ_s − γ_p| ≤ 5 % of the larger + 2 bins`, a joint-bilateral rule against blending across
    /// silhouettes). `None` when no sample matches (the pixel is then ray marched like the ring).
    pub fn unrectify(
        &self,
        results: &[SliceResult],
        x: usize,
        y: usize,
        v: DVec3,
        extent: f64,
        dgamma: f64,
    ) -> Option<[f32; 3]> {
        let (lo, hi, wgt) = self.bracket(x, y)?;
        let beta = self.geo.beta(v);
        let gp = self.geo.gamma_end(self.eye, v, beta, extent);
        let (mut acc, mut wsum) = ([0.0f64; 3], 0.0f64);
        for (si, ws) in [(lo, 1.0 - wgt), (hi, wgt)] {
            let s = &self.slices[si];
            if results[si].over_gain {
                continue;
            }
            let vals = &results[si].values;
            let m = s.betas.len();
            if m == 0 || vals.len() != m {
                continue;
            }
            let (b0, b1) = (s.betas[0], s.betas[m - 1]);
            let pos = if b1 > b0 { ((beta - b0) / (b1 - b0) * (m - 1) as f64).clamp(0.0, (m - 1) as f64) } else { 0.0 };
            let i = (pos.floor() as usize).min(m - 1);
            let j = (i + 1).min(m - 1);
            let f = pos - i as f64;
            for (idx, wb) in [(i, 1.0 - f), (j, f)] {
                let g = s.gend[idx];
                if (g - gp).abs() > 0.05 * g.max(gp) + 2.0 * dgamma {
                    continue;
                }
                // A small floor keeps a matching sample usable when its bilinear weight is 0.
                let w = ws * wb + 1e-6;
                for c in 0..3 {
                    acc[c] += w * f64::from(vals[idx][c]);
                }
                wsum += w;
            }
        }
        (wsum > 0.0).then(|| acc.map(|a| (a / wsum) as f32))
    }
}
