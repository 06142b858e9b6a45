// POP gathering iteration: elek2014 Eqs. 2-6 (one thread per cell), plus the iterate's energy per
// workgroup. Driven by src/gpu/pop.rs; the CPU twin is effects::pop::propagate::step.
//
// Cells are indexed i + dims.x * (j + dims.y * k); axis 2 is the light direction d. Per-channel
// values are the xyz of a vec4 (w unused).
//
// Bindings (group 0):
//   0  params      uniform  StepParams
//   1  l_in        storage  array<vec4<f32>>  [cells]    lobe magnitude L (fluence) per channel
//   2  a_in        storage  array<vec4<f32>>  [cells]    lobe anisotropy a per channel
//   3  link_t      storage  array<vec4<f32>>  [3 cells]  absorption transmittance of the link from a
//                                                        cell to its +axis neighbour (0: blocked/border)
//   4  link_decay  storage  array<vec4<f32>>  [3 cells]  anisotropy decay g^(sigma_s t) of that link (Eq. 4)
//   5  flow        storage  array<vec4<f32>>  [bins]     Eq. 2-3 partition (front, side, back) on a
//                                                        uniform axis a in [-1, 1], linearly interpolated
//   6  l_out       storage  array<vec4<f32>>  [cells]    read_write
//   7  a_out       storage  array<vec4<f32>>  [cells]    read_write
//   8  partial     storage  array<f32>        [groups]   read_write: sum of L_out over the workgroup's cells
//   9  state       storage  State                        read: the step runs only while state.running == 1

struct StepParams {
    dims: vec3<u32>,
    cells: u32,
    bins: u32,
    iso: u32, // 1: isotropic residuum (Sec. 5.4): every lobe has a = 0, no anisotropy bookkeeping
    _pad0: u32,
    _pad1: u32,
}

struct State {
    running: u32,
    iterations: u32,
    anisotropic: u32,
    isotropic: u32,
    energy: array<f32>,
}

@group(0) @binding(0) var<uniform> params: StepParams;
@group(0) @binding(1) var<storage, read> l_in: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> a_in: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> link_t: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> link_decay: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> flow: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> l_out: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> a_out: array<vec4<f32>>;
@group(0) @binding(8) var<storage, read_write> partial: array<f32>;
@group(0) @binding(9) var<storage, read> state: State;

var<workgroup> sums: array<f32, 64>;

// The partition at anisotropy a, as tables::pop_preset::lerp_flow reads it.
fn lerp_flow(a: f32) -> vec3<f32> {
    let n = params.bins;
    let t = (clamp(a, -1.0, 1.0) + 1.0) * 0.5 * f32(n - 1u);
    let i = min(u32(floor(t)), n - 2u);
    let f = t - f32(i);
    return flow[i].xyz * (1.0 - f) + flow[i + 1u].xyz * f;
}

fn part_of(p: vec3<f32>, part: u32) -> f32 {
    return select(select(p.z, p.y, part == 1u), p.x, part == 0u);
}

@compute @workgroup_size(64)
fn main(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let group = wid.x + wid.y * nwg.x;
    let n = group * 64u + lid;
    let run = state.running == 1u && n < params.cells;
    var total = 0.0;
    if run {
        let dims = params.dims;
        let c = vec3<u32>(n % dims.x, (n / dims.x) % dims.y, n / (dims.x * dims.y));
        let iso_row = lerp_flow(0.0);
        var sum_l = vec3<f32>(0.0);
        var sum_la = vec3<f32>(0.0);
        for (var axis = 0u; axis < 3u; axis++) {
            for (var s = 0u; s < 2u; s++) {
                // s = 0: the neighbour below along the axis, s = 1: above.
                if (s == 0u && c[axis] == 0u) || (s == 1u && c[axis] + 1u >= dims[axis]) {
                    continue;
                }
                var sc = c;
                if s == 0u { sc[axis] = c[axis] - 1u; } else { sc[axis] = c[axis] + 1u; }
                let src = sc.x + dims.x * (sc.y + dims.y * sc.z);
                // The link is stored at the lower cell of the pair.
                let link = select(n, src, s == 0u) * 3u + axis;
                let t = link_t[link].xyz;
                // Flow along +d from the cell behind is "front", from the cell ahead "back".
                var part = 1u;
                if axis == 2u { part = select(2u, 0u, s == 0u); }
                let ls = l_in[src].xyz;
                var frac: vec3<f32>;
                if params.iso == 1u {
                    frac = vec3<f32>(part_of(iso_row, part));
                } else {
                    let a = a_in[src].xyz;
                    frac = vec3<f32>(part_of(lerp_flow(a.x), part), part_of(lerp_flow(a.y), part), part_of(lerp_flow(a.z), part));
                }
                let live = (ls > vec3<f32>(0.0)) & (t > vec3<f32>(0.0));
                let dl = select(vec3<f32>(0.0), ls * t * frac, live);
                sum_l += dl;
                if params.iso == 0u {
                    sum_la += dl * a_in[src].xyz * link_decay[link].xyz;
                }
            }
        }
        var na = vec3<f32>(0.0);
        if params.iso == 0u {
            let has = sum_l > vec3<f32>(0.0);
            na = select(vec3<f32>(0.0), clamp(sum_la / max(sum_l, vec3<f32>(1e-38)), vec3<f32>(-1.0), vec3<f32>(1.0)), has);
        }
        l_out[n] = vec4<f32>(sum_l, 0.0);
        a_out[n] = vec4<f32>(na, 0.0);
        total = sum_l.x + sum_l.y + sum_l.z;
    }
    // The workgroup's share of the iterate's energy (a tree sum; every thread reaches the barriers).
    sums[lid] = total;
    workgroupBarrier();
    for (var stride = 32u; stride > 0u; stride >>= 1u) {
        if lid < stride {
            sums[lid] += sums[lid + stride];
        }
        workgroupBarrier();
    }
    if lid == 0u && state.running == 1u {
        partial[group] = sums[0];
    }
}
