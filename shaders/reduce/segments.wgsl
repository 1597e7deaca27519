// Per-segment reduction: thread s folds rows starts[s] .. starts[s+1] (or n for the last
// segment) of a particle array, component by component. Meant for short segments (cell
// lists: a handful of particles per cell); each segment is summed sequentially in order,
// so the result is deterministic.
//
// OP: 0 sum, 1 max, 2 min, 3 mean (0 for an empty segment).
#import common/index.wgsl
#import common/twosum.wgsl

override OP: u32 = 0u;
override COMPENSATED: bool = false;

struct Shape { rows: u32, k: u32, segments: u32, one: f32 }

@group(0) @binding(0) var<storage, read> x: array<f32>;
@group(0) @binding(1) var<storage, read> starts: array<u32>;
@group(0) @binding(2) var<storage, read_write> out: array<f32>;
@group(0) @binding(3) var<uniform> shape: Shape;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let s = flat_index(wid, nwg, lid, 256u);
    if (s >= shape.segments) {
        return;
    }
    let begin = min(starts[s], shape.rows);
    var end = shape.rows;
    if (s + 1u < shape.segments) {
        end = min(starts[s + 1u], shape.rows);
    }
    for (var c = 0u; c < shape.k; c = c + 1u) {
        var acc = vec2<f32>(0.0, 0.0);
        if (OP == 1u) { acc.x = -bitcast<f32>(0x7f800000u); }
        if (OP == 2u) { acc.x = bitcast<f32>(0x7f800000u); }
        for (var r = begin; r < end; r = r + 1u) {
            let v = x[r * shape.k + c];
            if (OP == 1u) {
                acc.x = max(acc.x, v);
            } else if (OP == 2u) {
                acc.x = min(acc.x, v);
            } else if (COMPENSATED) {
                acc = twosum_add(acc, v, shape.one);
            } else {
                acc.x = acc.x + v;
            }
        }
        var result = acc.x + acc.y;
        if (OP == 3u) {
            result = select(0.0, result / f32(end - begin), end > begin);
        }
        out[s * shape.k + c] = result;
    }
}
