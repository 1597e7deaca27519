// bin_sort, step 2 (nodes/bin_sort.rs): each key takes the next free rank of its bin,
// rank[i] = atomicAdd(&counter[min(key, bins)], 1). Keys at or past `bins` share the
// overflow counter `bins`. Ranks inside a bin come in whatever order the atomics run.
#import common/index.wgsl

struct Shape { n: u32, bins: u32 }

@group(0) @binding(0) var<storage, read> keys: array<u32>;
@group(0) @binding(1) var<storage, read_write> counter: array<atomic<u32>>;
@group(0) @binding(2) var<storage, read_write> rank: array<u32>;
@group(0) @binding(3) var<uniform> shape: Shape;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i < shape.n) {
        rank[i] = atomicAdd(&counter[min(keys[i], shape.bins)], 1u);
    }
}
