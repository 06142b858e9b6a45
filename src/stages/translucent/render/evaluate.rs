//! Scattering passes 2–4 of wang2018 (Eq. 5–8, Sec. 4.3–4.4): segments and camera samples →
//! single, double, multiple and bounced scattering per segment, by tree cuts over the light samples.

use super::*;
use crate::physics::medium::extinguished;

pub(super) struct Evaluator<'a> {
    pub(super) setup: &'a Setup<'a>,
    /// Per channel, the table's lobes.
    pub(super) slices: &'a [LobeSlice<'a>],
    pub(super) opts: &'a RenderOptions,
    pub(super) ch: [MediumChannel; 3],
    pub(super) vol_tree: &'a Octree,
    pub(super) vol_agg: &'a [VolAgg],
    pub(super) vol_items: &'a [VolAgg],
    /// Extrapolation distance per channel when `boundary_image` is on.
    pub(super) z_b: Option<[f64; 3]>,
}

impl<'a> Evaluator<'a> {
    pub(super) fn new(
        setup: &'a Setup<'a>,
        slices: &'a [LobeSlice<'a>],
        opts: &'a RenderOptions,
        (vol_tree, vol_agg, vol_items): (&'a Octree, &'a [VolAgg], &'a [VolAgg]),
    ) -> Self {
        let m = setup.material;
        Evaluator {
            setup,
            slices,
            opts,
            ch: channels(&m),
            vol_tree,
            vol_agg,
            vol_items,
            z_b: opts.boundary_image.then(|| extrapolation_distance(&m)),
        }
    }

    pub(super) fn sigma(&self, c: usize) -> f64 {
        self.ch[c].sigma_t
    }

    pub(super) fn clamp_r(&self, r: f64, c: usize) -> f64 {
        r.max(self.opts.clamp_mfp / self.sigma(c))
    }

    /// Algorithm 1 for a volume-sample node seen from `p` with the camera direction `w`.
    pub(super) fn refine(&self, node: u32, p: DVec3, w: DVec3) -> bool {
        let n = &self.vol_tree.nodes[node as usize];
        let (center, _, _, dir) = self.vol_agg[node as usize].points();
        let u = p - center;
        let dist = u.length();
        let radius = self.vol_agg[node as usize].radius();
        if n.is_leaf() {
            // A leaf splits into its samples only around the point itself.
            return dist < radius;
        }
        let omega = solid_angle(radius, dist);
        if omega > self.opts.epsilon1 {
            return true;
        }
        if omega > self.opts.epsilon2 {
            let uh = u / dist;
            let g = self.ch[0].g;
            return phase(uh.dot(w), g) > self.opts.phase_threshold
                || phase(dir.dot(uh), g) > self.opts.phase_threshold;
        }
        false
    }

    /// Double scattering (Eq. 6) at `p` toward `w` over the Algorithm 1 cut, per channel, radiance per
    /// unit length; also the number of cut entries.
    pub(super) fn double(&self, p: DVec3, w: DVec3, cut: &mut Vec<CutEntry>) -> ([f64; 3], usize) {
        cut.clear();
        if self.vol_tree.nodes.is_empty() {
            return ([0.0; 3], 0);
        }
        self.vol_tree.cut(&[0], |n| self.refine(n, p, w), cut);
        let mut dbl = [0.0; 3];
        let g = self.ch[0].g;
        let n_disk = self.opts.double_disk as usize;
        // Eq. 6 for light of track length `weight · Λ` scattered at `p − qv` (travel direction `dir`).
        let add = |dbl: &mut [f64; 3], qv: DVec3, lam: &[f64; 3], dir: DVec3, weight: f64| {
            let rq = qv.length();
            if rq <= 0.0 {
                return;
            }
            let qh = qv / rq;
            let pp = phase(dir.dot(qh), g) * phase(qh.dot(w), g);
            for (c, dc) in dbl.iter_mut().enumerate() {
                let ss = self.ch[c].albedo * self.sigma(c);
                let rc = self.clamp_r(rq, c);
                *dc += ss * ss * lam[c] * weight * (-self.sigma(c) * rq).exp() / (rc * rc) * pp;
            }
        };
        for e in cut.iter() {
            let a = self.entry(e);
            let (center, _, _, dir) = a.points();
            let rv = p - center;
            let r = rv.length();
            if r <= 0.0 {
                continue;
            }
            let a2 = if a.w_lam > 0.0 { a.tube / a.w_lam / PI } else { 0.0 };
            if n_disk > 0 && r * r < DISK_REACH * DISK_REACH * a2 {
                // Near its tube the sample's light is spread over the tube's cross-section, not
                // concentrated at its centre: average Eq. 6 over `n_disk` equal-area points of that
                // disk (a Vogel spiral), so the sum keeps the sample's power.
                let (t1, t2) = frame_of(dir.try_normalize().unwrap_or(DVec3::Z));
                let radius = a2.sqrt();
                let share = 1.0 / n_disk as f64;
                for k in 0..n_disk {
                    let rr = radius * ((k as f64 + 0.5) * share).sqrt();
                    let ang = k as f64 * GOLDEN_ANGLE;
                    add(&mut dbl, p - (center + (t1 * ang.cos() + t2 * ang.sin()) * rr), &a.lam, dir, share);
                }
            } else {
                add(&mut dbl, rv, &a.lam, dir, 1.0);
            }
        }
        (dbl, cut.len())
    }

