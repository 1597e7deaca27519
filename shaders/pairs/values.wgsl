// template: the value loads and result stores of the pair traversals (neighbour_sum.wgsl,
// neighbour_sum_lanes.wgsl, all_pairs.wgsl), which bind `vals` and `out`, and the `Row` a
// pair kernel reads and returns.
//
// A pair kernel reads each particle's value row as a Row of 8 words (its first
// VALUE_COMPS words: 3 for a force, 1 for a charge, 6 for a force and a torque; the rest 0)
// and returns a Row of which words OUT_FIRST .. OUT_FIRST + OUT_COMPS are the particle's
// result row (nodes/pairs/mod.rs `PairKernel::value_comps`, `out_first`, `out_comps`
// prepend these constants). Words 0 to 3 are `a`, 4 to 7 `b`; two 3-vectors (a force and
// a torque, a velocity and an angular velocity) are words 0-2 and 3-5: `first3`,
// `second3`, `two3`.

override HAS_VALUES: bool = true;

struct Row {
    a: vec4<f32>,
    b: vec4<f32>,
}

fn row4(a: vec4<f32>) -> Row {
    return Row(a, vec4<f32>(0.0));
}

fn first3(v: Row) -> vec3<f32> {
    return v.a.xyz;
}

fn second3(v: Row) -> vec3<f32> {
    return vec3<f32>(v.a.w, v.b.x, v.b.y);
}

fn two3(u: vec3<f32>, w: vec3<f32>) -> Row {
    return Row(vec4<f32>(u, w.x), vec4<f32>(w.y, w.z, 0.0, 0.0));
}

fn row_add(x: Row, y: Row) -> Row {
    return Row(x.a + y.a, x.b + y.b);
}

fn value_row(p: u32) -> Row {
    var a = vec4<f32>(0.0);
    var b = vec4<f32>(0.0);
    if (HAS_VALUES) {
        for (var c = 0u; c < min(VALUE_COMPS, 4u); c++) {
            a[c] = vals[VALUE_COMPS * p + c];
        }
        for (var c = 4u; c < VALUE_COMPS; c++) {
            b[c - 4u] = vals[VALUE_COMPS * p + c];
        }
    }
    return Row(a, b);
}

fn store_out(i: u32, result: Row) {
    var a = result.a;
    var b = result.b;
    for (var c = 0u; c < OUT_COMPS; c++) {
        let w = OUT_FIRST + c;
        out[OUT_COMPS * i + c] = select(b[min(w, 7u) & 3u], a[min(w, 3u)], w < 4u);
    }
}
