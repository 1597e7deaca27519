// template: the line steps of the slab solve kernels (slab_solve.wgsl, slab_staged.wgsl),
// imported by them: each thread's z line and its solve's coefficients in private arrays,
// the Chebyshev derivative in place and chebyshev_bvp's banded solve. The importer defines
// POINTS, `alias Lane` (f32: a line a thread; vec3<f32>: three lines a thread, solved
// side by side with the same per-k tables), the uniform `u` (its dz_scale: 2 / H) and
// `entry(row, k)`, row `row` of column k of chebyshev_bvp's per-k tables.
//
// Every loop over a line is bounded by the constant POINTS itself, `i < POINTS` (not by a
// `let n = POINTS` copy, not `i + 1u < POINTS`), here and in slab_solve.wgsl (its
// transform's loop past 64 points aside): the NVIDIA driver compiles them much better so
// (how, wgpu does not show). The fused kernel, otherwise the same, took 0.496 ms at 10^6
// spheres with `n` bounds and 0.330 ms with POINTS on an H100 (BENCHMARKS.md).

// This thread's line, and the solve's coefficients of y.
var<private> line: array<Lane, POINTS>;
var<private> coef: array<Lane, POINTS>;

// The line's derivative coefficients in place, times 2 / H (chebyshev_derivative's
// recurrence d_{m-1} = d_{m+1} + 2 m c_m from d_{n-1} = 0, d_0 halved).
fn differentiate_line() {
    var next = Lane(0.0);
    var here = Lane(0.0);
    for (var i = 0u; i < POINTS - 1u; i++) {
        let m = POINTS - 1u - i;
        let cm = line[m];
        line[m] = u.dz_scale * here;
        let prev = next + 2.0 * f32(m) * cm;
        next = here;
        here = prev;
    }
    line[0] = u.dz_scale * 0.5 * here;
}

// chebyshev_bvp's solve of k (shaders/chebyshev/bvp.wgsl): the line holds f (scaled by
// (H/2)^2), alpha and beta are scaled; leaves y's coefficients in coef.
fn solve(k: u32, alpha: Lane, beta: Lane) {
    let n = POINTS;
    var r0 = -alpha;
    var r1 = -beta;
    for (var z = 0u; z < POINTS; z++) {
        r0 += entry(3u * n + z, k) * line[z];
        r1 += entry(4u * n + z, k) * line[z];
    }
    let y0 = entry(5u * n, k) * r0 + entry(5u * n + 1u, k) * r1;
    let p0 = entry(5u * n + 2u, k) * r0 + entry(5u * n + 3u, k) * r1;
    let kappa2 = entry(5u * n + 4u, k);
    line[0] += kappa2 * y0;
    if (n > 1u) {
        line[1] += kappa2 * p0;
    }
    for (var z = 2u; z < POINTS; z++) {
        line[z] -= entry(z, k) * line[z - 2u];
    }
    for (var i = 0u; i < POINTS; i++) {
        let z = n - 1u - i;
        var up = Lane(0.0);
        if (z + 2u < n) {
            up = entry(2u * n + z, k) * line[z + 2u];
        }
        line[z] = (line[z] - up) * entry(n + z, k);
    }
    for (var m = 0u; m < POINTS; m++) {
        var v: Lane;
        if (m == 0u) {
            v = y0;
        } else if (m == 1u) {
            v = p0 - 0.5 * derivative(2u, p0);
        } else {
            v = (derivative(m - 1u, p0) - derivative(m + 1u, p0)) / (2.0 * f32(m));
        }
        coef[m] = v;
    }
}

// a_j of the line (0 past the end).
fn a_at(j: u32) -> Lane {
    if (j >= POINTS) {
        return Lane(0.0);
    }
    return line[j];
}

// y'_m from the a's (0 for m >= n).
fn derivative(m: u32, p0: Lane) -> Lane {
    if (m >= POINTS) {
        return Lane(0.0);
    }
    if (m == 0u) {
        return p0;
    }
    if (m == 1u) {
        return a_at(0u) - 0.5 * a_at(2u);
    }
    return (a_at(m - 1u) - a_at(m + 1u)) / (2.0 * f32(m));
}
