// Epipolar god rays, pass 4: the in-scatter of each view ray of a slice (baran2010 Secs. 4–6): the
// partial sum of the slice's quantised leaves up to the fractional bin γ_end/Δγ, each leaf reduced by
// the depth modes (Sec. 7) the view ray has passed, combined with B_i(β). Three entry points:
// `bases`, one thread per (slice of this chunk, block of T β samples, lane); `sums`, one thread per
// (slice of this chunk, β sample, lane); `combine`, one thread per (slice of this chunk, β sample).
//
// The paper's sweep keeps one running partial-sum tree per slice and visits the β samples in order,
// which is one long sequential loop per slice. Here the samples are cut into blocks of T (P.n4.y):
// `bases` writes, for each block, the partial sums of the leaves as they stand at the block's first
// sample (every bin's removals evaluated directly, then a prefix sum), and the list of the bins that
// have a depth mode inside the block; a sample's partial sum up to bin q is then its block's base at
// q less what the listed bins below q lose between the block's start and the sample. With S samples
// per slice, B bins and M depth modes, that is O(S/T·B + S·M·T/S) work per lane instead of the
// sweep's O(S log B + M log B) in one thread (T ≈ √S balances the two terms), with every thread
// independent. The sums are the integers the CPU's Fenwick tree holds after the same removals
// (exact, order-free sums), so the result equals the CPU sweep's up to f32 rounding of the leaves
// and of B_i. Each thread's loops stay far below 65 535 iterations in all: lavapipe (Mesa 22.3) ends
// any loop nest after that many iterations in total, silently, which a per-slice sweep (and a
// lanes × bins loop nest) exceeds.
// CPU twin: step (3) of effects::epipolar::integrate::integrate_slice.
// Prepend epi_common.wgsl.
//
// Bindings (group 0), besides epi_common's P (0); nblk = P.n4.z blocks per slice:
//   4  offs    storage  array<u32> [slices + 1]      read: first sample of each slice
//   5  betas   storage  array<f32> [samples]         read: β (pass 1)
//   6  gend    storage  array<f32> [samples]         read: γ_end (pass 1)
//   7  nbins   storage  array<u32> [slices]          read: γ bins the slice uses
//   8  events  storage  array<u32> [chunk·bins·4]    read: depth modes (pass 2)
//  11  bnode   storage  array<f32> [kernels·rank·64] read: s_i·V_i at the β nodes
//  12  scales  storage  array<f32> [chunk·lanes]     read: per-lane scale (pass 3)
//  13  cum     storage  array<i32> [chunk·bins·lanes] read: the leaves' inclusive prefix sums (pass 3)
//  14  lsum    storage  array<f32> [chunk·max β·lanes] sums writes, combine reads: the lanes' scaled
//                                                    partial sums, ((local·max β) + k)·lanes + l
//  15  listed  storage  array<u32> [chunk·nblk·(bins+1)] bases writes, sums reads: per block, the
//                                                    count n, then the n bins with a mode in the block
//  16  values  storage  array<vec4<f32>> [samples]   combine writes: in-scatter per β sample
//  17  base    storage  array<i32> [chunk·nblk·bins·lanes] bases writes, sums reads: per block the
//                                                    inclusive prefix sums at its first sample,
//                                                    ((local·nblk + b)·bins + j)·lanes + l

@group(0) @binding(4) var<storage, read> offs: array<u32>;
@group(0) @binding(5) var<storage, read> betas: array<f32>;
@group(0) @binding(6) var<storage, read> gend: array<f32>;
@group(0) @binding(7) var<storage, read> nbins: array<u32>;
@group(0) @binding(8) var<storage, read> events: array<u32>;
@group(0) @binding(11) var<storage, read> bnode: array<f32>;
@group(0) @binding(12) var<storage, read> scales: array<f32>;
@group(0) @binding(13) var<storage, read> cum: array<i32>;
@group(0) @binding(14) var<storage, read_write> lsum: array<f32>;
@group(0) @binding(15) var<storage, read_write> listed: array<u32>;
@group(0) @binding(16) var<storage, read_write> values: array<vec4<f32>>;
@group(0) @binding(17) var<storage, read_write> base: array<i32>;

// round(o·count/4) half away from zero without overflow (|o| < 2^30).
fn quarter(o: i32, count: u32) -> i32 {
    let a = u32(abs(o));
    let r = (a / 4u) * count + ((a % 4u) * count + 2u) / 4u;
    return select(i32(r), -i32(r), o < 0);
}

