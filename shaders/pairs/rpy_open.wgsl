// template: the open-space RPY blocks shared by the rpy and rpy_wall pair kernels
// (nodes/pairs/rpy.rs is their f64 twin): translation with the overlap form below 2a,
// rotation-rotation (1 / (16 pi eta r^3)) (3 r^ r^ - I) and the couplings u_i += c t_j x r,
// w_i += c f_j x r (c = 1 / (8 pi eta r^3); overlapping, the overlap forms).
// pair_params[0..4]: a, 1 / (6 pi eta a), 1 / (8 pi eta), 1 / (8 pi eta a^3).
//
// Apart from contact (nearly every pair) one division and one square root per pair: a
// float division costs several instructions, and these kernels run at the arithmetic
// rate (BENCHMARKS.md "Direct pair mobilities").

// 1 / r^2, taken as 0 for coincident particles (their r^ r^ terms are 0).
fn rpy_inv_r2(r2: f32) -> f32 {
    return select(0.0, 1.0 / r2, r2 > 0.0);
}

fn rpy_tensor(r: vec3<f32>, inv_r2: f32, v: vec3<f32>, f: f32, g: f32) -> vec3<f32> {
    // f v + g (r^ . v) r^
    return f * v + (g * dot(r, v) * inv_r2) * r;
}

// The translational block times vj, from d = |r| and 1 / r^2.
fn rpy_pair_d(r: vec3<f32>, d: f32, inv_r2: f32, vj: vec3<f32>) -> vec3<f32> {
    let a = pair_params[0];
    if (d >= 2.0 * a) {
        let c = pair_params[2] * d * inv_r2;
        let s = a * a * inv_r2;
        return rpy_tensor(r, inv_r2, vj, c * (1.0 + 2.0 / 3.0 * s), c * (1.0 - 2.0 * s));
    }
    let c = pair_params[1];
    let t = d / (32.0 * a);
    return rpy_tensor(r, inv_r2, vj, c * (1.0 - 9.0 * t), c * (3.0 * t));
}

fn rpy_pair(r: vec3<f32>, r2: f32, vj: vec3<f32>) -> vec3<f32> {
    return rpy_pair_d(r, sqrt(r2), rpy_inv_r2(r2), vj);
}

// The grand RPY mobility times (f, t) at r = x_i - x_j: velocity and angular velocity.
fn rpy_grand(r: vec3<f32>, r2: f32, f: vec3<f32>, t: vec3<f32>) -> Row {
    let d = sqrt(r2);
    let inv_r2 = rpy_inv_r2(r2);
    let u = rpy_pair_d(r, d, inv_r2, f);
    var fr: f32;
    var gr: f32;
    var c: f32;
    if (d >= 2.0 * pair_params[0]) {
        let k = pair_params[2] * d * inv_r2 * inv_r2;
        fr = -0.5 * k;
        gr = 1.5 * k;
        c = k;
    } else {
        let s = d / pair_params[0];
        let r0 = pair_params[3];
        fr = r0 * (1.0 - 0.84375 * s + 0.078125 * s * s * s);
        gr = r0 * (0.28125 * s - 0.046875 * s * s * s);
        c = 0.5 * r0 * (1.0 - 0.375 * s);
    }
    return two3(u + c * cross(t, r), rpy_tensor(r, inv_r2, t, fr, gr) + c * cross(f, r));
}