    /// Multiple scattering (Eq. 7, orders ≥ 3) at `p` toward `w` over the coarser solid-angle cut at
    /// `epsilon_multiple` (smooth and costly: four table look-ups per entry and channel, eight with the
    /// image beams); also the number of cut entries and failed look-ups.
    pub(super) fn multiple(&self, p: DVec3, w: DVec3, cut: &mut Vec<CutEntry>) -> ([f64; 3], usize, u64) {
        let (mut mul, mut failed) = ([0.0; 3], 0u64);
        if self.vol_tree.nodes.is_empty() {
            return (mul, 0, 0);
        }
        let needed = self.ch.map(|ch| multiple_needed(ch.albedo));
        cut.clear();
        self.coarse_cut(p, cut);
        for e in cut.iter() {
            let a = self.entry(e);
            let (_, start, end, dir) = a.points();
            for (c, mc) in mul.iter_mut().enumerate() {
                if !needed[c] || a.phi0[c] <= 0.0 {
                    continue;
                }
                let look = |origin: DVec3, dir: DVec3| {
                    self.slices[c].multiple_radiance((origin.to_array(), dir.to_array()), p.to_array(), w.to_array())
                };
                let (v0, v1) = match (look(start, dir), look(end, dir)) {
                    (Ok(v0), Ok(v1)) => (v0, v1),
                    _ => {
                        failed += 1;
                        continue;
                    }
                };
                let real = (a.phi0[c] * v0 - a.phi1[c] * v1).max(0.0);
                let image = match self.z_b {
                    Some(z) => {
                        let (is, ie, id) = a.image(z[c]);
                        match (look(is, id), look(ie, id)) {
                            (Ok(u0), Ok(u1)) => (a.phi0[c] * u0 - a.phi1[c] * u1).max(0.0),
                            _ => {
                                failed += 1;
                                0.0
                            }
                        }
                    }
                    None => 0.0,
                };
                *mc += (real - image).max(0.0);
            }
        }
        (mul, cut.len(), failed)
    }

    pub(super) fn entry(&self, e: &CutEntry) -> &VolAgg {
        match *e {
            CutEntry::Node(n) => &self.vol_agg[n as usize],
            CutEntry::Item(i) => &self.vol_items[i as usize],
        }
    }

    /// The solid-angle-only cut at `epsilon_multiple` seen from `p`.
    pub(super) fn coarse_cut(&self, p: DVec3, cut: &mut Vec<CutEntry>) {
        self.vol_tree.cut(
            &[0],
            |n| {
                let node = &self.vol_tree.nodes[n as usize];
                let (center, ..) = self.vol_agg[n as usize].points();
                let (radius, dist) = (self.vol_agg[n as usize].radius(), (p - center).length());
                if node.is_leaf() { dist < radius } else { solid_angle(radius, dist) > self.opts.epsilon_multiple }
            },
            cut,
        );
    }

    /// Irradiance reaching a surface sample from inside from the volume samples: the irradiance `φ/4`
    /// of an isotropic field whose fluence `φ` is that of the light scattered at least once (the table's
    /// scattering-event density of orders ≥ 2 is `σ_s φ`).
    pub(super) fn inner_irradiance(&self, s: &SurfaceSample) -> Result<[f64; 3], LobeQueryError> {
        let mut out = [0.0; 3];
        if self.vol_tree.nodes.is_empty() {
            return Ok(out);
        }
        let p = s.position;
        let mut cut = Vec::new();
        self.coarse_cut(p, &mut cut);
        for e in &cut {
            let a = self.entry(e);
            let (_, start, end, dir) = a.points();
            for (c, o) in out.iter_mut().enumerate() {
                if !inner_needed(self.ch[c].albedo) {
                    continue;
                }
                let st = self.sigma(c);
                let ss = self.ch[c].albedo * st;
                let fluence = |origin: DVec3, dir: DVec3| -> Result<f64, LobeQueryError> {
                    let v = p - origin;
                    let z = v.dot(dir);
                    let rho = (v - z * dir).length();
                    // Scattering-event density per unit volume per watt: σ_t³ D(σ_t x) = σ_s φ.
                    Ok(self.slices[c].density(st * rho, st * z)? * st * st * st / ss)
                };
                let m = (a.phi0[c] * fluence(start, dir)? - a.phi1[c] * fluence(end, dir)?).max(0.0);
                let image = match self.z_b {
                    Some(z) => {
                        let (is, ie, id) = a.image(z[c]);
                        (a.phi0[c] * fluence(is, id)? - a.phi1[c] * fluence(ie, id)?).max(0.0)
                    }
                    None => 0.0,
                };
                *o += 0.25 * (m - image).max(0.0);
            }
        }
        Ok(out)
    }
}

