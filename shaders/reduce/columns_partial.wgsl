// First pass of a per-component reduction of a particle array (rows x K, K <= 4):
// workgroup g folds a grid-strided share of the rows into partials[2g] (values) and
// partials[2g + 1] (TwoSum compensations, for compensated sums).
//
// OP: 0 sum, 1 max, 2 min.
#import common/twosum.wgsl

override OP: u32 = 0u;
override COMPENSATED: bool = false;
override K: u32 = 3u;

struct Shape { rows: u32, groups: u32, one: f32 }

@group(0) @binding(0) var<storage, read> x: array<f32>;
@group(0) @binding(1) var<storage, read_write> partials: array<vec4<f32>>;
@group(0) @binding(2) var<uniform> shape: Shape;

const WG: u32 = 256u;
var<workgroup> tree_v: array<vec4<f32>, 256>;
var<workgroup> tree_c: array<vec4<f32>, 256>;

fn identity() -> f32 {
    if (OP == 1u) { return -bitcast<f32>(0x7f800000u); }
    if (OP == 2u) { return bitcast<f32>(0x7f800000u); }
    return 0.0;
}

// Folds (q, qc) into (p, pc), component by component.
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
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let g = wid.x;
    var v = vec4<f32>(identity());
    var vc = vec4<f32>(0.0);
    let stride = shape.groups * WG;
    for (var r = g * WG + lid; r < shape.rows; r = r + stride) {
        var row = vec4<f32>(identity());
        for (var c = 0u; c < K; c = c + 1u) {
            row[c] = x[r * K + c];
        }
        fold(&v, &vc, row, vec4<f32>(0.0));
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
    if (lid == 0u) {
        partials[2u * g] = tree_v[0];
        partials[2u * g + 1u] = tree_c[0];
    }
}
