// out[index[i]] = i for every index below N (the output's length, filled with u32::MAX
// before): the inverse of a permutation. The `invert_permutation` node (nodes/permute.rs).
#import common/index.wgsl

struct Shape { n: u32 }

@group(0) @binding(0) var<storage, read> index: array<u32>;
@group(0) @binding(1) var<storage, read_write> out: array<u32>;
@group(0) @binding(2) var<uniform> shape: Shape;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i >= shape.n) {
        return;
    }
    let dst = index[i];
    if (dst < shape.n) {
        out[dst] = i;
    }
}
