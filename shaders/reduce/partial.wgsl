// First pass of a flat reduction: workgroup g folds a grid-strided share of the input
// into partials[g] = (value, compensation). Loads are vec4 through a second view of the
// same buffer (buffers are padded to 16 bytes); the n % 4 tail is read as f32.
//
// OP: 0 sum, 1 max, 2 min. MAP: 0 x, 1 x*y (dot), 2 x*x (squared norm).
// COMPENSATED: sums carry a TwoSum error term (otherwise each thread sums its share
// sequentially, then the workgroup combines pairwise: error O((n/threads + log n) eps)).
#import common/twosum.wgsl

override OP: u32 = 0u;
override MAP: u32 = 0u;
override COMPENSATED: bool = false;

struct Shape { n: u32, groups: u32, one: f32 }

@group(0) @binding(0) var<storage, read> a4: array<vec4<f32>>;
@group(0) @binding(1) var<storage, read> a1: array<f32>;
@group(0) @binding(2) var<storage, read> b4: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> b1: array<f32>;
@group(0) @binding(4) var<storage, read_write> partials: array<vec2<f32>>;
@group(0) @binding(5) var<uniform> shape: Shape;

const WG: u32 = 256u;
var<workgroup> tree: array<vec2<f32>, 256>;

fn identity() -> f32 {
    if (OP == 1u) { return -bitcast<f32>(0x7f800000u); }
    if (OP == 2u) { return bitcast<f32>(0x7f800000u); }
    return 0.0;
}

fn combine(acc: vec2<f32>, x: f32) -> vec2<f32> {
    if (OP == 1u) { return vec2<f32>(max(acc.x, x), 0.0); }
    if (OP == 2u) { return vec2<f32>(min(acc.x, x), 0.0); }
    if (COMPENSATED) { return twosum_add(acc, x, shape.one); }
    return vec2<f32>(acc.x + x, 0.0);
}

fn merge(p: vec2<f32>, q: vec2<f32>) -> vec2<f32> {
    if (OP == 0u && COMPENSATED) { return twosum_merge(p, q, shape.one); }
    return combine(p, q.x);
}

fn mapped4(i: u32) -> vec4<f32> {
    let x = a4[i];
    if (MAP == 1u) { return x * b4[i]; }
    if (MAP == 2u) { return x * x; }
    return x;
}

fn mapped1(i: u32) -> f32 {
    let x = a1[i];
    if (MAP == 1u) { return x * b1[i]; }
    if (MAP == 2u) { return x * x; }
    return x;
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let g = wid.x;
    var acc = vec2<f32>(identity(), 0.0);
    let n4 = shape.n / 4u;
    let stride = shape.groups * WG;
    for (var i = g * WG + lid; i < n4; i = i + stride) {
        let v = mapped4(i);
        acc = combine(acc, v.x);
        acc = combine(acc, v.y);
        acc = combine(acc, v.z);
        acc = combine(acc, v.w);
    }
    if (g == 0u) {
        let t = n4 * 4u + lid;
        if (t < shape.n) {
            acc = combine(acc, mapped1(t));
        }
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
        partials[g] = tree[0];
    }
}
