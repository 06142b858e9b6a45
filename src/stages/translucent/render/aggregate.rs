//! Aggregates of the light samples for the tree cuts of wang2018 Sec. 4.3 (Algorithm 1): the
//! volume samples' flux, track length and beam ends ([`VolAgg`]) and the surface samples' emission
//! ([`SurfAgg`], [`EmissionProfile`]) → what a tree node stands for in Eq. 5–8.

use super::*;

/// Eq. 6 spreads a volume sample over its tube's disk within this many tube radii of its centre;
/// beyond, the disk and its centre differ by under about `1/(2·3²)` in `1/r²`.
pub(super) const DISK_REACH: f64 = 3.0;
/// `π (3 − √5)`: successive points of a Vogel spiral.
pub(super) const GOLDEN_ANGLE: f64 = 2.399_963_229_728_653;

/// `x` mirrored about the plane through `q` with unit normal `n`.
pub(super) fn mirror_about(x: DVec3, q: DVec3, n: DVec3) -> DVec3 {
    x - 2.0 * (x - q).dot(n) * n
}

/// Aggregate of volume samples (a tree node or one sample).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct VolAgg {
    /// Track length `∫Φ ds` per channel \[W·m\].
    pub(super) lam: [f64; 3],
    /// Flux entering the samples' intervals, per channel \[W\].
    pub(super) phi0: [f64; 3],
    /// Flux leaving them.
    pub(super) phi1: [f64; 3],
    /// Track-length-weighted centre (divided through after merging).
    pub(super) center: DVec3,
    /// Entering-flux-weighted start.
    pub(super) start: DVec3,
    /// Leaving-flux-weighted end.
    pub(super) end: DVec3,
    /// Sum of track-length-weighted directions (its length over the weight is the directions' spread).
    pub(super) dir_sum: DVec3,
    /// Track-length-weighted light-tube cross-section \[m²·W·m\] (divided by `w_lam` when read).
    pub(super) tube: f64,
    /// Scalar weights of the centroids.
    pub(super) w_lam: f64,
    pub(super) w0: f64,
    pub(super) w1: f64,
    /// Bounds of the samples' interval end points (the extent the cuts judge).
    pub(super) lo: DVec3,
    pub(super) hi: DVec3,
    /// Image beams (`boundary_image`): entering-flux-weighted start mirrored about its sample's
    /// boundary plane, and the weighted outward normals (the shift by `2 z_b` is per channel).
    pub(super) istart: DVec3,
    pub(super) inormal0: DVec3,
    /// Leaving-flux-weighted mirrored end and normals.
    pub(super) iend: DVec3,
    pub(super) inormal1: DVec3,
    /// Track-length-weighted mirrored directions.
    pub(super) idir_sum: DVec3,
}

impl VolAgg {
    pub(super) fn of_sample(v: &VolumeSample, sigma_t: [f64; 3]) -> Self {
        let lam = v.track_length(sigma_t);
        let phi1: [f64; 3] = std::array::from_fn(|c| v.flux[c] * (-sigma_t[c] * v.length).exp());
        let (w_lam, w0, w1) = (lam.iter().sum::<f64>(), v.flux.iter().sum::<f64>(), phi1.iter().sum::<f64>());
        VolAgg {
            lam,
            phi0: v.flux,
            phi1,
            center: v.center() * w_lam,
            start: v.start * w0,
            end: v.end() * w1,
            dir_sum: v.direction * w_lam,
            tube: v.area * w_lam,
            w_lam,
            w0,
            w1,
            lo: v.start.min(v.end()),
            hi: v.start.max(v.end()),
            istart: mirror_about(v.start, v.plane_point, v.plane_normal) * w0,
            inormal0: v.plane_normal * w0,
            iend: mirror_about(v.end(), v.plane_point, v.plane_normal) * w1,
            inormal1: v.plane_normal * w1,
            idir_sum: mirror_about(v.direction, DVec3::ZERO, v.plane_normal) * w_lam,
        }
    }

    pub(super) fn merge(parts: &[VolAgg]) -> Self {
        let mut a = VolAgg { lo: DVec3::INFINITY, hi: DVec3::NEG_INFINITY, ..VolAgg::default() };
        for p in parts {
            a.lo = a.lo.min(p.lo);
            a.hi = a.hi.max(p.hi);
            for c in 0..3 {
                a.lam[c] += p.lam[c];
                a.phi0[c] += p.phi0[c];
                a.phi1[c] += p.phi1[c];
            }
            a.center += p.center;
            a.start += p.start;
            a.end += p.end;
            a.dir_sum += p.dir_sum;
            a.tube += p.tube;
            a.istart += p.istart;
            a.inormal0 += p.inormal0;
            a.iend += p.iend;
            a.inormal1 += p.inormal1;
            a.idir_sum += p.idir_sum;
            a.w_lam += p.w_lam;
            a.w0 += p.w0;
            a.w1 += p.w1;
        }
        a
    }

