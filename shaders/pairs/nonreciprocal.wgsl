// template: a pair kernel (see nodes/pairs/mod.rs), composed with a pair traversal.
//
// The non-reciprocal 2-D pair force of S1 eq. 2 (Carter et al. 2017) on i from j:
// mu_i alpha_j f(r), f(r) = r / |r|^3 (pair_params[0] = 0, long range) or r / |r|^7
// (pair_params[0] = 1, short range), r = x_i - x_j in the plane. Values are (alpha, mu)
// per particle; the result is the force (2 words). Coincident particles add nothing (as
// nonreciprocal_forces). Summed over a cell list this is the short-range law with its
// cutoff (S1: 2.5 sigma).

fn pair_term(xi: vec3<f32>, xj: vec3<f32>, r: vec3<f32>, r2: f32, vi: Row, vj: Row) -> Row {
    let ok = r2 > 0.0;
    let inv2 = 1.0 / select(1.0, r2, ok);
    var w = inv2 * sqrt(inv2);
    if (pair_params[0] > 0.5) {
        w = inv2 * inv2 * inv2 * sqrt(inv2);
    }
    let c = select(0.0, vi.a.y * vj.a.x * w, ok);
    return row4(vec4<f32>(c * r.xy, 0.0, 0.0));
}

fn self_term(xi: vec3<f32>, vi: Row) -> Row {
    return row4(vec4<f32>(0.0));
}
