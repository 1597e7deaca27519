// Second pass of a per-component reduction: one workgroup folds the partials into the
// K outputs (divided by the row count for a mean).
#import common/twosum.wgsl

override OP: u32 = 0u;
override COMPENSATED: bool = false;
override MEAN: bool = false;
override K: u32 = 3u;

struct Shape { rows: u32, groups: u32, one: f32 }

@group(0) @binding(0) var<storage, read> partials: array<vec4<f32>>;
@group(0) @binding(1) var<storage, read_write> out: array<f32>;
@group(0) @binding(2) var<uniform> shape: Shape;

const WG: u32 = 256u;
var<workgroup> tree_v: array<vec4<f32>, 256>;
var<workgroup> tree_c: array<vec4<f32>, 256>;

fn identity() -> f32 {
    if (OP == 1u) { return -bitcast<f32>(0x7f800000u); }
    if (OP == 2u) { return bitcast<f32>(0x7f800000u); }
    return 0.0;
}

fn fold(p: ptr<function, vec4<f32>>, pc: ptr<function, vec4<f32>>, q: vec4<f32>, qc: vec4<f32>) {
    for (var c = 0u; c < 4u; c = c + 1u) {
        if (OP == 1u) {
            (*p)[c] = max((*p)[c], q[c]);
        } else if (OP == 2u) {
            (*p)[c] = min((*p)[c], q[c]);
        } else if (COMPENSATED) {
            let r = twosum_merge(vec2<f32>((*p)[c], (*pc)[c]), vec2<f32>(q[c], qc[c]), shape.one);
            (*p)[c] = r.x;
            (*pc)[c] = r.y;
        } else {
            (*p)[c] = (*p)[c] + q[c];
        }
    }
}

@compute @workgroup_size(256)
fn main(@builtin(local_invocation_index) lid: u32) {
    var v = vec4<f32>(identity());
    var vc = vec4<f32>(0.0);
    for (var g = lid; g < shape.groups; g = g + WG) {
        fold(&v, &vc, partials[2u * g], partials[2u * g + 1u]);
    }
    tree_v[lid] = v;
    tree_c[lid] = vc;
    workgroupBarrier();
    for (var s = WG / 2u; s > 0u; s = s >> 1u) {
        if (lid < s) {
            var p = tree_v[lid];
            var pc = tree_c[lid];
            fold(&p, &pc, tree_v[lid + s], tree_c[lid + s]);
            tree_v[lid] = p;
            tree_c[lid] = pc;
        }
        workgroupBarrier();
    }
    if (lid < K) {
        var r = tree_v[0][lid] + tree_c[0][lid];
        if (MEAN) {
            r = select(0.0, r / f32(shape.rows), shape.rows > 0u);
        }
        out[lid] = r;
    }
}
