//! baran2010: real-time shadowed single scattering ("god rays") in a homogeneous medium by epipolar
//! rectification and partial-sum trees, with brute-force ray-marching references.
//!
//! **Input → output.** A camera [`DistanceImage`] (from [`crate::render::gbuffer::distance_image`]),
//! a light [`ShadowMap`] ([`render_shadow_map`]), an [`EpiLight`] (directional or spot, optionally
//! textured), a homogeneous [`EpiMedium`] and [`EpipolarOptions`] → per pixel the single-scattered
//! in-scatter and the view transmittance ([`render`] → [`EpipolarOutput`]), composited over a colour
//! image by [`composite`].
//!
//! Pipeline of [`render`] (paper sections in brackets):
//! 1. [`rectify`]: epipole, slice distribution `x(α) = h·sinh(α)` per exit edge (Sec. 8, half-pixel
//!    bound), per slice the view-ray angles `β` and the rectified depth `D[β]` as a light-ray coordinate
//!    `γ` (Sec. 3; Sec. 9 for spot lights).
//! 2. [`factor`]: the visibility-free integrand `I(γ, β)` sampled on a grid and factorised by a Jacobi
//!    SVD into `N` terms `Γ_i(γ)·B_i(β)` (Sec. 6), shared by all slices.
//! 3. [`integrate`]: per slice, the shadow map rectified into blocker angles `S[γ]` with depth modes
//!    (Sec. 7), then the incremental sweep over `β` with a Fenwick half tree of `N`-vectors (Sec. 4–5).
//! 4. unrectification back to pixels (bilinear in slice angle and `β`, restricted to samples whose
//!    rectified depth matches the pixel's — a joint-bilateral rule the paper leaves to Engelhardt and
//!    Dachsbacher 2010), and ray marching ([`reference`](mod@reference)'s shadow-map marcher) in the ring around the
//!    epipole (Sec. 6) and at the few silhouette pixels no sample matches.
//!
//! **Conventions** (shared with the references, so all methods integrate the same quantity):
//! - Single scattering `L = ∫₀^d e^{−σ_t s} σ_s p(μ) L_in(x(s)) V(x(s)) ds` per channel, `p` the HG
//!   phase with `μ` the cosine between the light's propagation direction and the direction to the eye.
//! - The medium fills the box [`EpiMedium::region`] (a global medium: [`Scene::global_medium_bounds`],
//!   the region the Mitsuba export gives it too) and is vacuum outside it. A view ray integrates over
//!   its segment inside the box and in front of its depth ([`view_segment`]).
//! - Directional light: `L_in = E · texture · e^{−σ_t u}`, `E` the irradiance outside the medium and
//!   `u` the distance the light travelled inside the box to reach `x` (from where its ray enters the
//!   box, [`EpiMedium::light_entry`]). Spot light (inside the box): `L_in = I · falloff · texture ·
//!   e^{−σ_t r} / r²` with `r` the distance to the light and the KHR falloff `clamp((cos θ − cos θ_o)/
//!   max(cos θ_i − cos θ_o, 10⁻³), 0, 1)²` ([`crate::render::spot`]).
//! - The epipolar split of the directional attenuation: with `a` the coordinate along the direction to
//!   the light measured from the eye, `u = a_entry(γ) − a(x)`, so `e^{−σ_t s}·e^{−σ_t u} =
//!   e^{−σ_t γ tan(β/2)} · e^{−σ_t a_entry(γ)}`: the first factor is the (still exponential) kernel
//!   [`factor`] factorises, the second a per-light-ray factor like the texture. Where a light ray
//!   enters the box behind the eye's plane (`a_entry < 0`) the second factor exceeds 1 and amplifies
//!   the kernel's truncation error; a slice whose largest gain exceeds [`MAX_LIGHT_GAIN`] is ray
//!   marched instead (counted in [`EpipolarStats::gain_pixels`]), as is every pixel when the eye is
//!   outside the box (the view segment then does not start at the eye).
//! - Visibility `V` comes from the shadow map (nearest texel, depth bias [`ShadowMap::bias`]) for
//!   [`render`] and [`march_shadow_map`]; [`march_bvh`] casts real shadow rays.
//! - Per-channel `σ`: when `σ_t` is the same in all channels one kernel is factorised and `σ_s,c·E_c`
//!   scales the result per channel; otherwise each channel has its own factorised kernel and the tree
//!   stores `3·N`-vectors (the same holds for a textured light, whose colour multiplies `Γ_i`).
//! - Results are clamped to be finite and non-negative (a truncated SVD can undershoot slightly where
//!   the integrand is near zero); transmittance underflows to 0 for very dense fog, never to NaN.

