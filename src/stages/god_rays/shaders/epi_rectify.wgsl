// Epipolar god rays, pass 1: rectification of the depth map (baran2010 Sec. 3; Sec. 9 for spot
// lights). One thread per view-ray sample β of every slice: the sample's angle, view direction and
// rectified depth γ_end, and the largest γ_end per slice. CPU twin: the per-sample loop of
// effects::epipolar::rectify::Setup::new. Prepend epi_common.wgsl.
//
// Bindings (group 0), besides epi_common's P (0):
//   3  slices  storage  array<vec4<f32>> [2·slices]  read: per slice (u.xyz, β_lo), (β_hi, -, -, -)
//   4  offs    storage  array<u32> [slices + 1]     read: first sample of each slice, then the total
//   5  depth   storage  array<f32> [w·h]            read: camera distance per pixel, < 0 = nothing hit
//   6  betas   storage  array<f32> [samples]        write: β
//   7  gend    storage  array<f32> [samples]        write: γ_end
//   8  cots    storage  array<f32> [samples]        write: cot β
//   9  gmax    storage  array<atomic<u32>> [slices] read_write: bits of the slice's largest γ_end (≥ 0)

@group(0) @binding(3) var<storage, read> slices: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> offs: array<u32>;
@group(0) @binding(5) var<storage, read> depth: array<f32>;
@group(0) @binding(6) var<storage, read_write> betas: array<f32>;
@group(0) @binding(7) var<storage, read_write> gend: array<f32>;
@group(0) @binding(8) var<storage, read_write> cots: array<f32>;
@group(0) @binding(9) var<storage, read_write> gmax: array<atomic<u32>>;

// The slice holding sample i: the last s with offs[s] ≤ i.
fn slice_of(i: u32) -> u32 {
    var lo = 0u;
    var hi = P.n0.x;
    while hi - lo > 1u {
        let mid = (lo + hi) / 2u;
        if offs[mid] <= i {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return lo;
}

// god_rays::sample_depth: the bilinear blend of the four pixels around raster position q when they see
// one surface (all hit, the largest ≤ 1.1× the smallest), else the containing pixel's distance.
fn sample_depth(q: vec2<f32>) -> f32 {
    let w = u32(P.cam_right.w);
    let h = u32(P.cam_up.w);
    let near = depth[u32(clamp(q.y, 0.0, f32(h - 1u))) * w + u32(clamp(q.x, 0.0, f32(w - 1u)))];
    let fx = clamp(q.x - 0.5, 0.0, f32(w - 1u));
    let fy = clamp(q.y - 0.5, 0.0, f32(h - 1u));
    let x0 = u32(floor(fx));
    let y0 = u32(floor(fy));
    let x1 = min(x0 + 1u, w - 1u);
    let y1 = min(y0 + 1u, h - 1u);
    let d = vec4<f32>(depth[y0 * w + x0], depth[y0 * w + x1], depth[y1 * w + x0], depth[y1 * w + x1]);
    let lo = min(min(d.x, d.y), min(d.z, d.w));
    let hi = max(max(d.x, d.y), max(d.z, d.w));
    if !(lo > 0.0 && hi <= 1.1 * lo) {
        return near;
    }
    let tx = fx - f32(x0);
    let ty = fy - f32(y0);
    return mix(mix(d.x, d.y, tx), mix(d.z, d.w, tx), ty);
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = thread_index(wid, nwg, lid);
    if i >= P.n2.w || P.n0.x == 0u {
        return;
    }
    let s = slice_of(i);
    let k = i - offs[s];
    let n = offs[s + 1u] - offs[s];
    let a = slices[2u * s];
    let b = slices[2u * s + 1u];
    let beta = a.w + (b.x - a.w) * f32(k) / f32(max(n, 2u) - 1u);
    let t = P.geo_t.xyz;
    let v = cos(beta) * t + sin(beta) * a.xyz;
    let q = project_dir(v);
    var dpx = -1.0;
    if q.w > 0.5 && q.z > 0.5 {
        dpx = sample_depth(q.xy);
    }
    let ext = view_extent(v, dpx);
    let ge = gamma_end(v, beta, ext);
    // Positive, or +0 (a NaN or −0 would corrupt the bit-wise maximum).
    let g = select(0.0, ge, ge > 0.0 && ge < 3.0e38);
    betas[i] = beta;
    gend[i] = g;
    cots[i] = cos(beta) / sin(beta);
    atomicMax(&gmax[s], bitcast<u32>(g));
}
