// Epipolar god rays (baran2010): the declarations every epipolar pass shares. The Rust side prepends
// this file to each epi_*.wgsl pass (WGSL has no include), so a pass lifted into an engine is this
// file followed by the pass file. The CPU twins are in effects::epipolar (rectify.rs, integrate.rs,
// shadow_map.rs, reference.rs, mod.rs); names follow them.
//
// Bindings (group 0) shared by the passes (a pass binds only those it uses):
//   0  P        uniform  EpiParams                  camera, light, shadow frame, medium, sizes
//   1  shadow   storage  array<f32> [res²]  read    blocker depth per texel, < 0 where nothing is hit
//   2  tex      storage  array<vec4<f32>> [tw·th] read   light texture (rgb), one texel when absent
//
// Conventions: depths and distances < 0 stand for "infinite" (WGSL may assume no infinities);
// f32 throughout.

struct EpiParams {
    cam_pos: vec4<f32>,   // xyz eye, w tan(yfov/2)
    cam_fwd: vec4<f32>,   // xyz forward, w aspect (width/height)
    cam_right: vec4<f32>, // xyz right, w width (px)
    cam_up: vec4<f32>,    // xyz up, w height (px)
    geo_t: vec4<f32>,     // xyz unit direction from the eye to the light, w kind (0 directional, 1 spot)
    geo_pos: vec4<f32>,   // xyz spot position, w eye–spot distance
    light_dir: vec4<f32>, // xyz spot cone axis, w 1/max(cos(inner) − cos(outer), 1e-3) (render::spot)
    light_str: vec4<f32>, // xyz irradiance (directional) or intensity (spot), w cos(outer cone)
    fr_origin: vec4<f32>, // shadow frame: xyz window corner (ortho) or light position (persp), w kind (0 ortho, 1 persp)
    fr_u: vec4<f32>,      // xyz ax_u (ortho) or right (persp), w extent_u (ortho) or tan_half (persp)
    fr_v: vec4<f32>,      // xyz ax_v or up, w extent_v
    fr_dir: vec4<f32>,    // xyz light travel direction (ortho) or forward (persp), w depth bias
    bmin: vec4<f32>,      // xyz medium region min, w shadow-map resolution
    bmax: vec4<f32>,      // xyz medium region max, w 1 when the light is textured
    sigma_s: vec4<f32>,   // xyz scattering, w HG g (clamped to ±0.999)
    sigma_t: vec4<f32>,   // xyz extinction, w Δγ (bin width)
    epi: vec4<f32>,       // xy epipole (raster), zw reference screen direction
    misc: vec4<f32>,      // x ring radius (px), y ln tan(β_lo/2), z ln tan(β_hi/2), w 1 when the epipole is inside
    n0: vec4<u32>,        // x slices, y γ bins, z SVD rank, w kernels (1 grey, 3 per channel)
    n1: vec4<u32>,        // x sub-samples per bin (1 or 4), y max depth modes, z ring steps, w channels in the tree
    n2: vec4<u32>,        // x texture width, y texture height, z first slice of this chunk, w β samples in all
    n3: vec4<u32>,        // x slices in this chunk, y 0 (unused), z jitter key lo, w jitter key hi
    n4: vec4<u32>,        // x most β samples in one slice, y β samples per integration block, z blocks per slice, w 0
}

@group(0) @binding(0) var<uniform> P: EpiParams;
@group(0) @binding(1) var<storage, read> shadow: array<f32>;
@group(0) @binding(2) var<storage, read> tex: array<vec4<f32>>;

const PI: f32 = 3.14159265358979;
const BETA_NODES: u32 = 64u;
const NONE: u32 = 0xffffffffu;

fn thread_index(wid: vec3<u32>, nwg: vec3<u32>, lid: u32) -> u32 {
    return (wid.x + wid.y * nwg.x) * 64u + lid;
}