    /// Half the diagonal of the end points' bounds (0 when empty).
    pub(super) fn radius(&self) -> f64 {
        if self.lo.x <= self.hi.x { 0.5 * (self.hi - self.lo).length() } else { 0.0 }
    }

    /// The image beam of channel `c` (extrapolation distance `z_b`): (start, end, unit direction).
    pub(super) fn image(&self, z_b: f64) -> (DVec3, DVec3, DVec3) {
        let div = |v: DVec3, w: f64| if w > 0.0 { v / w } else { v };
        let dir = self.idir_sum.try_normalize().unwrap_or(-DVec3::Z);
        let start = div(self.istart, self.w0) + 2.0 * z_b * div(self.inormal0, self.w0);
        let end = div(self.iend, self.w1) + 2.0 * z_b * div(self.inormal1, self.w1);
        (start, end, dir)
    }

    /// The weighted sums divided through: (centre, start, end, unit mean direction).
    pub(super) fn points(&self) -> (DVec3, DVec3, DVec3, DVec3) {
        let div = |v: DVec3, w: f64| if w > 0.0 { v / w } else { v };
        let dir = self.dir_sum.try_normalize().unwrap_or(DVec3::Z);
        (div(self.center, self.w_lam), div(self.start, self.w0), div(self.end, self.w1), dir)
    }
}

/// Aggregate of surface samples.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct SurfAgg {
    /// `Σ S_ext A/π` per channel \[W/sr\]: the scene's indirect light refracted in (its radiance
    /// inside follows the transmitted cone, [`Prepared::emission_profile`]).
    pub(super) power_ext: [f64; 3],
    /// `Σ S_int A/π`: the internally reflected light (its radiance follows `F(θ)`).
    pub(super) power_int: [f64; 3],
    /// Flux `Σ S A` emitted into the object along the inward normal, per channel \[W\] (all of it when
    /// [`RenderOptions::grazing_beams`] is 0, else the refracted scene light's).
    pub(super) flux0: [f64; 3],
    /// The part of it left unscattered at the chord's end, `Σ S A e^{−σ_t d}`.
    pub(super) flux1: [f64; 3],
    /// Flux of the internally reflected light sent along the grazing beams (0 without them).
    pub(super) graze0: [f64; 3],
    /// The part of it left unscattered at the grazing chords' ends.
    pub(super) graze1: [f64; 3],
    /// Power-weighted mean length of the grazing chords.
    pub(super) graze_len: f64,
    /// Power-weighted position.
    pub(super) pos: DVec3,
    /// Power-weighted chord end.
    pub(super) end: DVec3,
    /// Sum of power-weighted inward normals.
    pub(super) normal: DVec3,
    pub(super) w: f64,
}

impl SurfAgg {
    pub(super) fn merge(parts: &[SurfAgg]) -> Self {
        let mut a = SurfAgg::default();
        for p in parts {
            for c in 0..3 {
                a.power_ext[c] += p.power_ext[c];
                a.power_int[c] += p.power_int[c];
                a.flux0[c] += p.flux0[c];
                a.flux1[c] += p.flux1[c];
                a.graze0[c] += p.graze0[c];
                a.graze1[c] += p.graze1[c];
            }
            a.graze_len += p.graze_len;
            a.pos += p.pos;
            a.end += p.end;
            a.normal += p.normal;
            a.w += p.w;
        }
        a
    }
}

