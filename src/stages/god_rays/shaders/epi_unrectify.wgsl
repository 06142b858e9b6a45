// Epipolar god rays, pass 4: unrectification back to pixels and the view transmittance (baran2010
// Sec. 3), with ray marching of the pixels around the epipole (Sec. 6) and of silhouette pixels no
// slice sample matches. One thread per pixel. CPU twin: step 4 of effects::epipolar::render,
// rectify::Setup::unrectify and reference::MarchCtx::pixel (shadow-map visibility, the same
// counter-based jitter: SplitMix64 on u32 pairs). Prepend epi_common.wgsl.
//
// Bindings (group 0), besides epi_common's P (0), shadow (1), tex (2):
//   3  angles  storage  array<f32> [slices]          read: screen angle of each slice (sorted)
//   4  offs    storage  array<u32> [slices + 1]     read: first sample of each slice
//   5  depth   storage  array<f32> [w·h]            read: camera distance, < 0 = nothing hit
//   6  betas   storage  array<f32> [samples]        read: β (pass 1)
//   7  gend    storage  array<f32> [samples]        read: γ_end (pass 1)
//   8  values  storage  array<vec4<f32>> [samples]  read: in-scatter per sample (pass 3)
//   9  inscat  storage  array<vec4<f32>> [w·h]      write: in-scatter (xyz)
//  10  trans   storage  array<vec4<f32>> [w·h]      write: view transmittance (xyz)
//  11  counts  storage  array<atomic<u32>> [2]      read_write: pixels marched in the ring, elsewhere

@group(0) @binding(3) var<storage, read> angles: array<f32>;
@group(0) @binding(4) var<storage, read> offs: array<u32>;
@group(0) @binding(5) var<storage, read> depth: array<f32>;
@group(0) @binding(6) var<storage, read> betas: array<f32>;
@group(0) @binding(7) var<storage, read> gend: array<f32>;
@group(0) @binding(8) var<storage, read> values: array<vec4<f32>>;
@group(0) @binding(9) var<storage, read_write> inscat: array<vec4<f32>>;
@group(0) @binding(10) var<storage, read_write> trans: array<vec4<f32>>;
@group(0) @binding(11) var<storage, read_write> counts: array<atomic<u32>>;

// 64-bit words as (lo, hi) u32 pairs, for the SplitMix64 finaliser of physics::rng.
fn mul_wide(a: u32, b: u32) -> vec2<u32> {
    let a0 = a & 0xffffu;
    let a1 = a >> 16u;
    let b0 = b & 0xffffu;
    let b1 = b >> 16u;
    let p00 = a0 * b0;
    let p01 = a0 * b1;
    let p10 = a1 * b0;
    let mid = (p00 >> 16u) + (p01 & 0xffffu) + (p10 & 0xffffu);
    return vec2<u32>((p00 & 0xffffu) | (mid << 16u), a1 * b1 + (p01 >> 16u) + (p10 >> 16u) + (mid >> 16u));
}

fn mul64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    let lo = mul_wide(a.x, b.x);
    return vec2<u32>(lo.x, lo.y + a.x * b.y + a.y * b.x);
}

fn add64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    let lo = a.x + b.x;
    return vec2<u32>(lo, a.y + b.y + select(0u, 1u, lo < a.x));
}

// z ^ (z >> s) for 0 < s < 32.
fn xorshift64(z: vec2<u32>, s: u32) -> vec2<u32> {
    return vec2<u32>(z.x ^ ((z.x >> s) | (z.y << (32u - s))), z.y ^ (z.y >> s));
}

fn mix64(z0: vec2<u32>) -> vec2<u32> {
    var z = add64(z0, vec2<u32>(0x7f4a7c15u, 0x9e3779b9u));
    z = mul64(xorshift64(z, 30u), vec2<u32>(0x1ce4e5b9u, 0xbf58476du));
    z = mul64(xorshift64(z, 27u), vec2<u32>(0x133111ebu, 0x94d049bbu));
    return xorshift64(z, 31u);
}

// StreamKey { table: JITTER_TABLE, cell }.uniform(k, 0), to f32 (the top 24 of its 53 bits).
fn jitter(cell: u32, k: u32) -> f32 {
    let h1 = mix64(vec2<u32>(P.n3.z ^ cell, P.n3.w));
    // k.rotate_left(17) for k < 2^32: (k << 17) across the two words.
    let h = mix64(vec2<u32>(h1.x ^ (k << 17u), h1.y ^ (k >> 15u)));
    return f32(h.y >> 8u) * (1.0 / 16777216.0);
}

// σ_s p(μ) L_in(x) toward the eye along v (unshadowed).
fn incident(x: vec3<f32>, v: vec3<f32>) -> vec3<f32> {
    let m = modulation(x);
    let str = max(P.light_str.xyz, vec3<f32>(0.0));
    if !is_spot() {
        let hs = sin(0.5 * angle_between(v, P.geo_t.xyz));
        return P.sigma_s.xyz * phase_omm(2.0 * hs * hs) * str * m;
    }
    let wv = x - P.geo_pos.xyz;
    let r = length(wv);
    if r <= 1e-12 {
        return vec3<f32>(0.0);
    }
    let hs = sin(0.5 * angle_between(v, -wv));
    return P.sigma_s.xyz * phase_omm(2.0 * hs * hs) * str * m * exp(-P.sigma_t.xyz * r) / (r * r);
}

