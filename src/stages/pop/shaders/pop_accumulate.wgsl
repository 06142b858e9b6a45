// POP accumulation toward the eye: elek2014 Eqs. 7-8 with the phase convolution of
// docs/design/pop.md (L_acc += w L f_hg(u, a g)), and the collided fluence (+= w L). One thread per
// cell; runs only while state.running == 1 (the iterate it reads was computed). The CPU twin is
// effects::pop::propagate::Accumulator::add for Observer::Eye.
//
// Bindings (group 0):
//   0  params      uniform  AccParams
//   1  l           storage  array<vec4<f32>> [cells]  the iterate's L per channel
//   2  a           storage  array<vec4<f32>> [cells]  its anisotropy (ignored when params.iso == 1)
//   3  u           storage  array<f32>       [cells]  d . (eye - x)/|eye - x| per cell
//   4  toward_eye  storage  array<vec4<f32>> [cells]  read_write
//   5  fluence     storage  array<vec4<f32>> [cells]  read_write
//   6  state       storage  State                     read

struct AccParams {
    cells: u32,
    iso: u32,
    weight: f32,
    _pad: u32,
    g: vec4<f32>, // the medium's HG g per channel (xyz)
}

struct State {
    running: u32,
    iterations: u32,
    anisotropic: u32,
    isotropic: u32,
    energy: array<f32>,
}

@group(0) @binding(0) var<uniform> params: AccParams;
@group(0) @binding(1) var<storage, read> l: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> a: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> u: array<f32>;
@group(0) @binding(4) var<storage, read_write> toward_eye: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> fluence: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read> state: State;

const INV_FOUR_PI: f32 = 0.07957747154594767;

// HG phase with the cancellation-free denominator (1 - g)^2 + 2 g (1 - mu) (physics::hg::phase).
fn hg(mu: f32, g: vec3<f32>) -> vec3<f32> {
    let m = clamp(mu, -1.0, 1.0);
    let s2 = (1.0 - g) * (1.0 - g) + 2.0 * g * (1.0 - m);
    return (1.0 - g) * (1.0 + g) * INV_FOUR_PI / (s2 * sqrt(s2));
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let n = (wid.x + wid.y * nwg.x) * 64u + lid;
    if state.running != 1u || n >= params.cells {
        return;
    }
    let ln = l[n].xyz;
    var an = vec3<f32>(0.0);
    if params.iso == 0u {
        an = a[n].xyz;
    }
    let p = hg(u[n], an * params.g.xyz);
    let add = select(vec3<f32>(0.0), params.weight * ln * p, ln > vec3<f32>(0.0));
    toward_eye[n] += vec4<f32>(add, 0.0);
    fluence[n] += vec4<f32>(params.weight * ln, 0.0);
}
