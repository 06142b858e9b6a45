//! Analytic fog media and the per-pixel quantities of iser2018 Sec. 3–4.1.
//!
//! **Input → output.** A [`FogMedium`] (a sum of homogeneous and exponential-height components) and a
//! camera ray (origin, unit direction, distance `D`, `D = ∞` for sky pixels) → the density integrals
//! `P_i = ∫₀ᴰ ρ_i` (Sec. 3.3, Eq. 4), the absorption / scattering optical depths, the transmittance
//! `T = e^{−τ_t}` and the spread: Eq. 1 `W(s)` and its density-scaled form Eq. 3 `W(P)`, turned into an
//! image-space standard deviation in pixels ([`PixelFog::spread_px`]).
//!
//! **Stability.** [`exponential_integral`] is [`crate::scene::bvh::exponential_density_integral`]
//! (one implementation for the scene's media queries and the effect): Eq. 4 as
//! `ρ' D e^{max(a₀, a₁)} φ(|b D μ|)` with the log-densities `a₀ = −b h₀`, `a₁ = a₀ − b D μ` at the two
//! ends and `φ(y) = −expm1(−y)/y`: no cancellation for `μ = ⟨ω, n⟩ → 0` or tiny `b`, the exponential
//! taken at the denser end (no overflow for downward rays unless the integral itself exceeds
//! `f64::MAX`, then `+∞`), and `D = ∞` handled (finite for rays going up, `+∞` otherwise); the
//! log-space form is only evaluated when the direct product is not a normal number. The tests check it
//! against Gauss–Legendre quadrature of the density.
//! Every quantity derived from `P` is written so that `P = +∞` gives its limit instead of NaN.

use glam::DVec3;

use crate::physics::medium::RgbMedium;
use crate::scene::{Boundary, Density, Scene};

/// One analytic component of the fog: coefficients at density 1 scaled by a density field.
#[derive(Debug, Clone, PartialEq)]
pub struct FogComponent {
    /// Coefficients at density 1 (the paper's `C_s`, `C_a`); the spread of Eq. 1 takes one `g`, the
    /// channel mean.
    pub coefficients: RgbMedium,
    /// Density field (homogeneous `ρ ≡ 1` or iser2018's exponential height fog).
    pub density: Density,
}

/// A sum of analytic fog components filling all space (the scene's global media).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FogMedium {
    /// The components; optical depths add.
    pub components: Vec<FogComponent>,
}

/// What the fog does along one camera ray (all per channel unless noted).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelFog {
    /// Absorption optical depth `τ_a = Σ σ_a,i P_i`.
    pub tau_a: [f64; 3],
    /// Scattering optical depth `τ_s = Σ σ_s,i P_i`.
    pub tau_s: [f64; 3],
    /// Reduced scattering depth averaged over channels, `Σ σ_s,i (1 − g_i) P_i` (drives the spread).
    pub tau_reduced: f64,
    /// Absorption depth averaged over channels (drives the spread).
    pub tau_a_mean: f64,
}

impl FogComponent {
    /// `P = ∫₀ᴰ ρ(origin + t·dir) dt` for a unit `dir` (Sec. 3.3): `ρ·D` exactly for a homogeneous
    /// component (`+∞` for `D = ∞`), Eq. 4 in stable form for the exponential one. `D ≤ 0` or NaN → 0.
    /// Never NaN for finite inputs; `+∞` only where the integral diverges or exceeds `f64::MAX`.
    pub fn density_integral(&self, origin: DVec3, dir: DVec3, distance: f64) -> f64 {
        if distance.is_nan() || distance <= 0.0 {
            return 0.0;
        }
        match &self.density {
            Density::Homogeneous => distance,
            Density::ExponentialHeight { rho, falloff, direction, offset } => {
                let n = DVec3::from_array(*direction);
                let len = n.length();
                if !(len > 0.0 && len.is_finite()) {
                    return 0.0;
                }
                let n = n / len;
                let h0 = (origin - DVec3::from_array(*offset)).dot(n);
                let mu = dir.dot(n);
                if *falloff == 0.0 {
                    return if distance.is_finite() { rho * distance } else { f64::INFINITY };
                }
                let p = exponential_integral(*rho, *falloff, h0, mu, distance);
                if p.is_nan() { 0.0 } else { p }
            }
        }
    }
}

impl FogMedium {
    /// The global media of `scene` (media with [`Boundary::Global`]) as fog components; `None` when the
    /// scene has none. Per-channel `g` is averaged (the spread of Eq. 1 takes one `g`).
    pub fn from_scene(scene: &Scene) -> Option<FogMedium> {
        let components: Vec<FogComponent> = scene
            .media
            .iter()
            .filter(|m| m.boundary == Boundary::Global)
            .map(|m| FogComponent { coefficients: m.coefficients(), density: m.density.clone() })
            .collect();
        if components.is_empty() { None } else { Some(FogMedium { components }) }
    }

