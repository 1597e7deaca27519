// template: what the fused slab solve kernels share (slab_solve.wgsl, three lines a
// thread; slab_solve_line.wgsl, a line a thread), imported by them: the uniform and the
// bindings (slab_bindings.wgsl), the reader of the per-k tables, the output's walls' flow
// and the inverse transform as a loop over the matrix (past WRITTEN_OUT_UP_TO points,
// nodes/slab_solve.rs). The importer defines POINTS, `alias Lane` (a thread's lines: f32
// or vec3<f32>), `put(j, v: Lane)`, which writes the values v at point j, and
// `velocity_end(slot, c, e)`, the velocity's value at end e (0 top, 1 bottom) of
// component c of slot `slot`, complex, from its workgroup memory.
#import chebyshev/slab_bindings.wgsl

fn entry(row: u32, k: u32) -> f32 {
    return bvp[row * u.slab.nk + k];
}

fn word(c: u32, z: u32, k: u32) -> u32 {
    return slab_word(c, z, k, POINTS, u.slab.nk);
}

// The velocity's values at end e (0 top, 1 bottom) of slot `slot`, columns x, y, z.
fn velocity_ends_at(slot: u32, e: u32) -> mat3x2<f32> {
    return mat3x2<f32>(velocity_end(slot, 0u, e), velocity_end(slot, 1u, e), velocity_end(slot, 2u, e));
}

// This thread's output: its first word, the factor on the transform's values (0 where the
// k = 0 mode is zero) and the walls' flow (a1 zeta + b1) exp(-|k| zeta) + (a2 zeta + b2)
// exp(|k| (zeta - H)) for its part, per line, where `out_walls`.
var<private> out_word: u32;
var<private> out_keep: Lane = Lane(1.0);
var<private> out_walls: bool = false;
var<private> out_kabs: f32;
var<private> out_a1: Lane;
var<private> out_b1: Lane;
var<private> out_a2: Lane;
var<private> out_b2: Lane;

// The transform's values v at point j with the walls' flow there.
fn with_walls(j: u32, v: Lane) -> Lane {
    if (!out_walls) {
        return v;
    }
    let zeta = points[POINTS * POINTS + j];
    let decay = exp(-out_kabs * zeta);
    let grow = exp(out_kabs * (zeta - u.slab.height));
    return out_keep * v + (out_a1 * zeta + out_b1) * decay + (out_a2 * zeta + out_b2) * grow;
}

// Values at the points (j = 0 the top) from the coefficients `coef`: the inverse
// transform, by parity. The points are symmetric (z_(n-1-j) = -z_j) and T_m(-z) = (-1)^m
// T_m(z), so the sums of the even and the odd terms at the upper half's points give both
// halves: half the dense matrix's products and loads, in two independent chains. Up to
// WRITTEN_OUT_UP_TO points the host writes the same sums out with the matrix's entries as
// literals (`values_written_out`: no matrix loads, constant indices); past them, this loop.
fn values_by_loop() {
    let n = POINTS;
    for (var j = 0u; j < (n + 1u) / 2u; j++) {
        var even = Lane(0.0);
        var odd = Lane(0.0);
        for (var m = 0u; m < n; m += 2u) {
            even += points[j * n + m] * coef[m];
        }
        for (var m = 1u; m < n; m += 2u) {
            odd += points[j * n + m] * coef[m];
        }
        put(j, even + odd);
        if (n - 1u - j != j) {
            put(n - 1u - j, even - odd);
        }
    }
}