mod stage;
pub use stage::*;
#[cfg(feature = "gpu")]
pub mod gpu;
#[cfg(feature = "gpu")]
pub mod shaders;

pub mod bench;
pub mod factor;
pub mod integrate;
pub mod rectify;
pub mod reference;
pub mod shadow_map;
pub mod tree;

#[cfg(test)]
pub(crate) mod tests;

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use crate::physics::medium::RgbMedium;
use crate::render::spot::SpotCone;
use crate::render::{DistanceImage, Image, RgbImage, ViewCamera};
use crate::scene::{Boundary, Density, LightKind, Scene};

pub use bench::{BenchReport, ErrorTimePoint, bench, error_vs_time, write_error_plot};
pub use reference::{march_bvh, march_shadow_map, mean_of_runs};
pub use shadow_map::{LightFrame, ShadowMap, render_shadow_map, trace_shadow_map};

/// A light for the epipolar effect (world space, metres, unit directions).
#[derive(Debug, Clone, PartialEq)]
pub enum EpiLight {
    /// Distant light.
    Directional {
        /// Unit direction the light travels to.
        direction: [f64; 3],
        /// Irradiance \[W/m²\] on a surface facing the light, per channel.
        irradiance: [f64; 3],
        /// Optional colour texture projected along the light over the shadow map's window
        /// (orthographic; `u` along [`LightFrame`]'s first axis, `v` along its second).
        texture: Option<RgbImage>,
    },
    /// Spot light with the KHR cone falloff.
    Spot {
        /// Position \[m\].
        position: [f64; 3],
        /// Unit direction the cone points to.
        direction: [f64; 3],
        /// Full-intensity half-angle \[rad\].
        inner_cone: f64,
        /// Cut-off half-angle \[rad\] (clamped to 80° for the shadow map's frustum).
        outer_cone: f64,
        /// On-axis intensity \[W/sr\] per channel.
        intensity: [f64; 3],
        /// Optional colour texture projected through the cone's square frustum.
        texture: Option<RgbImage>,
    },
}

impl EpiLight {
    /// The first directional or spot light of `scene` (untextured), `None` when it has neither or its
    /// direction is degenerate.
    pub fn from_scene(scene: &Scene) -> Option<EpiLight> {
        scene.lights.iter().find_map(|l| match &l.kind {
            LightKind::Directional { direction, .. } => {
                let d = DVec3::from_array(*direction).try_normalize()?;
                Some(EpiLight::Directional { direction: d.to_array(), irradiance: l.radiance, texture: None })
            }
            LightKind::Spot { position, direction, inner_cone, outer_cone } => {
                let d = DVec3::from_array(*direction).try_normalize()?;
                Some(EpiLight::Spot {
                    position: *position,
                    direction: d.to_array(),
                    inner_cone: *inner_cone,
                    outer_cone: *outer_cone,
                    intensity: l.radiance,
                    texture: None,
                })
            }
            _ => None,
        })
    }

    /// The light's texture, if any.
    pub fn texture(&self) -> Option<&RgbImage> {
        match self {
            EpiLight::Directional { texture, .. } | EpiLight::Spot { texture, .. } => texture.as_ref(),
        }
    }

    /// Per-channel strength: irradiance (directional) or intensity (spot).
    pub fn strength(&self) -> [f64; 3] {
        match self {
            EpiLight::Directional { irradiance, .. } => *irradiance,
            EpiLight::Spot { intensity, .. } => *intensity,
        }
    }

