// Image-space fog: final compositing L' = L_at + L'_sc (iser2018 Sec. 4.4), saturated at f32::MAX
// without forming an infinity. One thread per pixel. The CPU twin is the compose in
// effects::image_fog::render.
//
// Bindings (group 0):
//   0  params      uniform  ComposeParams
//   1  attenuated  storage  array<vec4<f32>> [pixels]  read: L_at (xyz)
//   2  scattered   storage  array<vec4<f32>> [pixels]  read: L'_sc (xyz)
//   3  image       storage  array<vec4<f32>> [pixels]  read_write: L' (xyz)

struct ComposeParams {
    count: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: ComposeParams;
@group(0) @binding(1) var<storage, read> attenuated: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> scattered: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> image: array<vec4<f32>>;

const F32_MAX: f32 = 3.40282347e38;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let n = (wid.x + wid.y * nwg.x) * 64u + lid;
    if n >= params.count {
        return;
    }
    let a = attenuated[n].xyz;
    let s = scattered[n].xyz;
    image[n] = vec4<f32>(a + min(s, vec3<f32>(F32_MAX) - a), 0.0);
}
