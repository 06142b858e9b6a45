// POP stopping rule: sums the per-workgroup energies of the newest iterate (written by
// pop_step.wgsl), appends the total to state.energy and keeps state.running = 1 while it is above
// eps_L times the seeded energy (elek2014 Sec. 5.4; the CPU loop condition of
// effects::pop::propagate). The GPU decides when to stop, so a whole frame's iterations are
// recorded at once and the host never waits on an iteration. Dispatched with exactly 64 threads.
//
// Bindings (group 0):
//   0  params   uniform  EnergyParams
//   1  partial  storage  array<f32> [groups]  read
//   2  state    storage  State                read_write

struct EnergyParams {
    groups: u32,
    iso: u32,
    stop: f32, // eps_L * seeded energy
    _pad: u32,
}

struct State {
    running: u32,
    iterations: u32,
    anisotropic: u32,
    isotropic: u32,
    energy: array<f32>,
}

@group(0) @binding(0) var<uniform> params: EnergyParams;
@group(0) @binding(1) var<storage, read> partial: array<f32>;
@group(0) @binding(2) var<storage, read_write> state: State;

var<workgroup> sums: array<f32, 64>;

@compute @workgroup_size(64)
fn main(@builtin(local_invocation_index) lid: u32) {
    var s = 0.0;
    for (var i = lid; i < params.groups; i += 64u) {
        s += partial[i];
    }
    sums[lid] = s;
    workgroupBarrier();
    for (var stride = 32u; stride > 0u; stride >>= 1u) {
        if lid < stride {
            sums[lid] += sums[lid + stride];
        }
        workgroupBarrier();
    }
    if lid == 0u && state.running == 1u {
        let e = sums[0];
        state.iterations += 1u;
        if params.iso == 1u { state.isotropic += 1u; } else { state.anisotropic += 1u; }
        state.energy[state.iterations] = e;
        state.running = select(0u, 1u, e > params.stop);
    }
}