/// Bounced scattering (Eq. 8) at `p` toward `w`: a tree cut over the surface samples.
pub(super) fn bounced_at(eval: &Evaluator, prep: &Prepared, p: DVec3, w: DVec3, cut: &mut Vec<CutEntry>) -> [f64; 3] {
    let mut out = [0.0; 3];
    let tree = &prep.surf_tree;
    if tree.nodes.is_empty() {
        return out;
    }
    let g = eval.ch[0].g;
    let cut_at = |eps: f64, cut: &mut Vec<CutEntry>| {
        cut.clear();
        tree.cut(
            &[0],
            |n| {
                let a = &prep.surf_agg[n as usize];
                let pos = if a.w > 0.0 {
                    a.pos / a.w
                } else {
                    0.5 * (tree.nodes[n as usize].bounds.0 + tree.nodes[n as usize].bounds.1)
                };
                let node = &tree.nodes[n as usize];
                let (radius, dist) = (half_diagonal(&node.bounds), (p - pos).length());
                if node.is_leaf() { dist < radius } else { solid_angle(radius, dist) > eps }
            },
            cut,
        );
    };
    // A cut entry with power: its aggregate, power-weighted position and mean inward normal (shorter
    // than 1 where the normals spread).
    let entry = |e: &CutEntry| {
        let a = match *e {
            CutEntry::Node(n) => &prep.surf_agg[n as usize],
            CutEntry::Item(i) => &prep.surf_items[i as usize],
        };
        (a.w > 0.0).then(|| (a, a.pos / a.w, a.normal / a.w))
    };
    cut_at(eval.opts.epsilon_multiple, cut);
    for (a, pos, nrm) in cut.iter().filter_map(entry) {
        let q = p - pos;
        let r = q.length();
        if r <= 0.0 {
            continue;
        }
        let qh = q / r;
        let cos = nrm.dot(qh).max(0.0);
        if cos > 0.0 {
            let (k_ext, k_int) = prep.emission_profile.factors(cos / nrm.length());
            let ph = phase(qh.dot(w), g);
            for (c, o) in out.iter_mut().enumerate() {
                let rc = eval.clamp_r(r, c);
                // With scene rays the refracted scene light's first scattering is theirs.
                let ext = if eval.opts.scene_rays == 0 { a.power_ext[c] } else { 0.0 };
                let power = ext * k_ext + a.power_int[c] * k_int;
                *o += eval.ch[c].albedo * eval.sigma(c) * power * cos * ph * (-eval.sigma(c) * r).exp() / (rc * rc);
            }
        }
    }
    if eval.opts.epsilon_beams != eval.opts.epsilon_multiple {
        cut_at(eval.opts.epsilon_beams, cut);
    }
    let n_graze = eval.opts.grazing_beams as usize;
    let mut graze_dirs = [DVec3::ZERO; 64]; // grazing_beams ≤ 64 (RenderOptions::check)
    for (a, pos, nrm) in cut.iter().filter_map(entry) {
        // Orders ≥ 2 of the emitted light: the table's response to beams from the samples' positions
        // with their flux minus from the chords' ends with what is left there. The refracted scene
        // light goes along the mean inward normal; the internally reflected light along
        // `grazing_beams` beams at its median angle (or with the rest when there are none).
        let Some(dir) = nrm.try_normalize() else { continue };
        let end = a.end / a.w;
        let graze = &mut graze_dirs[..n_graze];
        for (slot, d) in graze.iter_mut().zip(grazing_dirs(dir, prep.grazing_mu, n_graze as u32)) {
            *slot = d;
        }
        let graze = &*graze;
        for (c, o) in out.iter_mut().enumerate() {
            // Left out where all orders ≥ 2 are under 2 % of the first (as for the inner irradiance).
            if !inner_needed(eval.ch[c].albedo) || a.flux0[c] + a.graze0[c] <= 0.0 {
                continue;
            }
            let look = |origin: DVec3, d: DVec3| {
                eval.slices[c].total_radiance((origin.to_array(), d.to_array()), p.to_array(), w.to_array())
            };
            // Beam from `pos` along `d` with flux `f0`, ending at `end` with `f1`, minus its image about
            // the sample's own plane (through `pos`, normal `dir`), moved out by `2 z_b`.
            let beam = |end: DVec3, d: DVec3, f0: f64, f1: f64| {
                let one = |pos: DVec3, end: DVec3, d: DVec3| {
                    let v0 = look(pos, d).unwrap_or(0.0);
                    // What is left at the end is skipped once it is a millionth of the start (thick
                    // media): its response is at most that share of the beam's own near field.
                    let v1 = if f1 > 1e-6 * f0 { look(end, d).unwrap_or(0.0) } else { 0.0 };
                    (f0 * v0 - f1 * v1).max(0.0)
                };
                let real = one(pos, end, d);
                let image = eval.z_b.map_or(0.0, |z| {
                    let out = -dir * (2.0 * z[c]);
                    one(pos + out, mirror_about(end, pos, dir) + out, d - 2.0 * d.dot(dir) * dir)
                });
                (real - image).max(0.0)
            };
            if a.flux0[c] > 0.0 {
                *o += beam(end, dir, a.flux0[c], a.flux1[c]);
            }
            if n_graze > 0 && a.graze0[c] > 0.0 {
                let len = a.graze_len / a.w;
                let (f0, f1) = (a.graze0[c] / n_graze as f64, a.graze1[c] / n_graze as f64);
                for &d in graze {
                    *o += beam(pos + d * len, d, f0, f1);
                }
            }
        }
    }
    out
}