fn is_spot() -> bool {
    return P.geo_t.w > 0.5;
}

// Angle between vectors without acos's precision loss near 0 and π (rectify::angle).
fn angle_between(a: vec3<f32>, b: vec3<f32>) -> f32 {
    return atan2(length(cross(a, b)), dot(a, b));
}

// ViewCamera::ray_dir at raster position (x, y).
fn ray_dir(x: f32, y: f32) -> vec3<f32> {
    let sx = (2.0 * x / P.cam_right.w - 1.0) * P.cam_pos.w * P.cam_fwd.w;
    let sy = (1.0 - 2.0 * y / P.cam_up.w) * P.cam_pos.w;
    return normalize(P.cam_fwd.xyz + sx * P.cam_right.xyz + sy * P.cam_up.xyz);
}

// ViewCamera::project_dir: xy raster position, z 1 when in front, w 0 when at infinity.
fn project_dir(d: vec3<f32>) -> vec4<f32> {
    let z = dot(d, P.cam_fwd.xyz);
    if abs(z) < 1e-12 * length(d) {
        return vec4<f32>(0.0);
    }
    let sx = dot(d, P.cam_right.xyz) / z / (P.cam_pos.w * P.cam_fwd.w);
    let sy = dot(d, P.cam_up.xyz) / z / P.cam_pos.w;
    return vec4<f32>((sx + 1.0) * 0.5 * P.cam_right.w, (1.0 - sy) * 0.5 * P.cam_up.w, select(0.0, 1.0, z > 0.0), 1.0);
}

// The parameter interval (lo, hi) of the line o + t·d inside the medium region; lo > hi when it misses
// (god_rays::clip_line).
fn clip_region(o: vec3<f32>, d: vec3<f32>) -> vec2<f32> {
    var t0 = -3.0e38;
    var t1 = 3.0e38;
    for (var a = 0u; a < 3u; a++) {
        let v = d[a];
        if abs(v) < 1e-30 {
            if o[a] < P.bmin[a] || o[a] > P.bmax[a] {
                return vec2<f32>(1.0, -1.0);
            }
            continue;
        }
        let ta = (P.bmin[a] - o[a]) / v;
        let tb = (P.bmax[a] - o[a]) / v;
        t0 = max(t0, min(ta, tb));
        t1 = min(t1, max(ta, tb));
    }
    return vec2<f32>(t0, t1);
}

// god_rays::view_segment's end for an eye inside the region: the ray's depth (< 0: none) or where it
// leaves the region, whichever comes first.
fn view_extent(dir: vec3<f32>, depth: f32) -> f32 {
    let c = clip_region(P.cam_pos.xyz, dir);
    if c.y < c.x || c.y <= 0.0 {
        return 0.0;
    }
    if depth >= 0.0 {
        return min(depth, c.y);
    }
    return c.y;
}

// Geo::gamma_end: γ where the view ray v (angle beta) of length d ends.
fn gamma_end(v: vec3<f32>, beta: f32, d: f32) -> f32 {
    if !is_spot() {
        return d * sin(beta);
    }
    if d <= 0.0 {
        return 0.0;
    }
    let p = P.cam_pos.xyz + d * v;
    return angle_between(p - P.geo_pos.xyz, P.cam_pos.xyz - P.geo_pos.xyz);
}

// LightFrame::uv_depth without the window check: xy window coordinates, z depth, w 0 behind a spot.
fn frame_uvz(p: vec3<f32>) -> vec4<f32> {
    let q = p - P.fr_origin.xyz;
    if P.fr_origin.w < 0.5 {
        return vec4<f32>(dot(q, P.fr_u.xyz) / P.fr_u.w, dot(q, P.fr_v.xyz) / P.fr_v.w, dot(q, P.fr_dir.xyz), 1.0);
    }
    let z = dot(q, P.fr_dir.xyz);
    if z <= 0.0 {
        return vec4<f32>(0.0);
    }
    let th = P.fr_u.w;
    let sx = dot(q, P.fr_u.xyz) / (z * th);
    let sy = dot(q, P.fr_v.xyz) / (z * th);
    return vec4<f32>((sx + 1.0) * 0.5, (1.0 - sy) * 0.5, length(q), 1.0);
}