    /// A spot light's cone (`None` for a directional light, or a spot whose axis or angles are degenerate).
    pub fn cone(&self) -> Option<SpotCone> {
        match self {
            EpiLight::Directional { .. } => None,
            EpiLight::Spot { direction, inner_cone, outer_cone, .. } => {
                SpotCone::khr(DVec3::from_array(*direction), *inner_cone, *outer_cone)
            }
        }
    }

    /// KHR spot falloff of the unit direction `w` from the light ([`crate::render::spot`]; 1 for a
    /// directional light, 0 for a spot without a cone).
    pub fn falloff(&self, w: DVec3) -> f64 {
        match self {
            EpiLight::Directional { .. } => 1.0,
            EpiLight::Spot { .. } => self.cone().map_or(0.0, |c| c.falloff(w)),
        }
    }
}

/// A homogeneous medium with an HG phase function filling a box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EpiMedium {
    /// The coefficients; the phase function is read at the channel mean of `g` (one value for all
    /// channels: the factorisation shares `β` across channels).
    pub coefficients: RgbMedium,
    /// The box the medium fills, `(min, max)` corners \[m\]; vacuum outside it.
    pub region: ([f64; 3], [f64; 3]),
}

/// Largest per-light-ray gain `e^{−σ_t a_entry}` the epipolar integration accepts (module doc); a slice
/// needing more is ray marched.
pub const MAX_LIGHT_GAIN: f64 = 64.0;

impl EpiMedium {
    /// The first homogeneous global medium of `scene` over the scene's
    /// global-medium box, `None` if there is none (or the scene has no extent).
    pub fn from_scene(scene: &Scene) -> Option<EpiMedium> {
        let region = scene.global_medium_bounds()?;
        scene
            .media
            .iter()
            .find(|m| m.boundary == Boundary::Global && m.density == Density::Homogeneous)
            .map(|m| EpiMedium { coefficients: m.coefficients(), region })
    }

    /// Why `scene` has no medium [`EpiMedium::from_scene`] accepts: each medium it has and what rules it
    /// out (the field to change), or that it has none.
    pub fn refusal(scene: &Scene) -> String {
        if scene.media.is_empty() {
            return format!("{} has no participating medium", scene.source.display());
        }
        let reasons: Vec<String> = scene
            .media
            .iter()
            .map(|m| match (&m.boundary, &m.density) {
                (Boundary::Global, Density::Homogeneous) => format!("medium {:?} fills a scene without extent", m.name),
                (Boundary::Global, _) => format!(
                    "medium {:?} has a height-varying density (exponential height fog): the god rays integrate a homogeneous medium (density Homogeneous); ImageFog renders height fog",
                    m.name
                ),
                (Boundary::Mesh(k), _) => format!(
                    "medium {:?} is bounded by mesh {k}: the god rays take a global medium (it fills the scene's padded bounds), not a fog volume bounded by a mesh (not supported yet)",
                    m.name
                ),
            })
            .collect();
        format!("{}: no homogeneous global medium ({})", scene.source.display(), reasons.join("; "))
    }

    /// Whether `p` lies in [`EpiMedium::region`] (boundary included).
    pub fn contains(&self, p: DVec3) -> bool {
        (0..3).all(|a| p[a] >= self.region.0[a] && p[a] <= self.region.1[a])
    }

    /// Where the light enters the medium on the line `p + a·toward` (`toward` the unit direction to
    /// the light): the largest `a` at which the line is inside the region, `None` when it misses it.
    /// For `p` inside the region it is the distance the light travels in the medium to reach `p`.
    pub fn light_entry(&self, p: DVec3, toward: DVec3) -> Option<f64> {
        let (lo, hi) = clip_line(p, toward, self.region)?;
        (hi >= lo).then_some(hi)
    }

    /// Per-channel light attenuation `e^{−σ_t a}` for a light path of length `a` in the medium
    /// (negative `a`: gain, see the module doc); 0 for a non-finite `a`.
    pub fn light_attenuation(&self, a: f64) -> [f64; 3] {
        let att = |s: f64| {
            let v = (-s * a).exp();
            if v.is_finite() { v } else { 0.0 }
        };
        let st = self.sigma_t();
        // Grey fog (the common case, once per γ bin of every slice): one exponential.
        if st[0] == st[1] && st[1] == st[2] { [att(st[0]); 3] } else { st.map(att) }
    }

