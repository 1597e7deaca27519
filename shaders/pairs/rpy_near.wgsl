// template: a pair kernel (see nodes/pairs/mod.rs), composed with a pair traversal.
//
// The near field of RPY under the Positively Split Ewald split, tabulated in f64 on the
// host (nodes/pairs/rpy.rs): pair_table holds (f, g) at equally spaced distances from 0
// to the cutoff; linear interpolation. pair_params: (points - 1) / cutoff, points - 1.

fn pair_term(xi: vec3<f32>, xj: vec3<f32>, r: vec3<f32>, r2: f32, vi: Row, vj4: Row) -> Row {
    let vj = first3(vj4);
    let s = sqrt(r2) * pair_params[0];
    let i = u32(min(floor(s), pair_params[1] - 1.0));
    let t = s - f32(i);
    let f = mix(pair_table[2u * i], pair_table[2u * i + 2u], t);
    let g = mix(pair_table[2u * i + 1u], pair_table[2u * i + 3u], t);
    let rv = select(0.0, dot(r, vj) / r2, r2 > 0.0);
    return row4(vec4<f32>(f * vj + (g * rv) * r, 0.0));
}

fn self_term(xi: vec3<f32>, vi: Row) -> Row {
    return row4(pair_table[0] * vi.a);
}
