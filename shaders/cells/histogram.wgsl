// counts[key] += 1 for every key below `bins` (keys past the last bin are not counted).
#import common/index.wgsl

struct Shape { n: u32, bins: u32 }

@group(0) @binding(0) var<storage, read> keys: array<u32>;
@group(0) @binding(1) var<storage, read_write> counts: array<atomic<u32>>;
@group(0) @binding(2) var<uniform> shape: Shape;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i < shape.n) {
        let key = keys[i];
        if (key < shape.bins) {
            atomicAdd(&counts[key], 1u);
        }
    }
}
