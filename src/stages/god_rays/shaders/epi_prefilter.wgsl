// Epipolar god rays, pass 2: the rectified shadow map with visibility prefiltering into depth modes
// (baran2010 Sec. 7) and the light modulation along each light ray (texture × spot falloff, Sec. 6
// last paragraph, Sec. 9). One thread per (slice of this chunk, γ bin). CPU twin: step (1) of
// effects::epipolar::integrate::integrate_slice (blocker_cot, modes, first_at_or_below).
// Prepend epi_common.wgsl.
//
// Bindings (group 0), besides epi_common's P (0), shadow (1), tex (2):
//   3  slices  storage  array<vec4<f32>> [2·slices]  read: per slice (u.xyz, β_lo), (β_hi, -, -, -)
//   4  offs    storage  array<u32> [slices + 1]     read: first sample of each slice
//   5  cots    storage  array<f32> [samples]        read: cot β per sample (pass 1)
//   6  nbins   storage  array<u32> [slices]         read: γ bins the slice uses
//   7  events  storage  array<u32> [chunk·bins·4]   write: per bin up to 4 modes, each
//                                                   (β index << 4) | exact << 3 | sub-sample count, 0 = none
//   8  modul   storage  array<vec4<f32>> [chunk·bins] write: modulation at the bin's centre (texture ×
//                                                   falloff × a directional light's entry attenuation)

@group(0) @binding(3) var<storage, read> slices: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> offs: array<u32>;
@group(0) @binding(5) var<storage, read> cots: array<f32>;
@group(0) @binding(6) var<storage, read> nbins: array<u32>;
@group(0) @binding(7) var<storage, read_write> events: array<u32>;
@group(0) @binding(8) var<storage, read_write> modul: array<vec4<f32>>;

// blocker_cot: cot β of the view ray through the blocker of light ray γ in the slice with axis u;
// x 1 when blocked.
fn blocker_cot(u: vec3<f32>, gamma: f32) -> vec2<f32> {
    let t = P.geo_t.xyz;
    let eye = P.cam_pos.xyz;
    if !is_spot() {
        let q = eye + gamma * u;
        let b = blocker_and_depth(q);
        if b.x > 0.5 && b.y >= 0.0 && gamma > 0.0 {
            return vec2<f32>(1.0, -(b.y + P.fr_dir.w - b.z) / gamma);
        }
        return vec2<f32>(0.0);
    }
    let w = cos(gamma) * (-t) + sin(gamma) * u;
    let pos = P.geo_pos.xyz;
    let b = blocker_and_depth(pos + w);
    if b.x > 0.5 && b.y >= 0.0 {
        let rel = pos + (b.y + P.fr_dir.w) * w - eye;
        let bu = dot(rel, u);
        if bu > 0.0 {
            return vec2<f32>(1.0, dot(rel, t) / bu);
        }
    }
    return vec2<f32>(0.0);
}

// light_point: a point on light ray γ.
fn light_point(u: vec3<f32>, gamma: f32) -> vec3<f32> {
    if !is_spot() {
        return P.cam_pos.xyz + gamma * u;
    }
    return P.geo_pos.xyz + cos(gamma) * (-P.geo_t.xyz) + sin(gamma) * u;
}

// First index p in [0, n) of the slice's decreasing cots with cots[p] ≤ c (n when none).
fn first_at_or_below(off: u32, n: u32, c: f32) -> u32 {
    var lo = 0u;
    var hi = n;
    while lo < hi {
        let mid = (lo + hi) / 2u;
        if cots[off + mid] > c {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return lo;
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = thread_index(wid, nwg, lid);
    let bins = P.n0.y;
    if i >= P.n3.x * bins {
        return;
    }
    let local = i / bins;
    let j = i % bins;
    let s = P.n2.z + local;
    let base = (local * bins + j) * 4u;
    for (var m = 0u; m < 4u; m++) {
        events[base + m] = 0u;
    }
    if j >= nbins[s] {
        return;
    }
    let u = slices[2u * s].xyz;
    let off = offs[s];
    let nbeta = offs[s + 1u] - off;
    let sub = P.n1.x;
    let dg = P.sigma_t.w;

    // Termination index per sub-sample (nbeta = never), sorted.
    var ks = array<u32, 4>(nbeta, nbeta, nbeta, nbeta);
    for (var q = 0u; q < sub; q++) {
        let g = (f32(j) + (f32(q) + 0.5) / f32(sub)) * dg;
        let c = blocker_cot(u, g);
        if c.x > 0.5 {
            ks[q] = first_at_or_below(off, nbeta, c.y);
        }
    }
    for (var a = 1u; a < sub; a++) {
        var b = a;
        while b > 0u && ks[b - 1u] > ks[b] {
            let tmp = ks[b];
            ks[b] = ks[b - 1u];
            ks[b - 1u] = tmp;
            b -= 1u;
        }
    }

    // Clusters (sum, count, last): indices at most one β step apart join; then the closest merge.
    var csum = array<u32, 4>(0u, 0u, 0u, 0u);
    var ccnt = array<u32, 4>(0u, 0u, 0u, 0u);
    var clast = array<u32, 4>(0u, 0u, 0u, 0u);
    var n = 0u;
    for (var q = 0u; q < sub; q++) {
        let k = ks[q];
        if n > 0u && (k == nbeta) == (clast[n - 1u] == nbeta) && k <= clast[n - 1u] + 1u {
            csum[n - 1u] += k;
            ccnt[n - 1u] += 1u;
            clast[n - 1u] = k;
        } else {
            csum[n] = k;
            ccnt[n] = 1u;
            clast[n] = k;
            n += 1u;
        }
    }
    let max_modes = max(P.n1.y, 1u);
    while n > max_modes {
        var best = 0u;
        var gap = 3.0e38;
        for (var a = 0u; a + 1u < n; a++) {
            let d = f32(csum[a + 1u]) / f32(ccnt[a + 1u]) - f32(csum[a]) / f32(ccnt[a]);
            if d < gap {
                gap = d;
                best = a;
            }
        }
        csum[best] += csum[best + 1u];
        ccnt[best] += ccnt[best + 1u];
        clast[best] = clast[best + 1u];
        for (var a = best + 1u; a + 1u < n; a++) {
            csum[a] = csum[a + 1u];
            ccnt[a] = ccnt[a + 1u];
            clast[a] = clast[a + 1u];
        }
        n -= 1u;
    }
    var applied = 0u;
    var out = 0u;
    for (var a = 0u; a < n; a++) {
        if clast[a] == nbeta {
            continue;
        }
        let k = u32(floor(f32(csum[a]) / f32(ccnt[a]) + 0.5));
        events[base + out] = (k << 4u) | ccnt[a];
        applied += ccnt[a];
        out += 1u;
    }
    if applied == sub && out > 0u {
        events[base + out - 1u] |= 8u;
    }
    modul[local * bins + j] = vec4<f32>(modulation(light_point(u, (f32(j) + 0.5) * dg)), 0.0);
}
