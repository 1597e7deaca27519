// template: a pair kernel (see nodes/pairs/mod.rs), composed with a pair traversal.
//
// Free-space Rotne-Prager-Yamakawa mobility times the value of j, with the overlap form
// below contact (r < 2a). Values and results: 3 components (x, y, z; w unused). pair_params: a, 1 / (6 pi eta a), 1 / (8 pi eta).

fn rpy_tensor(r: vec3<f32>, r2: f32, v: vec3<f32>, f: f32, g: f32) -> vec3<f32> {
    // f v + g (r^ . v) r^; r^ r^ is taken as 0 for coincident particles (g is 0 there).
    let rv = select(0.0, dot(r, v) / r2, r2 > 0.0);
    return f * v + (g * rv) * r;
}

fn pair_term(xi: vec3<f32>, xj: vec3<f32>, r: vec3<f32>, r2: f32, vi: Row, vj: Row) -> Row {
    return row4(vec4<f32>(rpy_pair(r, r2, first3(vj)), 0.0));
}

fn rpy_pair(r: vec3<f32>, r2: f32, vj: vec3<f32>) -> vec3<f32> {
    let a = pair_params[0];
    let d = sqrt(r2);
    if (d >= 2.0 * a) {
        let c = pair_params[2] / d;
        let s = a * a / r2;
        return rpy_tensor(r, r2, vj, c * (1.0 + 2.0 / 3.0 * s), c * (1.0 - 2.0 * s));
    }
    let c = pair_params[1];
    let t = d / (32.0 * a);
    return rpy_tensor(r, r2, vj, c * (1.0 - 9.0 * t), c * (3.0 * t));
}

fn self_term(xi: vec3<f32>, vi: Row) -> Row {
    return row4(pair_params[1] * vi.a);
}
