// Image-space fog: the per-pixel analytic integrals (iser2018 Secs. 3.3, 4.1): the density integral
// P_i = ∫₀ᴰ ρ_i of every fog component along the pixel's ray (Eq. 4 for exponential height fog), the
// optical depths, L_at = e^{−τ_t} L, L_sc = e^{−τ_a}(1 − e^{−τ_s}) L and the spread W [pixels]
// (Eq. 1/3 in optical depths), written straight into level 0 of the MIP chains that
// fog_downsample.wgsl reduces. One thread per pixel. The CPU twin is effects::image_fog::prepare
// (medium.rs: FogComponent::density_integral, PixelFog::weights, spread_angle, spread_px) and the
// level-0 set-up of gpu::fog (clamp_spread, the (Y·W, Y, W) chain).
//
// f32 with the CPU's stable forms: Eq. 4 as ρ' e^{max(a₀, a₁)} D φ(|bDμ|) with φ(y) = −expm1(−y)/y
// (expm1 by its Taylor series near 0, as WGSL has none), re-formed in log space when the direct
// product is not a normal f32; 1 − e^{−τ_s} as −expm1(−τ_s). WGSL may assume no infinities, so an
// infinite density integral or optical depth is carried as F32_MAX (whose exponential is still 0),
// and sky pixels (D = ∞) arrive as D < 0. The per-camera constants (the height h₀ of the eye above
// each component's offset, a₀ = −b h₀, ln ρ', the channel means) come from the host in f64 then
// rounded, so a far-away camera loses no precision in h₀.
//
// Bindings (group 0):
//   0  params      uniform  IntegralParams
//   1  comps       storage  array<Component> [components]  read
//   2  colour      storage  array<vec4<f32>> [pixels]      read: L (xyz), sanitised to [0, F32_MAX]
//   3  distance    storage  array<f32> [pixels]            read: D [m], < 0 for ∞, 0 for none
//   4  attenuated  storage  array<vec4<f32>> [pixels]      read_write: L_at (xyz)
//   5  rgb         storage  array<vec4<f32>> [chain]       read_write: level 0 = L_sc (xyz)
//   6  spread      storage  array<vec4<f32>> [chain]       read_write: level 0 = (Y·W, Y, W), W clamped
//   7  width       storage  array<f32> [pixels]            read_write: W [pixels] before clamping

struct IntegralParams {
    fwd: vec4<f32>,   // xyz camera forward, w tan(yfov/2)
    right: vec4<f32>, // xyz camera right, w aspect (width/height)
    up: vec4<f32>,    // xyz camera up, w focal length [pixels]
    n: vec4<u32>,     // x width, y height, z pixels, w components
    m: vec4<f32>,     // x spread cap 2·sqrt(V_K), y 1 luminance-weighted spread chain (0 Gaussian), z 1 no spreading, w 0
}

struct Component {
    sigma_s: vec4<f32>, // xyz σ_s [1/m], w mean σ_s·max(1 − g, 0)
    sigma_a: vec4<f32>, // xyz σ_a [1/m], w mean σ_a
    axis: vec4<f32>,    // xyz unit height axis n, w kind: 0 P = ρ'·D, 1 exponential height, 2 P = 0, 3 P = ∞ for D > 0
    expo: vec4<f32>,    // x a₀ = −b·h₀, y falloff b, z ln ρ', w ρ' (kind 0: the density scale)
}

@group(0) @binding(0) var<uniform> params: IntegralParams;
@group(0) @binding(1) var<storage, read> comps: array<Component>;
@group(0) @binding(2) var<storage, read> colour: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> distance: array<f32>;
@group(0) @binding(4) var<storage, read_write> attenuated: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> rgb: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> spread: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> width: array<f32>;

const F32_MAX: f32 = 3.40282347e38;
const F32_MIN_NORMAL: f32 = 1.17549435e-38;

// x saturated at F32_MAX (an overflow to +∞ becomes F32_MAX).
fn sat(x: f32) -> f32 {
    return select(F32_MAX, x, x <= F32_MAX);
}

// e^x − 1 without cancellation near 0: the Taylor series to x⁸ for |x| < 1/2 (truncation below
// 3e-9 relative), e^x − 1 beyond (cancellation below 3 ulp there). Kahan's (u − 1)·x/ln u would
// need a logarithm accurate to an ulp next to 1, which lavapipe's is not (measured: wrong by
// orders of magnitude at x = −1e-13).
fn expm1(x: f32) -> f32 {
    if abs(x) < 0.5 {
        let p = 1.0 / 5040.0 + x * (1.0 / 40320.0);
        let q = 1.0 / 120.0 + x * (1.0 / 720.0 + x * p);
        return x * (1.0 + x * (0.5 + x * (1.0 / 6.0 + x * (1.0 / 24.0 + x * q))));
    }
    return exp(x) - 1.0;
}

// `direct` when it is a normal f32, else e^lg (the same value formed in log space), saturated.
fn from_log(lg: f32, direct: f32) -> f32 {
    if direct >= F32_MIN_NORMAL && direct <= F32_MAX {
        return direct;
    }
    return sat(exp(min(lg, 89.0)));
}

