// template: a pair kernel (see nodes/pairs/mod.rs), composed with a pair traversal.
//
// Rotne-Prager-Blake: RPY above a no-slip wall (the plane z = wall), open RPY plus Swan and
// Brady's wall corrections with right-handed cross products, and the damping that keeps
// the mobility positive definite for particles overlapping the wall (a pair's block times
// b_i b_j, b = clamp(h / a, 0, 1), heights below a taken as a). The f64 twin, with the
// formulas' sources, is nodes/pairs/blake.rs. Values and results: 3 components, or 6 with
// `rotation` (VALUE_COMPS = 6). The corrections are in units of the radius.
// pair_params: a, 1 / (6 pi eta a), 1 / (8 pi eta), 1 / (8 pi eta a^3),
// 1 / (8 pi eta a^2), the wall's height.
#import pairs/rpy_open.wgsl

// Translation correction (units of 6 pi eta a) times v, R = x_i - image of x_j; hh = h_j / R_z
// (the callers share one division for it).
fn wall_uf(r: vec3<f32>, hh: f32, v: vec3<f32>) -> vec3<f32> {
    let d2 = dot(r, r);
    let i1 = inverseSqrt(d2);
    let i2 = i1 * i1;
    let i3 = i1 * i2;
    let i5 = i3 * i2;
    let e = r * i1;
    let ez2 = e.z * e.z;
    let f1 = -(3.0 * (1.0 + 2.0 * hh * (1.0 - hh) * ez2) * i1 + 2.0 * (1.0 - 3.0 * ez2) * i3
        - 2.0 * (1.0 - 5.0 * ez2) * i5) * 0.25;
    let f2 = -(3.0 * (1.0 - 6.0 * hh * (1.0 - hh) * ez2) * i1 - 6.0 * (1.0 - 5.0 * ez2) * i3
        + 10.0 * (1.0 - 7.0 * ez2) * i5) * 0.25;
    let f3 = e.z * (3.0 * hh * (1.0 - 6.0 * (1.0 - hh) * ez2) * i1 - 6.0 * (1.0 - 5.0 * ez2) * i3
        + 10.0 * (2.0 - 7.0 * ez2) * i5) * 0.5;
    let f4 = e.z * (3.0 * hh * i1 - 10.0 * i5) * 0.5;
    let f5 = -(3.0 * hh * hh * ez2 * i1 + 3.0 * ez2 * i3 + (2.0 - 15.0 * ez2) * i5);
    // f1 v + f2 e (e . v), plus the z column and row terms.
    var out = f1 * v + (f2 * dot(e, v)) * e;
    out.x += f3 * e.x * v.z;
    out.y += f3 * e.y * v.z;
    out.z += f4 * (e.x * v.x + e.y * v.y) + (f3 * e.z + f4 * e.z + f5) * v.z;
    return out;
}

// Rotation correction (units of 8 pi eta a^3) times v.
fn wall_wt(r: vec3<f32>, v: vec3<f32>) -> vec3<f32> {
    let i1 = inverseSqrt(dot(r, r));
    let i3 = i1 * i1 * i1;
    let e = r * i1;
    let f1 = (1.0 - 6.0 * e.z * e.z) * i3 * 0.5;
    let f2 = -1.5 * i3;
    let f3 = 3.0 * i3 * e.z;
    let f4 = 3.0 * i3;
    var out = f1 * v + (f2 * dot(e, v)) * e;
    // + f4 (e_y^2, -e_x e_y; -e_x e_y, e_x^2) on (x, y): f4 e_perp x (e_perp x v) + f4 |e_perp|^2 v.
    out.x += f4 * (e.y * e.y * v.x - e.x * e.y * v.y);
    out.y += f4 * (e.x * e.x * v.y - e.x * e.y * v.x);
    out.z += f3 * (e.x * v.x + e.y * v.y + e.z * v.z);
    return out;
}

