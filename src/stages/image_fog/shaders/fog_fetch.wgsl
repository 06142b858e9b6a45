// Image-space fog: per-pixel fetch from the MIP chains (iser2018 Secs. 4.2-4.3). Level selection from
// the pixel's spread W (variance-matched blend of the two levels whose blur variances bracket W^2, or
// the paper's k = clamp(log2(W/c), 0, K)), re-selection from the spread chain read at that level
// (blur_level: k' = k(W^[k(W)])), cubic B-spline reconstruction within a level and linear blending
// between levels. One thread per level-0 pixel. The CPU twin is effects::image_fog::filter::fetch
// (with spread_level = None).
//
// Bindings (group 0):
//   0  params     uniform  FetchParams
//   1  levels     storage  array<Level>      [K + 1]        offset, size and blur variance per level
//   2  rgb        storage  array<vec4<f32>>  [chain texels] read: L^[0..K] (xyz)
//   3  spread     storage  array<vec4<f32>>  [chain texels] read: (Y.W, Y, W) chains (xyz)
//   4  scattered  storage  array<vec4<f32>>  [pixels]       read_write: L'_sc (xyz)
//   5  level      storage  array<f32>        [pixels]       read_write: fractional level read

struct FetchParams {
    width: u32,
    height: u32,
    count: u32,
    k_max: u32,
    blur_level: u32,
    paper: u32, // 1: LevelRule::Paper, 0: LevelRule::VarianceMatched
    c: f32,
    _pad: u32,
}

struct Level {
    offset: u32,
    width: u32,
    height: u32,
    variance: f32, // V_k [pixels^2]
}

@group(0) @binding(0) var<uniform> params: FetchParams;
@group(0) @binding(1) var<storage, read> levels: array<Level>;
@group(0) @binding(2) var<storage, read> rgb: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> spread: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> scattered: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> level: array<f32>;

fn spread_of(v: vec3<f32>) -> f32 {
    if v.y > 0.0 {
        let q = v.x / v.y;
        if ((bitcast<u32>(q) >> 23u) & 0xffu) != 0xffu {
            return q;
        }
    }
    return v.z;
}

// (a, f): read level a with weight 1 - f and a + 1 with weight f (filter::select_level).
fn select_level(w_in: f32) -> vec2<f32> {
    let k_max = params.k_max;
    let w = max(w_in, 0.0);
    if !(w > 0.0) || k_max == 0u {
        return vec2<f32>(0.0, 0.0);
    }
    if params.paper == 1u {
        let l = clamp(log2(w / params.c), 0.0, f32(k_max));
        let a = min(u32(floor(l)), k_max);
        return vec2<f32>(f32(a), select(l - f32(a), 0.0, a == k_max));
    }
    let w2 = w * w;
    if w2 >= levels[k_max].variance {
        return vec2<f32>(f32(k_max), 0.0);
    }
    var a = 0u;
    for (var k = 1u; k <= k_max; k++) {
        if levels[k].variance <= w2 {
            a = k;
        }
    }
    let va = levels[a].variance;
    return vec2<f32>(f32(a), (w2 - va) / (levels[a + 1u].variance - va));
}

// Per-axis cubic B-spline taps of output coordinate x at level k: 4 clamped indices and weights.
struct Taps {
    idx: vec4<i32>,
    wt: vec4<f32>,
}

fn taps(x: u32, n_level: u32, k: u32) -> Taps {
    let u = (f32(x) + 0.5) / f32(1u << k) - 0.5;
    let fi = floor(u);
    let t = u - fi;
    let i = i32(fi);
    let t2 = t * t;
    let t3 = t2 * t;
    let w0 = (1.0 - t) * (1.0 - t) * (1.0 - t) / 6.0;
    let w1 = (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0;
    let w2 = (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0;
    let w3 = t3 / 6.0;
    let hi = i32(n_level) - 1;
    let idx = vec4<i32>(clamp(i - 1, 0, hi), clamp(i, 0, hi), clamp(i + 1, 0, hi), clamp(i + 2, 0, hi));
    return Taps(idx, vec4<f32>(w0, w1, w2, w3));
}

// Reads level k (k >= 1) of the colour chain (which = 0) or the spread chain (which = 1) at pixel
// (x, y): rows weighted horizontally, then combined vertically, zero-weight rows skipped (filter::sample).
fn sample_level(which: u32, k: u32, x: u32, y: u32) -> vec3<f32> {
    let lv = levels[k];
    let tx = taps(x, lv.width, k);
    let ty = taps(y, lv.height, k);
    var acc = vec3<f32>(0.0);
    for (var j = 0; j < 4; j++) {
        let yw = ty.wt[j];
        if yw == 0.0 {
            continue;
        }
        let row = lv.offset + u32(ty.idx[j]) * lv.width;
        var r = vec3<f32>(0.0);
        for (var i = 0; i < 4; i++) {
            let idx = row + u32(tx.idx[i]);
            var v: vec3<f32>;
            if which == 0u { v = rgb[idx].xyz; } else { v = spread[idx].xyz; }
            r += tx.wt[i] * v;
        }
        acc += yw * r;
    }
    return acc;
}

fn read_spread(k: u32, x: u32, y: u32, n: u32) -> f32 {
    if k == 0u {
        return spread[n].z;
    }
    return spread_of(sample_level(1u, k, x, y));
}

fn read_colour(k: u32, x: u32, y: u32, n: u32) -> vec3<f32> {
    if k == 0u {
        return rgb[n].xyz;
    }
    return max(sample_level(0u, k, x, y), vec3<f32>(0.0));
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let n = (wid.x + wid.y * nwg.x) * 64u + lid;
    if n >= params.count {
        return;
    }
    let x = n % params.width;
    let y = n / params.width;
    var s = spread[n].z;
    var af = select_level(s);
    if params.blur_level == 1u && (af.x > 0.0 || af.y > 0.0) {
        let a = u32(af.x);
        let s_a = read_spread(a, x, y, n);
        if af.y > 0.0 {
            s = (1.0 - af.y) * s_a + af.y * read_spread(a + 1u, x, y, n);
        } else {
            s = s_a;
        }
        af = select_level(s);
    }
    let a = u32(af.x);
    let f = af.y;
    let va = read_colour(a, x, y, n);
    var res = va;
    if f > 0.0 {
        let vb = read_colour(a + 1u, x, y, n);
        res = (1.0 - f) * va + f * vb;
    }
    scattered[n] = vec4<f32>(res, 0.0);
    level[n] = af.x + f;
}