/// Single scattering per segment (Eq. 5), with the two-step traversal for primary 2×2 blocks; also the
/// total number of nodes tested.
pub(super) fn single_pass(
    eval: &Evaluator,
    prep: &Prepared,
    segments: &[Segment],
    width: usize,
) -> (Vec<[f64; 3]>, usize) {
    let tree = &prep.vol_tree;
    let m = eval.setup.material;
    let sr = m.sigma_t.iter().copied().fold(f64::INFINITY, f64::min);
    let layer = eval.opts.single_layer_mfp / sr;
    // Group segments: primary segments by 2×2 pixel block (when two_step), every other one alone.
    let mut groups: Vec<Vec<usize>> = Vec::new();
    if eval.opts.two_step {
        let mut by_block: std::collections::BTreeMap<(usize, usize), Vec<usize>> = std::collections::BTreeMap::new();
        for (k, s) in segments.iter().enumerate() {
            if s.primary {
                let px = s.pixel as usize;
                by_block.entry(((px % width) / 2, (px / width) / 2)).or_default().push(k);
            } else {
                groups.push(vec![k]);
            }
        }
        groups.extend(by_block.into_values());
    } else {
        groups.extend((0..segments.len()).map(|k| vec![k]));
    }
    let results: Vec<GroupSingle> = groups
        .par_iter()
        .map(|grp| {
            let rays: Vec<(DVec3, DVec3, f64)> =
                grp.iter().map(|&k| (segments[k].entry, segments[k].dir, segments[k].d_max.min(layer))).collect();
            let mut roots = vec![0u32];
            let mut tested = 0;
            if tree.nodes.is_empty() {
                return (grp.iter().map(|&k| (k, [0.0; 3])).collect(), 0);
            }
            if eval.opts.two_step && grp.len() > 1 {
                roots.clear();
                tested += tree.ray_frontier(&rays, eval.opts.stop_height, &mut roots);
            }
            let out = grp
                .iter()
                .zip(&rays)
                .map(|(&k, &(o, d, tmax))| {
                    let mut acc = [0.0; 3];
                    let wcam = -d;
                    tested += tree.ray_items(&roots, o, d, tmax, |it| {
                        let v = &prep.points.volume[it as usize];
                        let obb = v.obb(eval.opts.widen);
                        let Some((a, b)) = obb.hit(o, d) else { return };
                        let (a, b) = (a.max(0.0), b.min(tmax));
                        if b <= a {
                            return;
                        }
                        let area = v.area * eval.opts.widen * eval.opts.widen;
                        if area.is_nan() || area <= 0.0 {
                            return;
                        }
                        let ph = phase(v.direction.dot(wcam), m.g);
                        for (c, x) in acc.iter_mut().enumerate() {
                            let st = m.sigma_t[c];
                            let e = v.flux[c] * (-0.5 * st * v.length).exp() / area;
                            // e^{−σa} − e^{−σb} = e^{−σa}(1 − e^{−σ(b−a)}), stable for thin boxes.
                            let dt = (-st * a).exp() * extinguished(st, b - a);
                            *x += m.albedo[c] * ph * e * dt;
                        }
                    });
                    (k, acc)
                })
                .collect();
            (out, tested)
        })
        .collect();
    let mut per_seg = vec![[0.0; 3]; segments.len()];
    let mut tested = 0;
    for (list, t) in results {
        tested += t;
        for (k, v) in list {
            per_seg[k] = v;
        }
    }
    (per_seg, tested)
}