// The rotation-from-force correction's matrix (units of 8 pi eta a^2), rows x, y, z; hh as
// in wall_uf.
fn wall_wf(r: vec3<f32>, hh: f32) -> mat3x3<f32> {
    let i1 = inverseSqrt(dot(r, r));
    let i2 = i1 * i1;
    let i4 = i2 * i2;
    let e = r * i1;
    let ez2 = e.z * e.z;
    let f1 = i2;
    let f2 = 2.0 * (6.0 * hh * ez2 * i2 + (1.0 - 10.0 * ez2) * i4);
    let f3 = -2.0 * e.z * (3.0 * hh * i2 - 5.0 * i4);
    let f4 = -2.0 * e.z * (hh * i2 - i4);
    // WGSL matrices are column-major: these are the rows, transposed on return.
    let row_x = vec3<f32>(f3 * e.x * e.y, -(f1 * e.z - f3 * e.y * e.y + f4), f1 * e.y + f2 * e.y + f3 * e.y * e.z);
    let row_y = vec3<f32>(f1 * e.z - f3 * e.x * e.x + f4, -f3 * e.x * e.y, -(f1 * e.x + f2 * e.x + f3 * e.x * e.z));
    let row_z = vec3<f32>(-f1 * e.y, f1 * e.x, 0.0);
    return transpose(mat3x3<f32>(row_x, row_y, row_z));
}

fn pair_term(xi: vec3<f32>, xj: vec3<f32>, r0: vec3<f32>, r02: f32, vi: Row, vj: Row) -> Row {
    // Two divisions per pair (1 / a, 1 / (h_i + h_j)): the rest multiplies.
    let a = pair_params[0];
    let inv_a = 1.0 / a;
    let wall = pair_params[5];
    let bij = clamp((xi.z - wall) * inv_a, 0.0, 1.0) * clamp((xj.z - wall) * inv_a, 0.0, 1.0);
    let hi = max(xi.z - wall, a);
    let hj = max(xj.z - wall, a);
    let r = vec3<f32>(xi.x - xj.x, xi.y - xj.y, hi - hj);
    let r2 = dot(r, r);
    let f = first3(vj);
    // The image of j seen from i, and of i seen from j, in units of a; h / R_z for each.
    let rim = vec3<f32>(r.x, r.y, hi + hj) * inv_a;
    let inv_sum = 1.0 / (hi + hj);
    var u: vec3<f32>;
    var w = vec3<f32>(0.0);
    if (VALUE_COMPS != 6u) {
        u = rpy_pair(r, r2, f);
    } else {
        let t = second3(vj);
        let open = rpy_grand(r, r2, f, t);
        u = first3(open);
        w = second3(open);
        let rim_ji = vec3<f32>(-rim.x, -rim.y, rim.z);
        w += pair_params[3] * wall_wt(rim, t) + pair_params[4] * (wall_wf(rim, hj * inv_sum) * f);
        u += pair_params[4] * (transpose(wall_wf(rim_ji, hi * inv_sum)) * t);
    }
    u += pair_params[1] * wall_uf(rim, hj * inv_sum, f);
    return two3(bij * u, bij * w);
}

fn self_term(xi: vec3<f32>, vi: Row) -> Row {
    let a = pair_params[0];
    let b = clamp((xi.z - pair_params[5]) / a, 0.0, 1.0);
    let h = max(xi.z - pair_params[5], a) / a;
    let i1 = 1.0 / h;
    let i3 = i1 * i1 * i1;
    let i5 = i3 * i1 * i1;
    let f = first3(vi);
    let par = 1.0 - (9.0 * i1 - 2.0 * i3 + i5) * 0.0625;
    let perp = 1.0 - (9.0 * i1 - 4.0 * i3 + i5) * 0.125;
    var u = pair_params[1] * vec3<f32>(par * f.x, par * f.y, perp * f.z);
    var w = vec3<f32>(0.0);
    if (VALUE_COMPS == 6u) {
        let t = second3(vi);
        let i4 = i3 * i1;
        w = pair_params[3] * vec3<f32>((1.0 - 0.3125 * i3) * t.x, (1.0 - 0.3125 * i3) * t.y, (1.0 - 0.125 * i3) * t.z);
        // w += (8 pi eta a^2)^-1 (-f_y, f_x, 0) / (8 h^4); u += its transpose times t.
        w += (pair_params[4] * 0.125 * i4) * vec3<f32>(-f.y, f.x, 0.0);
        u += (pair_params[4] * 0.125 * i4) * vec3<f32>(t.y, -t.x, 0.0);
    }
    let bb = b * b;
    return two3(bb * u, bb * w);
}
