// template: the value loads and result stores of the pair traversals (neighbour_sum.wgsl,
// neighbour_sum_lanes.wgsl, all_pairs.wgsl), which bind `vals` and `out`.
//
// A pair kernel reads each particle's value as a vec4 (its first VALUE_COMPS words: 3 for
// a force, 1 for a charge; the rest 0) and returns a vec4 of which components
// OUT_FIRST .. OUT_FIRST + OUT_COMPS are the particle's result row (nodes/pairs/mod.rs
// `PairKernel::value_comps`, `out_first`, `out_comps` prepend these constants).

override HAS_VALUES: bool = true;

fn value4(a: u32) -> vec4<f32> {
    var v = vec4<f32>(0.0);
    if (HAS_VALUES) {
        for (var c = 0u; c < VALUE_COMPS; c++) {
            v[c] = vals[VALUE_COMPS * a + c];
        }
    }
    return v;
}

fn store_out(i: u32, result: vec4<f32>) {
    var r = result;
    for (var c = 0u; c < OUT_COMPS; c++) {
        out[OUT_COMPS * i + c] = r[OUT_FIRST + c];
    }
}