// One depth mode's removal from leaf `orig` once the β index k has passed it: -1 for "all of
// the rest" (the bin's exact last mode), else its rounded share, 0 when not passed or empty.
fn removal(orig: i32, ev: u32, k: u32) -> i32 {
    if (ev & 7u) == 0u || (ev >> 4u) > k {
        return 0;
    }
    return quarter(orig, (ev & 7u) * (4u / P.n1.x));
}

fn exact_passed(ev: u32, k: u32) -> bool {
    return (ev & 7u) != 0u && (ev & 8u) != 0u && (ev >> 4u) <= k;
}

// Leaf `orig` of bin j after the removals of the modes at β indices ≤ k: 0 once the bin's exact
// (last) mode has passed, else orig less each passed mode's share. (No loop: see the header.)
fn visible(orig: i32, eb: u32, j: u32, k: u32) -> i32 {
    let e = eb + j * 4u;
    let e0 = events[e];
    let e1 = events[e + 1u];
    let e2 = events[e + 2u];
    let e3 = events[e + 3u];
    if exact_passed(e0, k) || exact_passed(e1, k) || exact_passed(e2, k) || exact_passed(e3, k) {
        return 0;
    }
    return orig - removal(orig, e0, k) - removal(orig, e1, k) - removal(orig, e2, k) - removal(orig, e3, k);
}

// Leaf j of the lane whose bin-0 prefix sum is at cum[row].
fn leaf_of(row: u32, j: u32) -> i32 {
    let lanes = P.n1.w * P.n0.z;
    if j == 0u {
        return cum[row];
    }
    return cum[row + j * lanes] - cum[row + (j - 1u) * lanes];
}

// s_i·V_i(β) of kernel kk, term i, interpolated between the β nodes n0 and n0 + 1.
fn b_node(kk: u32, i: u32, n0: u32, fb: f32) -> f32 {
    let row = (kk * P.n0.z + i) * BETA_NODES;
    return (1.0 - fb) * bnode[row + n0] + fb * bnode[row + n0 + 1u];
}

// The sample's slice (local), β index and first sample, or local = NONE past the slice's samples.
fn sample_of(t: u32) -> vec3<u32> {
    let maxb = P.n4.x;
    let local = t / maxb;
    let k = t % maxb;
    let off = offs[P.n2.z + local];
    if local >= P.n3.x || k >= offs[P.n2.z + local + 1u] - off {
        return vec3<u32>(NONE, 0u, 0u);
    }
    return vec3<u32>(local, k, off);
}

// Leaf `orig` of bin j as it stands before the β index `start`: after the removals of the modes at
// β indices < start.
fn visible_before(orig: i32, eb: u32, j: u32, start: u32) -> i32 {
    if start == 0u {
        return orig;
    }
    return visible(orig, eb, j, start - 1u);
}

// Whether depth-mode word ev is a (non-empty) mode at a β index in [start, end).
fn within(ev: u32, start: u32, end: u32) -> bool {
    return (ev & 7u) != 0u && (ev >> 4u) >= start && (ev >> 4u) < end;
}

// Whether bin j has a mode at a β index in [start, end). (No loop: see the header.)
fn mode_within(eb: u32, j: u32, start: u32, end: u32) -> bool {
    let e = eb + j * 4u;
    return within(events[e], start, end) || within(events[e + 1u], start, end) || within(events[e + 2u], start, end)
        || within(events[e + 3u], start, end);
}

@compute @workgroup_size(64)
fn bases(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = thread_index(wid, nwg, lid);
    let lanes = P.n1.w * P.n0.z;
    let nblk = P.n4.z;
    let blk = t / lanes;
    if blk >= P.n3.x * nblk {
        return;
    }
    let l = t % lanes;
    let local = blk / nblk;
    let b = blk % nblk;
    let start = b * P.n4.y;
    let slice = P.n2.z + local;
    if start >= offs[slice + 1u] - offs[slice] {
        return;
    }
    let bins = P.n0.y;
    let nb = nbins[slice];
    let eb = local * bins * 4u;
    let row = local * bins * lanes + l;
    let out = blk * bins * lanes + l;
    // Sibling loops of at most 32 768 bins each (gamma_bins ≤ 65 536; see the header).
    let mid = min(nb, 32768u);
    var acc = 0;
    for (var j = 0u; j < mid; j++) {
        acc += visible_before(leaf_of(row, j), eb, j, start);
        base[out + j * lanes] = acc;
    }
    for (var j = mid; j < nb; j++) {
        acc += visible_before(leaf_of(row, j), eb, j, start);
        base[out + j * lanes] = acc;
    }
    if l == 0u {
        let end = start + P.n4.y;
        let lb = blk * (bins + 1u);
        var n = 0u;
        for (var j = 0u; j < mid; j++) {
            if mode_within(eb, j, start, end) {
                listed[lb + 1u + n] = j;
                n++;
            }
        }
        for (var j = mid; j < nb; j++) {
            if mode_within(eb, j, start, end) {
                listed[lb + 1u + n] = j;
                n++;
            }
        }
        listed[lb] = n;
    }
}