    /// Extinction per channel (negative or NaN inputs count as 0).
    pub fn sigma_t(&self) -> [f64; 3] {
        [0, 1, 2].map(|c| clean(self.coefficients.sigma_s[c]) + clean(self.coefficients.sigma_a[c]))
    }

    /// Scattering per channel (negative or NaN inputs count as 0).
    pub fn sigma_s_clean(&self) -> [f64; 3] {
        self.coefficients.sigma_s.map(clean)
    }

    /// The phase function's g: the channel mean, clamped to ±0.999 (0 when not finite).
    pub fn phase_g(&self) -> f64 {
        let g = self.coefficients.mean_g();
        if g.is_finite() { g.clamp(-0.999, 0.999) } else { 0.0 }
    }

    /// HG phase for cosine `mu` at [`EpiMedium::phase_g`].
    pub fn phase(&self, mu: f64) -> f64 {
        crate::physics::hg::phase(mu, self.phase_g())
    }
}

fn clean(x: f64) -> f64 {
    if x.is_finite() && x > 0.0 { x } else { 0.0 }
}

/// Knobs of [`render`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EpipolarOptions {
    /// Slice density relative to the half-pixel bound of Sec. 8 (1 = adjacent slices one pixel apart
    /// at the screen edge they leave through; larger is denser).
    pub slice_density: f64,
    /// View-ray samples `β` per pixel of epipolar line.
    pub samples_per_pixel: f64,
    /// Light-ray bins `d` along `γ` (the integration grid; paper: 2048–4096).
    pub gamma_bins: usize,
    /// SVD rank `N` (Sec. 6; paper: 4).
    pub rank: usize,
    /// Largest number of depth modes per `γ` bin (Sec. 7). 1 disables prefiltering (one blocker
    /// sample per bin); otherwise 4 sub-samples per bin are clustered into at most this many modes.
    pub depth_modes: usize,
    /// Radius \[px\] of the disc around the epipole that is ray marched; `None`: 2° of view angle (4° around
    /// the anti-epipole of a directional light behind the camera, where the kernel is steepest).
    pub ring_px: Option<f64>,
    /// Steps per ray of the ring march.
    pub ring_steps: usize,
}

impl Default for EpipolarOptions {
    fn default() -> Self {
        EpipolarOptions {
            slice_density: 1.0,
            samples_per_pixel: 1.0,
            gamma_bins: 2048,
            rank: 4,
            depth_modes: 4,
            ring_px: None,
            ring_steps: 128,
        }
    }
}

/// Timings and sizes of one [`render`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EpipolarStats {
    /// Slice layout, rectified depth map \[ms\].
    pub rectify_ms: f64,
    /// SVD factorisation of `I(γ, β)` \[ms\].
    pub factorize_ms: f64,
    /// Shadow-map rectification and depth modes (share of the per-slice stage's wall time) \[ms\].
    pub prefilter_ms: f64,
    /// Tree build and sweep (share of the per-slice stage's wall time) \[ms\].
    pub integrate_ms: f64,
    /// Ray marching around the epipole and at unmatched silhouette pixels \[ms\].
    pub ring_ms: f64,
    /// Unrectification and transmittance \[ms\].
    pub unrectify_ms: f64,
    /// Wall time of the whole call \[ms\].
    pub total_ms: f64,
    /// Epipolar slices.
    pub slices: usize,
    /// `β` samples over all slices.
    pub samples: usize,
    /// Pixels ray marched in the ring.
    pub ring_pixels: usize,
    /// Pixels outside the ring ray marched because no slice sample near them has a matching depth
    /// (silhouettes thinner than the slice spacing).
    pub edge_pixels: usize,
    /// Pixels ray marched because the slices around them need a light gain above [`MAX_LIGHT_GAIN`],
    /// or (all pixels) because the eye is outside the medium's region (module doc).
    pub gain_pixels: usize,
    /// Slices whose light gain exceeds [`MAX_LIGHT_GAIN`].
    pub gain_slices: usize,
    /// Ratio of the `N+1`-th to the first singular value (0 when the rank is complete): how much the
    /// truncation leaves out.
    pub svd_residual: f64,
}

