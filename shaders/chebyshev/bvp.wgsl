// template: nodes/chebyshev_bvp.rs prepends the constants WG, POINTS and K_MAJOR.
//
// The per-k boundary-value solve of nodes/chebyshev_bvp.rs: one thread per (k, component,
// real or imaginary part). f, y: Chebyshev coefficients along z of a half spectrum,
// word 2 ((c n + z) nk + k) + part. tables: per k, strided (entry i of every k contiguous):
// l, q, u (Thomas factors of A), g0, g1 (rows of C A^-1), s_inv (2 x 2), kappa^2, k = 0.
// line: this thread's a_n. nodes/chebyshev_bvp.rs prepends WG (threads per workgroup),
// POINTS (n) and K_MAJOR.
#import common/index.wgsl

struct Shape { nk: u32, n: u32, comps: u32, has_boundary: u32, f_scale: f32, bc_scale: f32, pad0: u32, pad1: u32 }

@group(0) @binding(0) var<storage, read> f: array<f32>;
@group(0) @binding(1) var<storage, read> boundary: array<f32>;
@group(0) @binding(2) var<storage, read_write> y: array<f32>;
@group(0) @binding(3) var<storage, read> tables: array<f32>;
@group(0) @binding(4) var<uniform> shape: Shape;

// This thread's line (POINTS = n, so its loops unroll and it stays in registers).
var<private> line: array<f32, POINTS>;

fn entry(row: u32, k: u32) -> f32 {
    return tables[row * shape.nk + k];
}

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let t = flat_index(wid, nwg, lid, WG);
    // No barriers: each thread touches only its own line, so threads past the end leave.
    if (t >= shape.nk * shape.comps * 2u) {
        return;
    }
    // K_MAJOR (tables larger than the cache): the components of a k in one warp, so its
    // tables are read once from memory; else each component's k in a row, so the lines'
    // reads and writes are contiguous.
    let part = t % 2u;
    var k = (t / 2u) % shape.nk;
    var c = t / (2u * shape.nk);
    if (K_MAJOR) {
        c = (t / 2u) % shape.comps;
        k = t / (2u * shape.comps);
    }
    let n = POINTS;
    let zero_mode = entry(5u * n + 5u, k) != 0.0;
    let kappa2 = entry(5u * n + 4u, k);
    // The boundary values (H/2 on a derivative condition; a Dirichlet value as it is).
    var alpha = 0.0;
    var beta = 0.0;
    if (shape.has_boundary == 1u) {
        let scale = select(shape.bc_scale, 1.0, zero_mode);
        alpha = scale * boundary[2u * ((c * 2u) * shape.nk + k) + part];
        beta = scale * boundary[2u * ((c * 2u + 1u) * shape.nk + k) + part];
    }
    // r = G f - (alpha, beta), f scaled by (H/2)^2; the line holds f.
    var r0 = -alpha;
    var r1 = -beta;
    for (var z = 0u; z < n; z++) {
        let v = shape.f_scale * f[2u * ((c * n + z) * shape.nk + k) + part];
        line[z] = v;
        r0 += entry(3u * n + z, k) * v;
        r1 += entry(4u * n + z, k) * v;
    }
    let y0 = entry(5u * n, k) * r0 + entry(5u * n + 1u, k) * r1;
    let p0 = entry(5u * n + 2u, k) * r0 + entry(5u * n + 3u, k) * r1;
    // A a = f - B (Y0, P0): B is -kappa^2 at (0, Y0) and (1, P0).
    line[0] += kappa2 * y0;
    if (n > 1u) {
        line[1] += kappa2 * p0;
    }
    // Thomas on the parities: forward elimination, then back substitution (in place).
    for (var z = 2u; z < n; z++) {
        line[z] -= entry(z, k) * line[(z - 2u)];
    }
    for (var i = 0u; i < n; i++) {
        let z = n - 1u - i;
        var up = 0.0;
        if (z + 2u < n) {
            up = entry(2u * n + z, k) * line[(z + 2u)];
        }
        line[z] = (line[z] - up) * entry(n + z, k);
    }
    // y from a: y'_0 = P0, y'_1 = (2 a_0 - a_2) / 2, y'_m = (a_{m-1} - a_{m+1}) / 2m
    // (m < n; 0 past), y_0 = Y0, y_1 = P0 - y'_2 / 2, y_m = (y'_{m-1} - y'_{m+1}) / 2m.
    for (var m = 0u; m < n; m++) {
        var v: f32;
        if (m == 0u) {
            v = y0;
        } else if (m == 1u) {
            v = p0 - 0.5 * derivative(2u, n, p0);
        } else {
            v = (derivative(m - 1u, n, p0) - derivative(m + 1u, n, p0)) / (2.0 * f32(m));
        }
        y[2u * ((c * n + m) * shape.nk + k) + part] = v;
    }
}

// a_j of this thread's line (0 past the end).
fn a_at(j: u32, n: u32) -> f32 {
    if (j >= n) {
        return 0.0;
    }
    return line[j];
}

// y'_m from the a's (0 for m >= n).
fn derivative(m: u32, n: u32, p0: f32) -> f32 {
    if (m >= n) {
        return 0.0;
    }
    if (m == 0u) {
        return p0;
    }
    if (m == 1u) {
        return a_at(0u, n) - 0.5 * a_at(2u, n);
    }
    return (a_at(m - 1u, n) - a_at(m + 1u, n)) / (2.0 * f32(m));
}
