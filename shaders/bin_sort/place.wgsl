// bin_sort, step 4 (nodes/bin_sort.rs): key i goes to slot start[bin] + rank[i]; the
// overflow bin (keys at or past `bins`) starts after every bin, at
// start[bins - 1] + counter[bins - 1] (bins >= 1). Where the general scan wrote
// `start`, the first `copy` threads also copy the counters to `count` (the
// one-workgroup scan writes `count` itself: copy = 0).
#import common/index.wgsl

struct Shape { n: u32, bins: u32, copy: u32 }

@group(0) @binding(0) var<storage, read> keys: array<u32>;
@group(0) @binding(1) var<storage, read> rank: array<u32>;
@group(0) @binding(2) var<storage, read> counter: array<u32>;
@group(0) @binding(3) var<storage, read> start: array<u32>;
@group(0) @binding(4) var<storage, read_write> perm: array<u32>;
@group(0) @binding(5) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(6) var<storage, read_write> count: array<u32>;
@group(0) @binding(7) var<uniform> shape: Shape;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i < shape.copy) {
        count[i] = counter[i];
    }
    if (i >= shape.n) {
        return;
    }
    let key = keys[i];
    var first: u32;
    if (key < shape.bins) {
        first = start[key];
    } else {
        let last = shape.bins - 1u;
        first = start[last] + counter[last];
    }
    let slot = first + rank[i];
    perm[slot] = i;
    keys_out[slot] = key;
}