/// What [`render`] returns.
#[derive(Debug, Clone, PartialEq)]
pub struct EpipolarOutput {
    /// In-scattered radiance per pixel.
    pub inscatter: RgbImage,
    /// Per-pixel view transmittance `exp(−σ_t d)` over the view extent `d`.
    pub transmittance: RgbImage,
    /// Timings and sizes.
    pub stats: EpipolarStats,
}

/// The parameter interval `(lo, hi)` over which the line `origin + t·dir` lies in the box `b`
/// (unbounded along axes it runs parallel to inside the slab), `None` when it misses the box.
pub(crate) fn clip_line(origin: DVec3, dir: DVec3, b: ([f64; 3], [f64; 3])) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    for a in 0..3 {
        let (o, v) = (origin[a], dir[a]);
        if v.abs() < 1e-300 {
            if o < b.0[a] || o > b.1[a] {
                return None;
            }
            continue;
        }
        let (ta, tb) = ((b.0[a] - o) / v, (b.1[a] - o) / v);
        t0 = t0.max(ta.min(tb));
        t1 = t1.min(ta.max(tb));
    }
    (t1 >= t0 && t0.is_finite() && t1.is_finite()).then_some((t0, t1))
}

/// The medium segment `(s0, s1)` of a view ray from `origin` along unit `dir` that ends at `depth`
/// (infinite: hits nothing): the part inside `region` and in front of the depth; `(0, 0)` when the
/// ray never is in the region. `s0 > 0` only for an origin outside the region.
pub fn view_segment(origin: DVec3, dir: DVec3, depth: f32, region: ([f64; 3], [f64; 3])) -> (f64, f64) {
    let d = f64::from(depth);
    let end = if d.is_nan() { 0.0 } else { d.max(0.0) };
    match clip_line(origin, dir, region) {
        Some((lo, hi)) => {
            let (s0, s1) = (lo.max(0.0), hi.min(end));
            if s1 > s0 { (s0, s1) } else { (0.0, 0.0) }
        }
        None => (0.0, 0.0),
    }
}

/// `∫_a^b e^{−σ t} dt` without cancellation, for `σ ≥ 0` (`b − a` at `σ = 0`).
pub(crate) fn exp_integral(sigma: f64, a: f64, b: f64) -> f64 {
    let w = b - a;
    if w <= 0.0 {
        return 0.0;
    }
    let x = sigma * w;
    if x < 1e-12 {
        return (-sigma * a).exp() * w;
    }
    (-sigma * a).exp() * (-(-x).exp_m1()) / sigma
}

/// Nearest-texel lookup of `tex` at `uv ∈ [0, 1]²` (`v` down), clamped to the edges; white when
/// there is no texture or it is empty.
pub(crate) fn sample_texture(tex: Option<&RgbImage>, uv: [f64; 2]) -> [f64; 3] {
    let Some(t) = tex.filter(|t| t.width > 0 && t.height > 0) else { return [1.0; 3] };
    let x = ((uv[0] * t.width as f64).floor().max(0.0) as usize).min(t.width - 1);
    let y = ((uv[1] * t.height as f64).floor().max(0.0) as usize).min(t.height - 1);
    t.at(x, y).map(|c| if c.is_finite() && c > 0.0 { f64::from(c) } else { 0.0 })
}

/// Per-channel light modulation at `p`: texture (sampled at the frame's window coordinates) times the
/// spot falloff; 0 behind a spot light, 1 for an untextured directional light.
pub(crate) fn modulation(light: &EpiLight, frame: &LightFrame, p: DVec3) -> [f64; 3] {
    let fall = match light {
        EpiLight::Directional { .. } => 1.0,
        EpiLight::Spot { position, .. } => match (p - DVec3::from_array(*position)).try_normalize() {
            Some(w) => light.falloff(w),
            None => return [0.0; 3],
        },
    };
    if fall <= 0.0 {
        return [0.0; 3];
    }
    match light.texture() {
        None => [fall; 3],
        Some(t) => match frame.uv(p) {
            Some(uv) => sample_texture(Some(t), uv).map(|c| c * fall),
            None => [0.0; 3],
        },
    }
}

