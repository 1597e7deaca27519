// template: a pair kernel (see nodes/pairs/mod.rs), composed with a pair traversal.
//
// Free-space Rotne-Prager-Yamakawa mobility times the value of j, with the overlap form
// below contact (r < 2a). Values and results: 3 components (force -> velocity), or with
// `rotation` (VALUE_COMPS = 6) force and torque -> velocity and angular velocity, the
// grand mobility (pairs/rpy_open.wgsl).
// pair_params: a, 1 / (6 pi eta a), 1 / (8 pi eta), 1 / (8 pi eta a^3).
#import pairs/rpy_open.wgsl

fn pair_term(xi: vec3<f32>, xj: vec3<f32>, r: vec3<f32>, r2: f32, vi: Row, vj: Row) -> Row {
    if (VALUE_COMPS != 6u) {
        return row4(vec4<f32>(rpy_pair(r, r2, first3(vj)), 0.0));
    }
    return rpy_grand(r, r2, first3(vj), second3(vj));
}

fn self_term(xi: vec3<f32>, vi: Row) -> Row {
    if (VALUE_COMPS != 6u) {
        return row4(pair_params[1] * vi.a);
    }
    return two3(pair_params[1] * first3(vi), pair_params[3] * second3(vi));
}
