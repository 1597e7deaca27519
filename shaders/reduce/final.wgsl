// Second pass of a flat reduction: one workgroup folds the partials into out[0]
// (the square root for a norm).
#import common/twosum.wgsl

override OP: u32 = 0u;
override COMPENSATED: bool = false;
override ROOT: bool = false;

struct Shape { groups: u32, one: f32 }

@group(0) @binding(0) var<storage, read> partials: array<vec2<f32>>;
@group(0) @binding(1) var<storage, read_write> out: array<f32>;
@group(0) @binding(2) var<uniform> shape: Shape;

const WG: u32 = 256u;
var<workgroup> tree: array<vec2<f32>, 256>;

fn identity() -> f32 {
    if (OP == 1u) { return -bitcast<f32>(0x7f800000u); }
    if (OP == 2u) { return bitcast<f32>(0x7f800000u); }
    return 0.0;
}

fn merge(p: vec2<f32>, q: vec2<f32>) -> vec2<f32> {
    if (OP == 1u) { return vec2<f32>(max(p.x, q.x), 0.0); }
    if (OP == 2u) { return vec2<f32>(min(p.x, q.x), 0.0); }
    if (COMPENSATED) { return twosum_merge(p, q, shape.one); }
    return vec2<f32>(p.x + q.x, 0.0);
}

@compute @workgroup_size(256)
fn main(@builtin(local_invocation_index) lid: u32) {
    var acc = vec2<f32>(identity(), 0.0);
    for (var i = lid; i < shape.groups; i = i + WG) {
        acc = merge(acc, partials[i]);
    }
    tree[lid] = acc;
    workgroupBarrier();
    for (var s = WG / 2u; s > 0u; s = s >> 1u) {
        if (lid < s) {
            tree[lid] = merge(tree[lid], tree[lid + s]);
        }
        workgroupBarrier();
    }
    if (lid == 0u) {
        let v = tree[0].x + tree[0].y;
        out[0] = select(v, sqrt(v), ROOT);
    }
}
