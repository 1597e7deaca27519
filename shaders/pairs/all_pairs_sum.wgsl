// The partial sums of all_pairs.wgsl's slices added in slice order (a fixed order: the
// result does not depend on scheduling): out[w] = sum_s part[s * words + w].
#import common/index.wgsl

struct Shape {
    words: u32,
    slices: u32,
}

@group(0) @binding(0) var<storage, read> part: array<f32>;
@group(0) @binding(1) var<storage, read_write> out: array<f32>;
@group(0) @binding(2) var<uniform> shape: Shape;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let w = flat_index(wid, nwg, lid, 256u);
    if (w >= shape.words) {
        return;
    }
    var sum = 0.0;
    for (var s = 0u; s < shape.slices; s++) {
        sum += part[s * shape.words + w];
    }
    out[w] = sum;
}