    /// Per-component density integrals `P_i` along the ray (see [`FogComponent::density_integral`]).
    pub fn density_integrals(&self, origin: DVec3, dir: DVec3, distance: f64) -> Vec<f64> {
        self.components.iter().map(|c| c.density_integral(origin, dir, distance)).collect()
    }

    /// Optical depths along the ray (Sec. 4.1: `τ = C_t ∫ρ`, summed over components). A component
    /// with zero coefficients contributes nothing even where its `P` is infinite (no `0·∞`).
    pub fn pixel_fog(&self, origin: DVec3, dir: DVec3, distance: f64) -> PixelFog {
        let mut f = PixelFog { tau_a: [0.0; 3], tau_s: [0.0; 3], tau_reduced: 0.0, tau_a_mean: 0.0 };
        for c in &self.components {
            let p = c.density_integral(origin, dir, distance);
            if p == 0.0 {
                continue;
            }
            let mul = |k: f64| if k == 0.0 { 0.0 } else { k * p };
            let RgbMedium { sigma_s, sigma_a, .. } = c.coefficients;
            for ch in 0..3 {
                f.tau_a[ch] += mul(sigma_a[ch]);
                f.tau_s[ch] += mul(sigma_s[ch]);
            }
            let s_mean = (sigma_s[0] + sigma_s[1] + sigma_s[2]) / 3.0;
            let a_mean = (sigma_a[0] + sigma_a[1] + sigma_a[2]) / 3.0;
            f.tau_reduced += mul(s_mean * (1.0 - c.coefficients.mean_g()).max(0.0));
            f.tau_a_mean += mul(a_mean);
        }
        f
    }
}

impl PixelFog {
    /// [`Self::transmittance`] and [`Self::scatter_weight`] from three shared exponentials per
    /// channel (`1 − e^{−τ_s}` through `expm1` below `τ_s = 0.01`, where the subtraction would lose
    /// digits).
    pub fn weights(&self) -> ([f64; 3], [f64; 3]) {
        let mut t = [0.0; 3];
        let mut s = [0.0; 3];
        for c in 0..3 {
            let ea = (-self.tau_a[c]).exp();
            let ts = self.tau_s[c];
            let es = (-ts).exp();
            t[c] = ea * es;
            s[c] = ea * if ts < 0.01 { -(-ts).exp_m1() } else { 1.0 - es };
        }
        (t, s)
    }

    /// Transmittance `T = e^{−(τ_a + τ_s)}` per channel (0 for infinite depth).
    pub fn transmittance(&self) -> [f64; 3] {
        [0, 1, 2].map(|c| (-(self.tau_a[c] + self.tau_s[c])).exp())
    }

    /// Weight of the scattered image `e^{−τ_a}(1 − e^{−τ_s})` per channel (Sec. 4.1, `L_sc = weight·L`),
    /// with `1 − e^{−τ_s}` as `−expm1(−τ_s)` so thin fog keeps its precision.
    pub fn scatter_weight(&self) -> [f64; 3] {
        [0, 1, 2].map(|c| (-self.tau_a[c]).exp() * -(-self.tau_s[c]).exp_m1())
    }

    /// The spread as an angle \[rad\]: `W/s` of Eq. 1 written in optical depths (see [`spread_angle`]).
    pub fn spread_angle(&self) -> f64 {
        spread_angle(self.tau_a_mean, self.tau_reduced)
    }

    /// Image-space standard deviation \[pixels\] for a camera with focal length `focal_px` \[pixels\]
    /// (`height / (2 tan(yfov/2))`): `focal_px · W(P)/P`, the angle that the density-scaled homogeneous
    /// path of Eq. 3 (length `P`, reference density 1) subtends. Clamped to `[0, f32::MAX]`: an infinite
    /// spread selects the last MIP level.
    pub fn spread_px(&self, focal_px: f64) -> f32 {
        let w = focal_px * self.spread_angle();
        if w.is_nan() { 0.0 } else { w.clamp(0.0, f32::MAX as f64) as f32 }
    }
}

/// Eq. 4 in stable form: `∫₀ᴰ ρ' e^{−b(h₀ + t μ)} dt` for a ray starting at height `h₀ = ⟨c − o, n⟩`
/// with direction cosine `μ = ⟨ω, n⟩`; the scene's media queries use the same function.
pub use crate::scene::bvh::exponential_density_integral as exponential_integral;

/// Eq. 1 (Premože et al.): `W(s) = sqrt(½ (2σ_a/(3s) + 4/(s³ σ_s (1−g)))^{-1})` \[m\], the standard
/// deviation of the spatial spreading of a pencil after a path of length `s` in a homogeneous medium.
/// Written as `s·sqrt(v / (4uv/3 + 8))` with `u = σ_a s`, `v = σ_s(1−g) s` (see [`spread_angle`]), so
/// `s → 0`, `σ_s → 0` (W → 0) and `s = ∞` (W → ∞ without absorption) are exact limits, never NaN.
pub fn spread_width(s: f64, sigma_a: f64, sigma_s: f64, g: f64) -> f64 {
    if s.is_nan() || s <= 0.0 {
        return 0.0;
    }
    if s.is_infinite() {
        // ½ (0 + 0)^{-1}: unbounded unless nothing scatters.
        return if sigma_s * (1.0 - g).max(0.0) > 0.0 { f64::INFINITY } else { 0.0 };
    }
    let theta = spread_angle(sigma_a * s, sigma_s * (1.0 - g).max(0.0) * s);
    if theta == 0.0 {
        return 0.0;
    }
    s * theta
}

