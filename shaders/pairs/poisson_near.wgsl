// template: a pair kernel (see nodes/pairs/mod.rs), composed with a pair traversal.
//
// The near field of Ewald-split Gaussian charges (nodes/pairs/poisson.rs; UAMMD thesis
// eq. 24.20): the value of j is its charge (x); the result is (phi, Ex, Ey, Ez), of which
// the traversal stores the components OUT_FIRST .. OUT_FIRST + OUT_COMPS (the potential,
// the field or both). pair_table holds (G, G'/r) at equally spaced distances from 0 to the
// cutoff, computed in f64 (G'/r is regular at 0); linear interpolation. pair_params:
// (points - 1) / cutoff, points - 1. The field at i from j is -q_j G'(r) r^ =
// -q_j (G'/r) r, with r = x_i - x_j.

fn pair_term(xi: vec3<f32>, xj: vec3<f32>, r: vec3<f32>, r2: f32, vi: Row, vj4: Row) -> Row {
    let vj = vj4.a;
    let s = sqrt(r2) * pair_params[0];
    let i = u32(min(floor(s), pair_params[1] - 1.0));
    let t = s - f32(i);
    var result = vec4<f32>(0.0);
    if (OUT_FIRST == 0u) {
        result.x = vj.x * mix(pair_table[2u * i], pair_table[2u * i + 2u], t);
    }
    if (OUT_FIRST + OUT_COMPS > 1u) {
        let slope = mix(pair_table[2u * i + 1u], pair_table[2u * i + 3u], t);
        let e = (-vj.x * slope) * r;
        result = vec4<f32>(result.x, e);
    }
    return row4(result);
}

fn self_term(xi: vec3<f32>, vi: Row) -> Row {
    return row4(vec4<f32>(pair_table[0] * vi.a.x, 0.0, 0.0, 0.0));
}