@compute @workgroup_size(64)
fn sums(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = thread_index(wid, nwg, lid);
    let lanes = P.n1.w * P.n0.z;
    let smp = sample_of(t / lanes);
    if smp.x == NONE || t / lanes >= P.n3.x * P.n4.x {
        return;
    }
    let l = t % lanes;
    let local = smp.x;
    let k = smp.y;
    let bins = P.n0.y;
    let nb = nbins[P.n2.z + local];
    let eb = local * bins * 4u;
    // Fractional bin γ_end/Δγ: bins below q whole, bin q by the fraction f.
    let x = max(gend[smp.z + k] / P.sigma_t.w, 0.0);
    let q = min(u32(floor(x)), nb);
    let row = local * bins * lanes + l;
    // Σ_{j<q} visible_j(k) = base_b[q − 1] − Σ_{listed j<q} (visible_j(start) − visible_j(k)): only
    // a bin with a mode inside the block changes between its start and k. The list ascends, so both
    // loops stop at the first bin ≥ q; two sibling loops of at most 32 768 entries each.
    let blk = local * P.n4.z + k / P.n4.y;
    let start = (k / P.n4.y) * P.n4.y;
    var sum = 0;
    if q > 0u {
        sum = base[(blk * bins + q - 1u) * lanes + l];
    }
    let lb = blk * (bins + 1u);
    let n = listed[lb];
    let mid = min(n, 32768u);
    for (var i = 0u; i < mid; i++) {
        let j = listed[lb + 1u + i];
        if j >= q {
            break;
        }
        let orig = leaf_of(row, j);
        sum -= visible_before(orig, eb, j, start) - visible(orig, eb, j, k);
    }
    for (var i = mid; i < n; i++) {
        let j = listed[lb + 1u + i];
        if j >= q {
            break;
        }
        let orig = leaf_of(row, j);
        sum -= visible_before(orig, eb, j, start) - visible(orig, eb, j, k);
    }
    var v = f32(sum);
    if q < nb {
        let f = x - f32(q);
        if f > 0.0 {
            v += f * f32(visible(leaf_of(row, q), eb, q, k));
        }
    }
    lsum[t] = v;
}

@compute @workgroup_size(64)
fn combine(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = thread_index(wid, nwg, lid);
    let smp = sample_of(t);
    if smp.x == NONE || t >= P.n3.x * P.n4.x {
        return;
    }
    let k = smp.y;
    let rank = P.n0.z;
    let ch = P.n1.w;
    let lanes = ch * rank;
    // B_i(β): nodes uniform in ln tan(β/2), times a(β).
    let beta = betas[smp.z + k];
    let nodes = f32(BETA_NODES - 1u);
    let xp = log(tan(0.5 * clamp(beta, 1e-9, PI - 1e-9)));
    let pos = clamp((xp - P.misc.y) / (P.misc.z - P.misc.y) * nodes, 0.0, nodes);
    let n0 = min(u32(floor(pos)), BETA_NODES - 2u);
    let fb = pos - f32(n0);
    let sb = max(sin(beta), 1e-12);
    var a = 1.0 / (P.geo_pos.w * sb);
    if !is_spot() {
        let hs = sin(0.5 * beta);
        a = phase_omm(2.0 * hs * hs) / sb;
    }
    var acc = vec3<f32>(0.0);
    for (var l = 0u; l < lanes; l++) {
        // Lane l = c·rank + i feeds channel c (every channel when the lanes are monochrome).
        let c = l / rank;
        let bv = b_node(min(c, P.n0.w - 1u), l % rank, n0, fb) * lsum[t * lanes + l] / scales[smp.x * lanes + l];
        var onto = vec3<f32>(f32(c == 0u), f32(c == 1u), f32(c == 2u));
        if ch == 1u {
            onto = vec3<f32>(1.0);
        }
        acc += onto * bv;
    }
    let val = acc * a * max(P.light_str.xyz, vec3<f32>(0.0)) * P.sigma_s.xyz;
    let ok = (val > vec3<f32>(0.0)) & (val < vec3<f32>(3.0e38));
    values[smp.z + k] = vec4<f32>(select(vec3<f32>(0.0), val, ok), 0.0);
}