/// `W(s)/s` of Eq. 1 as a function of the absorption depth `u = σ_a s` and the reduced scattering
/// depth `v = σ_s (1−g) s` only: `sqrt(v / (4uv/3 + 8))`. This is how sums of components enter the
/// spread: their depths add. Limits: `v = 0` → 0; `v = ∞` → `sqrt(3/(4u))` (∞ for `u = 0`).
pub fn spread_angle(u: f64, v: f64) -> f64 {
    let u = if u.is_nan() { 0.0 } else { u.max(0.0) };
    let v = if v.is_nan() { 0.0 } else { v.max(0.0) };
    if v == 0.0 {
        return 0.0;
    }
    if v.is_infinite() {
        return if u == 0.0 { f64::INFINITY } else { (0.75 / u).sqrt() };
    }
    // v / (4uv/3 + 8) = 1 / (4u/3 + 8/v): no ∞/∞ when u·v overflows.
    (1.0 / (4.0 * u / 3.0 + 8.0 / v)).sqrt()
}

/// Rows of the stability matrix ([`crate::stability`]): the fog integrals and the spread at the
/// inputs where the paper's forms cancel or overflow, each against its analytic limit.
pub fn stability_rows() -> Vec<crate::stability::Row> {
    use crate::stability::{Expect, Row};
    let row = |formula: &'static str, input: String, value: f64, expect: Expect| Row {
        kind: "ImageFog",
        formula,
        input,
        value,
        expect,
    };
    let p = "P = ∫ρ' e^{-b(h0 + tμ)} dt";
    let w = "W(s) (Eq. 1)";
    vec![
        // ⟨ω,n⟩ → 0: the quotient (1 − e^{−bDμ})/(bμ) → D.
        row(
            p,
            "ρ'=1, b=0.05, h0=0, μ=1e-12, D=100".into(),
            exponential_integral(1.0, 0.05, 0.0, 1e-12, 100.0),
            Expect::Close { to: 100.0, rel: 1e-9 },
        ),
        row(
            p,
            "ρ'=1, b=0.05, h0=0, μ=-1e-12, D=100".into(),
            exponential_integral(1.0, 0.05, 0.0, -1e-12, 100.0),
            Expect::Close { to: 100.0, rel: 1e-9 },
        ),
        // Tiny b: homogeneous limit ρ'D.
        row(
            p,
            "ρ'=1, b=1e-12, h0=0, μ=0.7, D=50".into(),
            exponential_integral(1.0, 1e-12, 0.0, 0.7, 50.0),
            Expect::Close { to: 50.0, rel: 1e-9 },
        ),
        // Huge b·D downwards: the naive e^{1000} overflows; P = e^{700}.
        row(
            p,
            "ρ'=1, b=1, h0=300, μ=-1, D=1000".into(),
            exponential_integral(1.0, 1.0, 300.0, -1.0, 1000.0),
            Expect::Close { to: 700f64.exp(), rel: 1e-9 },
        ),
        // Sky pixel looking up: D = ∞ gives ρ' e^{−b h0}/(bμ).
        row(
            p,
            "ρ'=0.8, b=0.05, h0=-1.7, μ=0.5, D=∞".into(),
            exponential_integral(0.8, 0.05, -1.7, 0.5, f64::INFINITY),
            Expect::Close { to: 0.8 * (0.05f64 * 1.7).exp() / 0.025, rel: 1e-12 },
        ),
        // Zero path: no spread (level 0).
        row(w, "s=0".into(), spread_width(0.0, 0.01, 0.02, 0.5), Expect::InRange(0.0, 0.0)),
        // Short path: W ≈ s·sqrt(σ_s(1−g)s/8) (u → 0, v → 0).
        row(
            w,
            "s=1e-6, σ_a=0.01, σ_s=0.02, g=0.5".into(),
            spread_width(1e-6, 0.01, 0.02, 0.5),
            Expect::Close { to: 1e-6 * (0.01f64 * 1e-6 / 8.0).sqrt(), rel: 1e-6 },
        ),
        // g → 1: nothing spreads.
        row(w, "s=100, g=1".into(), spread_width(100.0, 0.01, 0.02, 1.0), Expect::InRange(0.0, 0.0)),
        // Long path with absorption: W/s → sqrt(3/(4 σ_a s)).
        row(
            w,
            "s=1e12, σ_a=0.01, σ_s=0.02, g=0.5".into(),
            spread_width(1e12, 0.01, 0.02, 0.5) / 1e12,
            Expect::Close { to: (0.75f64 / (0.01 * 1e12)).sqrt(), rel: 1e-6 },
        ),
    ]
}