/// Renders the in-scatter and transmittance of `medium` lit by `light` (visibility from `shadow`) for
/// every pixel of `cam`, on the current rayon pool. Deterministic: bit-identical for any thread count.
/// `depth` must have the camera's raster size (a mismatching image is read with clamped indices).
pub fn render(
    cam: &ViewCamera,
    depth: &DistanceImage,
    light: &EpiLight,
    shadow: &ShadowMap,
    medium: &EpiMedium,
    opts: &EpipolarOptions,
) -> EpipolarOutput {
    let start = Instant::now();
    let mut stats = EpipolarStats::default();
    let (w, h) = (cam.width, cam.height);

    // 1. Slices and rectified depth.
    let t0 = Instant::now();
    let setup = rectify::Setup::new(cam, depth, light, medium.region, opts);
    stats.rectify_ms = ms(t0);
    stats.slices = setup.slices.len();
    stats.samples = setup.slices.iter().map(|s| s.betas.len()).sum();

    // 2. Factorisation of I(γ, β).
    let t1 = Instant::now();
    let fac = factor::Factorization::new(&setup, medium, opts);
    stats.factorize_ms = ms(t1);
    stats.svd_residual = fac.residual;

    // 3. Per slice: rectified shadow map, depth modes, tree sweep.
    let t2 = Instant::now();
    let per_slice: Vec<integrate::SliceResult> = setup
        .slices
        .par_iter()
        .map(|s| integrate::integrate_slice(&setup, &fac, s, light, shadow, medium, opts))
        .collect();
    stats.gain_slices = per_slice.iter().filter(|r| r.over_gain).count();
    let eye_inside = medium.contains(cam.position);
    let wall = ms(t2);
    let (pre, int): (f64, f64) =
        per_slice.iter().fold((0.0, 0.0), |(a, b), r| (a + r.prefilter_ns as f64, b + r.integrate_ns as f64));
    let frac = if pre + int > 0.0 { pre / (pre + int) } else { 0.5 };
    stats.prefilter_ms = wall * frac;
    stats.integrate_ms = wall * (1.0 - frac);

    // 4. Unrectify; pixels in the ring or without a depth-matching sample are ray marched.
    let t3 = Instant::now();
    let sigma_t = medium.sigma_t();
    let grey = sigma_t[0] == sigma_t[1] && sigma_t[1] == sigma_t[2];
    let rows: Vec<UnrectifiedRow> = (0..h)
        .into_par_iter()
        .map(|y| {
            let (mut row, mut trow, mut march) = (vec![[0.0f32; 3]; w], vec![[1.0f32; 3]; w], Vec::new());
            for x in 0..w {
                let v = cam.pixel_dir(x, y);
                let (s0, s1) = view_segment(cam.position, v, depth_at(depth, x, y), medium.region);
                let d = s1 - s0;
                trow[x] =
                    if grey { [(-sigma_t[0] * d).exp() as f32; 3] } else { sigma_t.map(|s| (-s * d).exp() as f32) };
                let r = if setup.in_ring(x, y) || !eye_inside {
                    None
                } else {
                    setup.unrectify(&per_slice, x, y, v, s1, fac.dgamma)
                };
                match r {
                    Some(px) => row[x] = px,
                    None => march.push((x, !eye_inside || setup.over_gain(&per_slice, x, y))),
                }
            }
            (row, trow, march)
        })
        .collect();
    let mut inscatter = Image::filled(w, h, [0.0f32; 3]);
    let mut transmittance = Image::filled(w, h, [1.0f32; 3]);
    let mut ring: Vec<(usize, usize)> = Vec::new();
    for (y, (row, trow, march)) in rows.into_iter().enumerate() {
        inscatter.data[y * w..(y + 1) * w].copy_from_slice(&row);
        transmittance.data[y * w..(y + 1) * w].copy_from_slice(&trow);
        for (x, other) in march {
            if setup.in_ring(x, y) && eye_inside {
                stats.ring_pixels += 1;
            } else if other {
                stats.gain_pixels += 1;
            } else {
                stats.edge_pixels += 1;
            }
            ring.push((x, y));
        }
    }
    stats.unrectify_ms = ms(t3);

    let t4 = Instant::now();
    let ctx = reference::MarchCtx {
        cam,
        depth,
        light,
        vis: reference::Visibility::ShadowMap(shadow),
        medium,
        frame: &shadow.frame,
        steps: opts.ring_steps,
        run: 0,
    };
    let marched: Vec<[f32; 3]> = ring.par_iter().map(|&(x, y)| ctx.pixel(x, y)).collect();
    for (&(x, y), v) in ring.iter().zip(marched) {
        inscatter.data[y * w + x] = v;
    }
    stats.ring_ms = ms(t4);
    stats.total_ms = ms(start);
    EpipolarOutput { inscatter, transmittance, stats }
}

