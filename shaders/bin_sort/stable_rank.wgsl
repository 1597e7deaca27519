// bin_sort, deterministic runs (nodes/bin_sort.rs): after a first `place`, each bin's
// slots hold its keys' input indices in whatever order the atomics ranked them; the
// rank of key i inside its bin becomes the count of the bin's indices below i, so that a
// second `place` lists every bin in input order (a stable counting sort). Cost: one read
// per key of its bin, count[bin] reads per key (cell lists hold a few keys a bin).
#import common/index.wgsl

struct Shape { n: u32, bins: u32 }

@group(0) @binding(0) var<storage, read> keys: array<u32>;
@group(0) @binding(1) var<storage, read> perm: array<u32>;
@group(0) @binding(2) var<storage, read> counter: array<u32>;
@group(0) @binding(3) var<storage, read> start: array<u32>;
@group(0) @binding(4) var<storage, read_write> rank: array<u32>;
@group(0) @binding(5) var<uniform> shape: Shape;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i >= shape.n) {
        return;
    }
    let key = keys[i];
    var first: u32;
    var size: u32;
    if (key < shape.bins) {
        first = start[key];
        size = counter[key];
    } else {
        let last = shape.bins - 1u;
        first = start[last] + counter[last];
        size = counter[shape.bins];
    }
    var below = 0u;
    for (var s = first; s < first + size; s = s + 1u) {
        below = below + select(0u, 1u, perm[s] < i);
    }
    rank[i] = below;
}
