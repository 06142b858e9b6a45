//! Pass 1 of wang2018 (Sec. 3.5, 4.4): a pixel's camera path through the scene → segments inside
//! the object and the rest of the picture (Fresnel splits at the boundary, Lambertian opaque surfaces,
//! diffuse rays); and the scene rays' first scattering ([`Tracer::scene_first`]).

use super::*;

/// Camera-path tracing of pass 1.
pub(super) struct Tracer<'a> {
    pub(super) setup: &'a Setup<'a>,
    pub(super) opts: &'a RenderOptions,
    /// The object's caustic and glow on opaque surfaces.
    pub(super) light: &'a ObjectLight,
}

/// Offset of secondary rays from surfaces \[m\].
pub(super) const EPS: f64 = 1e-6;
/// Throughput below which a camera path is dropped.
pub(super) const MIN_WEIGHT: f64 = 1e-6;

impl Tracer<'_> {
    /// Traces a pixel's primary ray; returns whether it hits the object first.
    pub(super) fn primary(&self, pixel: u32, o: DVec3, d: DVec3, segs: &mut Vec<Segment>, rest: &mut [f64; 3]) -> bool {
        let hit = self.setup.bvh.closest_hit(&Ray::new(o.to_array(), d.to_array()));
        let object = hit.is_some_and(|h| h.mesh == self.setup.object)
            && !self.emitter_before(o, d, hit.map(|h| h.t).unwrap_or(f64::INFINITY));
        self.trace(pixel, o, d, [1.0; 3], 0, true, segs, rest);
        object
    }

    pub(super) fn emitter_before(&self, o: DVec3, d: DVec3, t_max: f64) -> bool {
        self.setup.emitters.iter().any(|e| e.intersect(o, d, 0.0).is_some_and(|t| t < t_max))
    }

    /// Radiance of emitters hit by the ray before `t_max` (the closest one).
    pub(super) fn emitter_radiance(&self, o: DVec3, d: DVec3, t_max: f64) -> Option<[f64; 3]> {
        let mut best: Option<(f64, [f64; 3])> = None;
        for e in self.setup.emitters {
            if let Some(t) = e.intersect(o, d, 0.0)
                && t < t_max
                && best.is_none_or(|b| t < b.0)
            {
                best = Some((t, e.radiance));
            }
        }
        best.map(|b| b.1)
    }

    #[allow(clippy::too_many_arguments)]
    pub(super) fn trace(
        &self,
        pixel: u32,
        o: DVec3,
        d: DVec3,
        thr: [f64; 3],
        depth: u32,
        primary: bool,
        segs: &mut Vec<Segment>,
        rest: &mut [f64; 3],
    ) {
        if thr.iter().all(|&t| t < MIN_WEIGHT) || depth > 8 {
            return;
        }
        let hit = self.setup.bvh.closest_hit(&Ray {
            origin: o.to_array(),
            direction: d.to_array(),
            t_min: 0.0,
            t_max: f64::INFINITY,
        });
        let t_hit = hit.map(|h| h.t).unwrap_or(f64::INFINITY);
        if let Some(l) = self.emitter_radiance(o, d, t_hit) {
            for c in 0..3 {
                rest[c] += thr[c] * l[c];
            }
            return;
        }
        let Some(h) = hit else { return };
        let p = o + h.t * d;
        let n = DVec3::from_array(h.geometric_normal);
        if h.mesh == self.setup.object {
            let eta = self.setup.material.ior;
            if !h.front_face {
                // A camera path meeting the object from inside (camera inside): treat as an exit.
                return;
            }
            let cos_i = d.dot(n).abs();
            let f = fresnel(cos_i, 1.0, eta);
            if f > 0.0 {
                let r = reflect(d, n);
                self.trace(pixel, p + n * EPS, r, thr.map(|t| t * f), depth + 1, false, segs, rest);
            }
            if let Some(tdir) = refract(d, n, 1.0, eta) {
                let w = thr.map(|t| t * (1.0 - f) / (eta * eta));
                self.inside(
                    pixel,
                    p - n * EPS,
                    n,
                    tdir,
                    w,
                    self.opts.camera_bounces,
                    depth,
                    primary,
                    self.opts.k_max,
                    segs,
                    rest,
                );
            }
            return;
        }
        // Opaque Lambertian surface: direct light from the emitters.
        let nf = if n.dot(d) > 0.0 { -n } else { n };
        let rho = self.setup.albedo_of(h.mesh);
        let direct = self.direct(p + nf * EPS, nf, pixel);
        // The object's light on the surface; its glow is gathered by the diffuse rays instead when
        // they are on.
        let object = self.light.irradiance(p, nf, !(primary && self.opts.diffuse_rays > 0));
        for c in 0..3 {
            rest[c] += thr[c] * rho[c] / PI * (direct[c] + object[c]);
        }
        if primary && self.opts.diffuse_rays > 0 && rho.iter().any(|&r| r > 0.0) {
            let key = StreamKey { table: self.opts.seed ^ 0x7a3c_0de5_1bad_5eed, cell: pixel as u64 };
            let nrays = self.opts.diffuse_rays;
            let (t1, t2) = frame_of(nf);
            for s in 0..nrays {
                let (u1, u2) = (key.uniform(s as u64, 0), key.uniform(s as u64, 1));
                let r = u1.sqrt();
                let phi = 2.0 * PI * u2;
                let dir = (t1 * (r * phi.cos()) + t2 * (r * phi.sin()) + nf * (1.0 - u1).max(0.0).sqrt()).normalize();
                let q = p + nf * EPS;
                let Some(h2) = self.setup.bvh.closest_hit(&Ray::new(q.to_array(), dir.to_array())) else { continue };
                if h2.mesh != self.setup.object || !h2.front_face {
                    continue;
                }
                let n2 = DVec3::from_array(h2.geometric_normal);
                let eta = self.setup.material.ior;
                let f = fresnel(dir.dot(n2).abs(), 1.0, eta);
                let Some(tdir) = refract(dir, n2, 1.0, eta) else { continue };
                // Cosine-weighted estimator: L = ρ/π ∫ L_i cos dω ≈ (ρ/N) Σ L_i.
                let w: [f64; 3] = std::array::from_fn(|c| thr[c] * rho[c] / nrays as f64 * (1.0 - f) / (eta * eta));
                let entry = q + h2.t * dir - n2 * EPS;
                let mut ignored = [0.0; 3];
                self.inside(
                    pixel,
                    entry,
                    n2,
                    tdir,
                    w,
                    0,
                    depth + 1,
                    false,
                    self.opts.diffuse_samples,
                    segs,
                    &mut ignored,
                );
            }
        }
    }

    /// A camera path inside the object from `entry` along `d` (unit): stores the segment, then follows
    /// the transmitted ray out and, with bounces left, the internally reflected one.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn inside(
        &self,
        pixel: u32,
        entry: DVec3,
        n_out: DVec3,
        d: DVec3,
        w: [f64; 3],
        bounces: u32,
        depth: u32,
        primary: bool,
        samples: usize,
        segs: &mut Vec<Segment>,
        rest: &mut [f64; 3],
    ) {
        if w.iter().all(|&t| t < MIN_WEIGHT) {
            return;
        }
        let Some(h) = self.setup.bvh.closest_hit(&Ray::new(entry.to_array(), d.to_array())) else { return };
        let d_max = h.t;
        if !(d_max > 0.0 && d_max.is_finite()) {
            return;
        }
        segs.push(Segment { pixel, entry, normal: n_out, dir: d, d_max, weight: w, samples: samples as u32, primary });
        if h.mesh != self.setup.object {
            return;
        }
        let m = self.setup.material;
        let att: [f64; 3] = std::array::from_fn(|c| w[c] * (-m.sigma_t[c] * d_max).exp());
        let exit = entry + d * d_max;
        let n = DVec3::from_array(h.geometric_normal);
        let f = fresnel(d.dot(n).abs(), m.ior, 1.0);
        if let Some(out) = refract(d, n, m.ior, 1.0) {
            let nout = if n.dot(out) > 0.0 { n } else { -n };
            let wt = att.map(|a| a * (1.0 - f) * m.ior * m.ior);
            self.trace(pixel, exit + nout * EPS, out, wt, depth + 1, false, segs, rest);
        }
        if bounces > 0 && f > 0.0 {
            let r = reflect(d, n);
            let nin = if n.dot(r) > 0.0 { n } else { -n };
            self.inside(
                pixel,
                exit + nin * EPS,
                -nin,
                r,
                att.map(|a| a * f),
                bounces - 1,
                depth + 1,
                false,
                samples,
                segs,
                rest,
            );
        }
    }

    /// First scattering toward `w` at `p` inside the object of the scene's light refracted in, per unit
    /// length, `σ_s ∫ p(ω·w) L_in(ω) dω`: `scene_rays` travel directions `ω` drawn from the phase
    /// function about `w` (stratified in its CDF, a rank-1 lattice in azimuth; weight 1), each traced
    /// back to the boundary, out through it (`(1 − F) η²`, none under total internal reflection) and to
    /// the first opaque surface, whose radiance is its direct light and the object's caustic and glow.
    /// Emitters seen this way are left out (the volume samples carry the lamp's light), as are rays that
    /// meet the object again. `key` and `sample` (the camera sample) pick the random stream.
    pub(super) fn scene_first(&self, p: DVec3, w: DVec3, key: StreamKey, sample: u64) -> [f64; 3] {
        let n = self.opts.scene_rays;
        let m = self.setup.material;
        let mut sum = [0.0; 3];
        if n == 0 || m.albedo.iter().all(|&a| a <= 0.0) {
            return sum;
        }
        let bvh = self.setup.bvh;
        let (j1, j2) = (key.uniform(sample, 0), key.uniform(sample, 1));
        let golden = 0.5 * (5f64.sqrt() - 1.0);
        let (t1, t2) = frame_of(w);
        for j in 0..n {
            let u1 = (f64::from(j) + j1) / f64::from(n);
            let phi = 2.0 * PI * (f64::from(j) * golden + j2).fract();
            let mu = crate::physics::hg::sample_mu(u1, m.g);
            let s = (1.0 - mu * mu).max(0.0).sqrt();
            // The light travels along `travel`; it comes from `−travel`.
            let travel = (w * mu + t1 * (s * phi.cos()) + t2 * (s * phi.sin())).normalize();
            let back = -travel;
            let Some(h) = bvh.closest_hit(&Ray::new(p.to_array(), back.to_array())) else { continue };
            if h.mesh != self.setup.object || h.front_face {
                continue;
            }
            let nrm = DVec3::from_array(h.geometric_normal);
            let Some(out) = refract(back, nrm, m.ior, 1.0) else { continue };
            let f = fresnel(back.dot(nrm).abs(), m.ior, 1.0);
            let exit = p + back * h.t;
            let nout = if nrm.dot(out) > 0.0 { nrm } else { -nrm };
            let o = exit + nout * EPS;
            let Some(h2) = bvh.closest_hit(&Ray::new(o.to_array(), out.to_array())) else { continue };
            if h2.mesh == self.setup.object || self.emitter_before(o, out, h2.t) {
                continue;
            }
            let q = o + out * h2.t;
            let mut nq = DVec3::from_array(h2.geometric_normal);
            if nq.dot(out) > 0.0 {
                nq = -nq;
            }
            let rho = self.setup.albedo_of(h2.mesh);
            if rho.iter().all(|&r| r <= 0.0) {
                continue;
            }
            let e = self.direct(q + nq * EPS, nq, u32::MAX);
            let obj = self.light.irradiance(q, nq, true);
            for c in 0..3 {
                let l_out = rho[c] / PI * (e[c] + obj[c]);
                sum[c] += l_out * (1.0 - f) * m.ior * m.ior * (-m.sigma_t[c] * h.t).exp();
            }
        }
        std::array::from_fn(|c| m.albedo[c] * m.sigma_t[c] * sum[c] / f64::from(n))
    }

    /// Irradiance from the emitters at a point with unit normal `n` (stratified points on each
    /// emitter's disk facing the point, shadow rays).
    pub(super) fn direct(&self, p: DVec3, n: DVec3, pixel: u32) -> [f64; 3] {
        let mut e = [0.0; 3];
        let ns = self.opts.light_samples.max(1);
        let side = (ns as f64).sqrt().ceil() as u32;
        let key = StreamKey { table: self.opts.seed ^ 0x51_9a7e_11e5, cell: pixel as u64 };
        for (li, em) in self.setup.emitters.iter().enumerate() {
            let to_c = em.center - p;
            let dist_c = to_c.length();
            if dist_c <= em.radius {
                continue;
            }
            let axis = to_c / dist_c;
            let (t1, t2) = frame_of(axis);
            let inten = em.intensity();
            for s in 0..ns {
                let (i, j) = (s % side, s / side);
                let su = (i as f64 + key.uniform(s as u64 + 1024 * li as u64, 0)) / side as f64;
                let sv = (j as f64 + key.uniform(s as u64 + 1024 * li as u64, 1)) / side as f64;
                let (r, phi) = (em.radius * su.sqrt(), 2.0 * PI * sv);
                let y = em.center + t1 * (r * phi.cos()) + t2 * (r * phi.sin());
                let l = y - p;
                let dist = l.length();
                let lh = l / dist;
                let cos = n.dot(lh);
                if cos <= 0.0 || self.setup.bvh.occluded(p.to_array(), lh.to_array(), dist - EPS) {
                    continue;
                }
                for c in 0..3 {
                    e[c] += inten[c] * cos / (dist * dist) / ns as f64;
                }
            }
        }
        e
    }
}

/// Two unit vectors completing `n` to an orthonormal frame.
pub(super) fn frame_of(n: DVec3) -> (DVec3, DVec3) {
    let a = if n.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let t1 = n.cross(a).normalize();
    (t1, n.cross(t1))
}