// Eq. 4, ∫₀ᴰ ρ' e^{a₀ − b μ t} dt, for a unit ray with height-axis cosine μ (D < 0: ∞).
fn exponential_integral(c: Component, mu: f32, d: f32) -> f32 {
    let a0 = c.expo.x;
    let k = c.expo.y * mu; // decay rate of the log-density along the ray [1/m]
    if d < 0.0 {
        if k > 0.0 {
            return from_log(c.expo.z + a0 - log(k), c.expo.w * exp(a0) / k);
        }
        return F32_MAX;
    }
    let x = k * d;
    let amax = max(a0, a0 - x);
    let y = abs(x);
    // D·φ(y) directly for y < 1; (1 − e^{−y})/|k| for y ≥ 1 (D/y would lose D when y overflows).
    var factor = d;
    if y >= 1.0 {
        factor = -expm1(-y) / abs(k);
    } else if y > 0.0 {
        factor = d * (-expm1(-y) / y);
    }
    return from_log(c.expo.z + amax + log(factor), c.expo.w * exp(amax) * factor);
}

// P of component c along direction dir to distance d (D < 0: ∞, D = 0: no path).
fn density_integral(c: Component, dir: vec3<f32>, d: f32) -> f32 {
    if d == 0.0 {
        return 0.0;
    }
    let kind = u32(c.axis.w);
    if kind == 2u {
        return 0.0;
    }
    if kind == 3u {
        return F32_MAX;
    }
    if kind == 0u {
        if d < 0.0 {
            return F32_MAX;
        }
        return sat(c.expo.w * d);
    }
    return exponential_integral(c, dot(dir, c.axis.xyz), d);
}

// k·P saturated, 0 for k = 0 whatever P (no 0·∞), and ∞ (F32_MAX) for P = ∞ whatever k > 0.
fn depth(k: f32, p: f32) -> f32 {
    if k == 0.0 {
        return 0.0;
    }
    if p >= F32_MAX {
        return F32_MAX;
    }
    return sat(k * p);
}

// W/s of Eq. 1 from the absorption depth u and the reduced scattering depth v (spread_angle).
fn spread_angle(u: f32, v: f32) -> f32 {
    if v <= 0.0 {
        return 0.0;
    }
    if v >= F32_MAX {
        if u <= 0.0 {
            return F32_MAX;
        }
        return sqrt(0.75 / u);
    }
    return sqrt(1.0 / (4.0 * u / 3.0 + 8.0 / v));
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = (wid.x + wid.y * nwg.x) * 64u + lid;
    if i >= params.n.z {
        return;
    }
    let w = params.n.x;
    let h = params.n.y;
    // ViewCamera::pixel_dir.
    let sx = (2.0 * (f32(i % w) + 0.5) / f32(w) - 1.0) * params.fwd.w * params.right.w;
    let sy = (1.0 - 2.0 * (f32(i / w) + 0.5) / f32(h)) * params.fwd.w;
    let dir = normalize(params.fwd.xyz + sx * params.right.xyz + sy * params.up.xyz);
    let d = distance[i];
    var tau_a = vec3<f32>(0.0);
    var tau_s = vec3<f32>(0.0);
    var reduced = 0.0;
    var absorb = 0.0;
    for (var k = 0u; k < params.n.w; k++) {
        let c = comps[k];
        let p = density_integral(c, dir, d);
        if p == 0.0 {
            continue;
        }
        tau_a = vec3<f32>(sat(tau_a.x + depth(c.sigma_a.x, p)), sat(tau_a.y + depth(c.sigma_a.y, p)), sat(tau_a.z + depth(c.sigma_a.z, p)));
        tau_s = vec3<f32>(sat(tau_s.x + depth(c.sigma_s.x, p)), sat(tau_s.y + depth(c.sigma_s.y, p)), sat(tau_s.z + depth(c.sigma_s.z, p)));
        reduced = sat(reduced + depth(c.sigma_s.w, p));
        absorb = sat(absorb + depth(c.sigma_a.w, p));
    }
    let ea = exp(-tau_a);
    let t = ea * exp(-tau_s);
    let s = ea * -vec3<f32>(expm1(-tau_s.x), expm1(-tau_s.y), expm1(-tau_s.z));
    let l = colour[i].xyz;
    attenuated[i] = vec4<f32>(t * l, 0.0);
    let lsc = s * l;
    rgb[i] = vec4<f32>(lsc, 0.0);
    let wpx = max(sat(params.up.w * spread_angle(absorb, reduced)), 0.0);
    width[i] = wpx;
    var ws = clamp(wpx, 0.0, params.m.x);
    if params.m.z > 0.5 {
        ws = 0.0;
    }
    var y = 1.0;
    if params.m.y > 0.5 {
        y = max(0.2126 * lsc.x + 0.7152 * lsc.y + 0.0722 * lsc.z, 0.0);
    }
    spread[i] = vec4<f32>(y * ws, y, ws, 0.0);
}
