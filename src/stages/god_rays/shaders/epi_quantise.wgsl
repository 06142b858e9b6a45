// Epipolar god rays, pass 3: the integer leaves of each slice's integrand (baran2010 Sec. 6, the
// rank-N factorisation; Sec. 5's partial sums are taken over these leaves in pass 4). One thread per
// (slice of this chunk, lane); lanes are channel-major, l = c·rank + i, holding Γ_i(γ_j)·M_j·Δγ.
// CPU twin: step (2) of effects::epipolar::integrate::integrate_slice and tree::FenwickTree::new.
// Prepend epi_common.wgsl.
//
// As on the CPU (there with i64 and 2^62), each lane is quantised once with a power-of-two scale so
// that the slice's n bins sum below 2^30 in magnitude; integer sums are then exact and associative,
// so any summation order gives the same bits, and a fully removed bin is exactly 0.
//
// Stored are the lane's inclusive prefix sums of the leaves, the partial sums with nothing removed
// (leaf j = cum[j] − cum[j − 1]).
//
// Bindings (group 0), besides epi_common's P (0):
//   7  nbins   storage  array<u32> [slices]          read: γ bins the slice uses
//   9  modul   storage  array<vec4<f32>> [chunk·bins] read: modulation (pass 2)
//  10  gfn     storage  array<f32> [kernels·rank·bins] read: Γ_i(γ_j), (k·rank + i)·bins + j
//  12  scales  storage  array<f32> [chunk·lanes]     write: the lane's scale
//  13  cum     storage  array<i32> [chunk·bins·lanes] write: the leaves' inclusive prefix sums,
//                                                    (local·bins + j)·lanes + l

@group(0) @binding(7) var<storage, read> nbins: array<u32>;
@group(0) @binding(9) var<storage, read> modul: array<vec4<f32>>;
@group(0) @binding(10) var<storage, read> gfn: array<f32>;
@group(0) @binding(12) var<storage, read_write> scales: array<f32>;
@group(0) @binding(13) var<storage, read_write> cum: array<i32>;

// Γ_i(γ_j)·M_j·Δγ for lane l of bin j of the chunk's slice `local` (0 when not finite).
fn lane_value(local: u32, j: u32, l: u32) -> f32 {
    let rank = P.n0.z;
    let bins = P.n0.y;
    let c = l / rank;
    let i = l % rank;
    let k = min(c, P.n0.w - 1u);
    let m = modul[local * bins + j][c];
    let v = gfn[(k * rank + i) * bins + j] * m * P.sigma_t.w;
    return select(0.0, v, abs(v) < 3.0e38);
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = thread_index(wid, nwg, lid);
    let lanes = P.n1.w * P.n0.z;
    if i >= P.n3.x * lanes {
        return;
    }
    let local = i / lanes;
    let l = i % lanes;
    let bins = P.n0.y;
    let nb = nbins[P.n2.z + local];
    // Sibling loops of at most 32 768 bins each: lavapipe ends a loop nest after 65 535 iterations
    // (epi_integrate.wgsl's header), and gamma_bins may be 65 536.
    let mid = min(nb, 32768u);
    var mx = 0.0;
    for (var j = 0u; j < mid; j++) {
        mx = max(mx, abs(lane_value(local, j, l)));
    }
    for (var j = mid; j < nb; j++) {
        mx = max(mx, abs(lane_value(local, j, l)));
    }
    var sc = 1.0;
    if mx > 0.0 {
        sc = exp2(floor(log2(1073741824.0 / f32(nb) / mx)));
    }
    scales[local * lanes + l] = sc;
    var acc = 0;
    for (var j = 0u; j < mid; j++) {
        acc += i32(lane_value(local, j, l) * sc);
        cum[(local * bins + j) * lanes + l] = acc;
    }
    for (var j = mid; j < nb; j++) {
        acc += i32(lane_value(local, j, l) * sc);
        cum[(local * bins + j) * lanes + l] = acc;
    }
}