fn march(cell: u32, v: vec3<f32>, d: f32) -> vec3<f32> {
    let n = max(P.n1.z, 1u);
    if d <= 0.0 {
        return vec3<f32>(0.0);
    }
    let dt = d / f32(n);
    var acc = vec3<f32>(0.0);
    for (var k = 0u; k < n; k++) {
        let a = f32(k) * dt;
        let b = select(a + dt, d, k + 1u == n);
        let t = a + jitter(cell, k) * (b - a);
        let p = P.cam_pos.xyz + t * v;
        let inc = incident(p, v);
        if all(inc <= vec3<f32>(0.0)) || !lit(p) {
            continue;
        }
        acc += inc * vec3<f32>(exp_integral(P.sigma_t.x, a, b), exp_integral(P.sigma_t.y, a, b), exp_integral(P.sigma_t.z, a, b));
    }
    return select(vec3<f32>(0.0), acc, (acc > vec3<f32>(0.0)) & (acc < vec3<f32>(3.0e38)));
}

// Setup::unrectify: x 1 when a depth-matching sample exists, yzw the blended in-scatter.
fn unrectify(px: f32, py: f32, v: vec3<f32>, extent: f32) -> vec4<f32> {
    let n = P.n0.x;
    let dx = px - P.epi.x;
    let dy = py - P.epi.y;
    let len = sqrt(dx * dx + dy * dy);
    var th = 0.0;
    if len > 0.0 {
        let r = P.epi.zw;
        let d = vec2<f32>(dx, dy) / len;
        th = atan2(r.x * d.y - r.y * d.x, r.x * d.x + r.y * d.y);
    }
    // k = number of slices with angle ≤ th.
    var lo_b = 0u;
    var hi_b = n;
    while lo_b < hi_b {
        let mid = (lo_b + hi_b) / 2u;
        if angles[mid] <= th {
            lo_b = mid + 1u;
        } else {
            hi_b = mid;
        }
    }
    let k = lo_b;
    var s0 = 0u;
    var s1 = 0u;
    var wgt = 0.0;
    if P.misc.w > 0.5 {
        s0 = (k + n - 1u) % n;
        s1 = k % n;
        let tau = 2.0 * PI;
        let span = angles[s1] - angles[s0];
        let span_m = span - tau * floor(span / tau);
        let o = th - angles[s0];
        let off_m = o - tau * floor(o / tau);
        if span_m > 0.0 {
            wgt = clamp(off_m / span_m, 0.0, 1.0);
        }
    } else if k >= n {
        s0 = n - 1u;
        s1 = n - 1u;
    } else if k > 0u {
        s0 = k - 1u;
        s1 = k;
        let span = angles[k] - angles[k - 1u];
        if span > 0.0 {
            wgt = clamp((th - angles[k - 1u]) / span, 0.0, 1.0);
        }
    }
    let beta = angle_between(v, P.geo_t.xyz);
    let gp = gamma_end(v, beta, extent);
    let dg = P.sigma_t.w;
    var acc = vec3<f32>(0.0);
    var wsum = 0.0;
    for (var side = 0u; side < 2u; side++) {
        let si = select(s0, s1, side == 1u);
        let ws = select(1.0 - wgt, wgt, side == 1u);
        let off = offs[si];
        let m = offs[si + 1u] - off;
        if m == 0u {
            continue;
        }
        let b0 = betas[off];
        let b1 = betas[off + m - 1u];
        var pos = 0.0;
        if b1 > b0 {
            pos = clamp((beta - b0) / (b1 - b0) * f32(m - 1u), 0.0, f32(m - 1u));
        }
        let i = min(u32(floor(pos)), m - 1u);
        let j = min(i + 1u, m - 1u);
        let f = pos - f32(i);
        for (var e = 0u; e < 2u; e++) {
            let idx = select(i, j, e == 1u);
            let wb = select(1.0 - f, f, e == 1u);
            let g = gend[off + idx];
            if abs(g - gp) > 0.05 * max(g, gp) + 2.0 * dg {
                continue;
            }
            let w = ws * wb + 1e-6;
            acc += w * values[off + idx].xyz;
            wsum += w;
        }
    }
    if wsum > 0.0 {
        return vec4<f32>(1.0, acc / wsum);
    }
    return vec4<f32>(0.0);
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = thread_index(wid, nwg, lid);
    let w = u32(P.cam_right.w);
    let h = u32(P.cam_up.w);
    if i >= w * h {
        return;
    }
    let x = i % w;
    let y = i / w;
    let px = f32(x) + 0.5;
    let py = f32(y) + 0.5;
    let v = ray_dir(px, py);
    let d = view_extent(v, depth[i]);
    trans[i] = vec4<f32>(exp(-P.sigma_t.xyz * d), 0.0);
    let ring = P.n0.x == 0u || length(vec2<f32>(px - P.epi.x, py - P.epi.y)) < P.misc.x;
    var r = vec4<f32>(0.0);
    if !ring {
        r = unrectify(px, py, v, d);
    }
    if r.x > 0.5 {
        inscat[i] = vec4<f32>(r.yzw, 0.0);
        return;
    }
    atomicAdd(&counts[select(1u, 0u, ring)], 1u);
    inscat[i] = vec4<f32>(march(i, v, d), 0.0);
}
