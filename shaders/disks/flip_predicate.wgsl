// The flip predicate (disks/predicate.wgsl) of quads given as rows (a, b, c, d), one
// thread per quad: its code (0 keep, 1 illegal, 2 folded).
#import common/index.wgsl
#import disks/predicate.wgsl

struct Params { n: u32, tolerance: f32 }

@group(0) @binding(0) var<storage, read> quads: array<vec2<f32>>;
@group(0) @binding(1) var<storage, read_write> codes: array<u32>;
@group(0) @binding(2) var<uniform> params: Params;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i >= params.n) {
        return;
    }
    let d = quads[4u * i + 3u];
    codes[i] = flip_code(quads[4u * i] - d, quads[4u * i + 1u] - d, quads[4u * i + 2u] - d,
        params.tolerance);
}