// ShadowMap::blocker_and_depth: x 1 when p falls in the window, y the texel's blocker depth (< 0: none),
// z p's own depth.
fn blocker_and_depth(p: vec3<f32>) -> vec3<f32> {
    let f = frame_uvz(p);
    if f.w < 0.5 || f.x < 0.0 || f.x >= 1.0 || f.y < 0.0 || f.y >= 1.0 {
        return vec3<f32>(0.0, -1.0, 0.0);
    }
    let n = u32(P.bmin.w);
    let i = min(u32(f.x * f32(n)), n - 1u);
    let j = min(u32(f.y * f32(n)), n - 1u);
    return vec3<f32>(1.0, shadow[j * n + i], f.z);
}

// ShadowMap::lit: outside the window lit, else depth < blocker + bias (no blocker: lit).
fn lit(p: vec3<f32>) -> bool {
    let b = blocker_and_depth(p);
    return b.x < 0.5 || b.y < 0.0 || b.z < b.y + P.fr_dir.w;
}

// god_rays::modulation: texture × spot falloff at p, times for a directional light its attenuation
// e^{−σ_t a} from where its ray through p enters the medium region (EpiMedium::light_entry; 0 when the
// ray misses the region).
fn modulation(p: vec3<f32>) -> vec3<f32> {
    var fall = vec3<f32>(1.0);
    if is_spot() {
        let r = p - P.geo_pos.xyz;
        let len = length(r);
        if len <= 0.0 {
            return vec3<f32>(0.0);
        }
        let t = clamp((dot(r / len, P.light_dir.xyz) - P.light_str.w) * P.light_dir.w, 0.0, 1.0);
        fall = vec3<f32>(t * t);
    } else {
        let c = clip_region(p, P.geo_t.xyz);
        if c.y < c.x {
            return vec3<f32>(0.0);
        }
        fall = exp(-P.sigma_t.xyz * c.y);
    }
    if all(fall <= vec3<f32>(0.0)) {
        return vec3<f32>(0.0);
    }
    if P.bmax.w < 0.5 {
        return fall;
    }
    let f = frame_uvz(p);
    if f.w < 0.5 {
        return vec3<f32>(0.0);
    }
    let tw = P.n2.x;
    let th = P.n2.y;
    let x = min(u32(clamp(floor(f.x * f32(tw)), 0.0, f32(tw - 1u))), tw - 1u);
    let y = min(u32(clamp(floor(f.y * f32(th)), 0.0, f32(th - 1u))), th - 1u);
    return tex[y * tw + x].xyz * fall;
}

// HG phase from 1 − μ (no cancellation near μ = 1), g = P.sigma_s.w.
fn phase_omm(omm: f32) -> f32 {
    let g = P.sigma_s.w;
    let s2 = (1.0 - g) * (1.0 - g) + 2.0 * g * clamp(omm, 0.0, 2.0);
    return (1.0 - g) * (1.0 + g) / (4.0 * PI * s2 * sqrt(s2));
}

// ∫_a^b e^{−σ t} dt without cancellation (effects::epipolar::exp_integral).
fn exp_integral(sigma: f32, a: f32, b: f32) -> f32 {
    let w = b - a;
    if w <= 0.0 {
        return 0.0;
    }
    let x = sigma * w;
    if x < 1e-4 {
        // −expm1(−x)/σ = w(1 − x/2 + x²/6) to f32 precision.
        return exp(-sigma * a) * w * (1.0 - x * (0.5 - x / 6.0));
    }
    return exp(-sigma * a) * (1.0 - exp(-x)) / sigma;
}