/// One surface sample as an emitter into the object (exitance `ex`, chord `d` along the inward
/// normal): its first-scattering powers split into the refracted scene light and the internal
/// reflections, the normal beam's flux and, with `graze.0` grazing beams at `cos θ = graze.1`, the
/// internally reflected flux, what is left of it at the grazing chords' ends and their mean length.
pub(super) fn surface_item(
    setup: &Setup,
    s: &SurfaceSample,
    ex: [f64; 3],
    d: f64,
    f_out: f64,
    graze: (u32, f64),
) -> SurfAgg {
    let sigma_t = setup.material.sigma_t;
    let s_ext: [f64; 3] = std::array::from_fn(|c| ((1.0 - f_out) * s.indirect[c]).min(ex[c]));
    let s_int: [f64; 3] = std::array::from_fn(|c| (ex[c] - s_ext[c]).max(0.0));
    let power_ext: [f64; 3] = std::array::from_fn(|c| s_ext[c] / PI * s.area);
    let power_int: [f64; 3] = std::array::from_fn(|c| s_int[c] / PI * s.area);
    let normal_share: [f64; 3] = if graze.0 > 0 { s_ext } else { ex };
    let flux0: [f64; 3] = std::array::from_fn(|c| normal_share[c] * s.area);
    let flux1: [f64; 3] = std::array::from_fn(|c| flux0[c] * (-sigma_t[c] * d).exp());
    let end = if d.is_finite() { s.position - s.normal * d } else { s.position };
    let w = ex.iter().sum::<f64>() * s.area;
    let (mut graze0, mut graze1, mut graze_len) = ([0.0; 3], [0.0; 3], 0.0);
    if graze.0 > 0 {
        // A ray that hits nothing (an open mesh) counts as a chord of length 0: nothing scatters.
        let chords: Vec<f64> = grazing_dirs(-s.normal, graze.1, graze.0)
            .map(|dir| Some(super::super::surface_light::chord(setup, s, dir)).filter(|q| q.is_finite()).unwrap_or(0.0))
            .collect();
        let n = chords.len() as f64;
        for c in 0..3 {
            graze0[c] = s_int[c] * s.area;
            graze1[c] = chords.iter().map(|&q| (-sigma_t[c] * q).exp()).sum::<f64>() * graze0[c] / n;
        }
        graze_len = chords.iter().sum::<f64>() / n * w;
    }
    SurfAgg {
        power_ext,
        power_int,
        flux0,
        flux1,
        graze0,
        graze1,
        graze_len,
        pos: s.position * w,
        end: end * w,
        normal: -s.normal * w,
        w,
    }
}

/// Radiance profile of the light the boundary sends into the object, relative to a Lambertian
/// emitter of the same exitance (both integrate to 1 against `cos θ dω/π` over the inner hemisphere):
/// the scene's diffuse light refracted in fills the cone inside the critical angle,
/// `(1 − F(θ)) η² / (1 − F_dr,out)`; the internally reflected light goes mostly to grazing angles,
/// `F(θ) / F_dr,in` (wang2018 Eq. 8 takes both as Lambertian). `θ` is measured from the inward normal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EmissionProfile {
    /// Index of refraction inside relative to outside.
    pub ior: f64,
    /// `F_dr,out`: diffuse Fresnel reflectance for light arriving from outside.
    pub f_out: f64,
    /// `F_dr,in`: the same from inside.
    pub f_in: f64,
}

impl EmissionProfile {
    /// (refracted, reflected) factors at `cos θ = mu`.
    pub fn factors(&self, mu: f64) -> (f64, f64) {
        let f = fresnel(mu, self.ior, 1.0);
        let ext = if self.f_out < 1.0 { (1.0 - f) * self.ior * self.ior / (1.0 - self.f_out) } else { 0.0 };
        let int = if self.f_in > 0.0 { f / self.f_in } else { 0.0 };
        (ext, int)
    }

    /// Median `cos θ` of the internally reflected light's flux, whose density in `μ = cos θ` is
    /// `∝ F(μ) μ` (2048-point midpoint rule, linear within the cell); without reflection
    /// (`F_dr,in = 0`) the Lambertian median `1/√2`.
    pub fn grazing_median(&self) -> f64 {
        let n = 2048;
        let dens: Vec<f64> = (0..n)
            .map(|i| {
                let mu = (i as f64 + 0.5) / n as f64;
                fresnel(mu, self.ior, 1.0) * mu
            })
            .collect();
        let total: f64 = dens.iter().sum();
        if total <= 0.0 {
            return std::f64::consts::FRAC_1_SQRT_2;
        }
        let mut acc = 0.0;
        for (i, d) in dens.iter().enumerate() {
            if acc + d >= 0.5 * total {
                return (i as f64 + (0.5 * total - acc) / d) / n as f64;
            }
            acc += d;
        }
        1.0
    }
}

/// `k` unit directions at `cos θ = mu` from the unit axis `n`, evenly spread in azimuth about it
/// (azimuth 0 along the first tangent of `frame_of(n)`).
pub(super) fn grazing_dirs(n: DVec3, mu: f64, k: u32) -> impl Iterator<Item = DVec3> {
    let (t1, t2) = frame_of(n);
    let sin = (1.0 - mu * mu).max(0.0).sqrt();
    (0..k).map(move |i| {
        let phi = 2.0 * PI * i as f64 / k as f64;
        n * mu + (t1 * phi.cos() + t2 * phi.sin()) * sin
    })
}
