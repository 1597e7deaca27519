// template: a pair kernel (see nodes/pairs/mod.rs), composed with a pair traversal.
//
// Lennard-Jones on i from j, as (potential, force): half the pair's energy
// 4 eps ((s/r)^12 - (s/r)^6) - shift (shifted to 0 at the cutoff) and the force
// 24 eps (2 (s/r)^12 - (s/r)^6) r / r^2 (the WCA force with cutoff 2^(1/6) sigma). Values
// are not read. pair_params: 24 eps, sigma^2, 2 eps, shift / 2.

fn pair_term(xi: vec3<f32>, xj: vec3<f32>, r: vec3<f32>, r2: f32, vi: Row, vj: Row) -> Row {
    let s2 = pair_params[1] / r2;
    let s6 = s2 * s2 * s2;
    var half = 0.0;
    if (OUT_FIRST == 0u) {
        half = pair_params[2] * (s6 * s6 - s6) - pair_params[3];
    }
    return row4(vec4<f32>(half, (pair_params[0] * (2.0 * s6 * s6 - s6) / r2) * r));
}

fn self_term(xi: vec3<f32>, vi: Row) -> Row {
    return row4(vec4<f32>(0.0));
}