/// One row of unrectified in-scatter, its transmittance and the columns left for ray marching.
/// A marched column carries whether it is marched for the light gain or the eye's position (not a
/// silhouette or the ring).
type UnrectifiedRow = (Vec<[f32; 3]>, Vec<[f32; 3]>, Vec<(usize, bool)>);

/// `colour · T + inscatter` per pixel and channel (images of equal size; extra pixels of a larger
/// `colour` are ignored, missing ones read as black).
pub fn composite(colour: &RgbImage, out: &EpipolarOutput) -> RgbImage {
    let mut img = out.inscatter.clone();
    for (i, px) in img.data.iter_mut().enumerate() {
        let c = colour.data.get(i).copied().unwrap_or([0.0; 3]);
        let t = out.transmittance.data[i];
        for k in 0..3 {
            let v = c[k] * t[k] + px[k];
            px[k] = if v.is_finite() { v } else { 0.0 };
        }
    }
    img
}

/// Distance along the view direction that projects to raster position `q` (pixel centres at `i + ½`):
/// the bilinear blend of the four surrounding pixels when they see one surface (all finite, the
/// largest at most 1.1× the smallest), else the containing pixel's (across a silhouette or the sky
/// nothing is blended). A view-ray sample between pixel centres on a grazing surface then ends on the
/// surface instead of up to half a pixel's depth change beyond it — through it, into fog the light
/// may reach behind it (the leak the grazing-sun stress case of issue 32 measured).
pub(crate) fn sample_depth(depth: &DistanceImage, q: [f64; 2]) -> f32 {
    let (w, h) = (depth.width, depth.height);
    if w == 0 || h == 0 {
        return f32::INFINITY;
    }
    let near = depth_at(depth, q[0].max(0.0) as usize, q[1].max(0.0) as usize);
    let (fx, fy) = ((q[0] - 0.5).clamp(0.0, (w - 1) as f64), (q[1] - 0.5).clamp(0.0, (h - 1) as f64));
    let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let d = [depth.at(x0, y0), depth.at(x1, y0), depth.at(x0, y1), depth.at(x1, y1)];
    let (lo, hi) = d.iter().fold((f32::INFINITY, 0.0f32), |(a, b), &v| (a.min(v), b.max(v)));
    if !(lo > 0.0 && hi.is_finite() && hi <= 1.1 * lo) {
        return near;
    }
    let (tx, ty) = (fx - x0 as f64, fy - y0 as f64);
    let d = d.map(f64::from);
    let top = (1.0 - tx) * d[0] + tx * d[1];
    let bottom = (1.0 - tx) * d[2] + tx * d[3];
    ((1.0 - ty) * top + ty * bottom) as f32
}

/// Depth of pixel `(x, y)` with clamped indices (`∞` for an empty image).
pub(crate) fn depth_at(depth: &DistanceImage, x: usize, y: usize) -> f32 {
    if depth.width == 0 || depth.height == 0 {
        return f32::INFINITY;
    }
    depth.at(x.min(depth.width - 1), y.min(depth.height - 1))
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}
