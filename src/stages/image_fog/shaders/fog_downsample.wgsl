// Image-space fog: one MIP level of the scattered-light chain and of the spread chain (iser2018
// Secs. 4.2-4.3): L^[k] = (M^[k] . L^[k-1]) * G and W^[k] = W^[k-1] * G, down-sampled by 2 with the
// separable 4-tap kernel G = {0.13, 0.37, 0.37, 0.13} and clamp-to-edge borders. The mask
// M^[k] = smoothstep(sigma_{k-1}/(1+eps), sigma_{k-1}, W^[k-1]) is evaluated per source texel. One
// thread per level-k texel; the rows are combined in the CPU's order (each of the 4 rows weighted
// horizontally, then the rows vertically). The CPU twin is effects::image_fog::filter::build_chain.
//
// All levels live in one buffer each; level k starts at params.dst_offset, level k-1 at src_offset.
//
// Bindings (group 0):
//   0  params  uniform  DownParams
//   1  rgb     storage  array<vec4<f32>>  [chain texels]  read_write: L^[k] (xyz)
//   2  spread  storage  array<vec4<f32>>  [chain texels]  read_write: (Y.W, Y, W) chains (xyz)

struct DownParams {
    src_offset: u32,
    dst_offset: u32,
    src_w: u32,
    src_h: u32,
    dst_w: u32,
    count: u32,   // dst_w * dst_h
    masking: u32, // 1: mask the colour (masking on and sigma_{k-1} > 0)
    _pad: u32,
    lo: f32,      // sigma_{k-1} / (1 + eps)
    hi: f32,      // sigma_{k-1}
    _pad1: f32,
    _pad2: f32,
}

@group(0) @binding(0) var<uniform> params: DownParams;
@group(0) @binding(1) var<storage, read_write> rgb: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> spread: array<vec4<f32>>;

const TAPS = array<f32, 4>(0.13, 0.37, 0.37, 0.13);

// W from a spread-chain texel (Y.W, Y, W): the luminance-weighted mean, or the plain mean where no
// light is (filter::spread_of). The finiteness test reads the exponent bits (no reliance on Inf).
fn spread_of(v: vec3<f32>) -> f32 {
    if v.y > 0.0 {
        let q = v.x / v.y;
        if ((bitcast<u32>(q) >> 23u) & 0xffu) != 0xffu {
            return q;
        }
    }
    return v.z;
}

fn mask_step(e0: f32, e1: f32, x: f32) -> f32 {
    if e1 <= e0 {
        return select(0.0, 1.0, x >= e1);
    }
    let t = clamp((x - e0) / (e1 - e0), 0.0, 1.0);
    return t * t * (3.0 - 2.0 * t);
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let n = (wid.x + wid.y * nwg.x) * 64u + lid;
    if n >= params.count {
        return;
    }
    let i = i32(n % params.dst_w);
    let j = i32(n / params.dst_w);
    let w = i32(params.src_w);
    let h = i32(params.src_h);
    var acc_c = vec3<f32>(0.0);
    var acc_s = vec3<f32>(0.0);
    for (var t = 0; t < 4; t++) {
        let sy = clamp(2 * j - 1 + t, 0, h - 1);
        var row_c = vec3<f32>(0.0);
        var row_s = vec3<f32>(0.0);
        for (var u = 0; u < 4; u++) {
            let sx = clamp(2 * i - 1 + u, 0, w - 1);
            let idx = params.src_offset + u32(sy * w + sx);
            let s = spread[idx].xyz;
            var c = rgb[idx].xyz;
            if params.masking == 1u {
                c = c * mask_step(params.lo, params.hi, spread_of(s));
            }
            row_c += TAPS[u] * c;
            row_s += TAPS[u] * s;
        }
        acc_c += TAPS[t] * row_c;
        acc_s += TAPS[t] * row_s;
    }
    rgb[params.dst_offset + n] = vec4<f32>(acc_c, 0.0);
    spread[params.dst_offset + n] = vec4<f32>(acc_s, 0.0);
}
