// Lanczos iteration for f(M) z (Ando, Chow, Saad, Skolnick 2012), the GPU half: the basis
// vectors and the recurrence. The host reads alpha and beta after each iteration, solves
// the small tridiagonal eigenproblem in f64 and writes back the coefficients of the
// answer in the basis (see nodes/lanczos.rs for the layout of `small`).
//
// Reductions run over a fixed number of workgroups (`shape.parts`, at most WG), each
// striding over the vector; every workgroup of the next kernel sums the partial sums
// itself in the same order, so all of them see the same scalar without another dispatch.

const WG: u32 = 256u;

struct Shape {
    n: u32,          // vector length (N x k words)
    max_iter: u32,   // rows of `basis_rows`: max_iter + 2 basis vectors, then w
    parts: u32,      // workgroups of the reductions
    alpha: u32,      // word offsets into `small`
    beta: u32,
    answer: u32,     // [m, coefficient 0, 1, ...]
    partial_a: u32,
    partial_b: u32,
}

@group(0) @binding(0) var<storage, read> z: array<f32>;
@group(0) @binding(1) var<storage, read> product: array<f32>;
@group(0) @binding(2) var<storage, read_write> result: array<f32>;
@group(0) @binding(3) var<storage, read_write> basis: array<f32>;
// Rows 0..=max_iter + 1: the basis vectors v_i (one past the cap: the executor may run
// one speculative iteration); row max_iter + 2: w, the orthogonalised product.
@group(0) @binding(4) var<storage, read_write> basis_rows: array<f32>;
// Word 0: iteration counter (u32); 1: |z| (f32); then alpha, beta, answer, partial sums.
@group(0) @binding(5) var<storage, read_write> small: array<u32>;
@group(0) @binding(6) var<uniform> shape: Shape;

var<workgroup> tree: array<f32, WG>;

fn reduce_tree(lid: u32, x: f32) -> f32 {
    tree[lid] = x;
    workgroupBarrier();
    for (var s = WG / 2u; s > 0u; s = s / 2u) {
        if (lid < s) {
            tree[lid] = tree[lid] + tree[lid + s];
        }
        workgroupBarrier();
    }
    let total = tree[0];
    workgroupBarrier();
    return total;
}

// Sum of the partial sums at `offset`, the same in every workgroup.
fn sum_parts(lid: u32, offset: u32) -> f32 {
    var x = 0.0;
    if (lid < shape.parts) {
        x = bitcast<f32>(small[offset + lid]);
    }
    return reduce_tree(lid, x);
}

fn row(i: u32) -> u32 {
    return i * shape.n;
}

@compute @workgroup_size(256)
fn start_partial(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid3: vec3<u32>) {
    let lid = lid3.x;
    var acc = 0.0;
    for (var j = wid.x * WG + lid; j < shape.n; j += shape.parts * WG) {
        acc += z[j] * z[j];
    }
    let total = reduce_tree(lid, acc);
    if (lid == 0u) {
        small[shape.partial_a + wid.x] = bitcast<u32>(total);
    }
}

@compute @workgroup_size(256)
fn start_scale(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid3: vec3<u32>) {
    let lid = lid3.x;
    let norm = sqrt(sum_parts(lid, shape.partial_a));
    if (wid.x == 0u && lid == 0u) {
        small[0] = 0u;
        small[1] = bitcast<u32>(norm);
    }
    let inv = select(0.0, 1.0 / norm, norm > 0.0);
    for (var j = wid.x * WG + lid; j < shape.n; j += shape.parts * WG) {
        let v = z[j] * inv;
        basis_rows[j] = v;
        basis[j] = v;
    }
}

// alpha_i = (M v_i - beta_{i-1} v_{i-1}) . v_i, partial sums.
@compute @workgroup_size(256)
fn dot_partial(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid3: vec3<u32>) {
    let lid = lid3.x;
    let i = small[0];
    var b = 0.0;
    var prev = row(i);
    if (i > 0u) {
        b = bitcast<f32>(small[shape.beta + i - 1u]);
        prev = row(i - 1u);
    }
    let cur = row(i);
    var acc = 0.0;
    for (var j = wid.x * WG + lid; j < shape.n; j += shape.parts * WG) {
        let w = product[j] - b * basis_rows[prev + j];
        acc += w * basis_rows[cur + j];
    }
    let total = reduce_tree(lid, acc);
    if (lid == 0u) {
        small[shape.partial_a + wid.x] = bitcast<u32>(total);
    }
}

// w = M v_i - alpha_i v_i - beta_{i-1} v_{i-1}, and |w|^2 partial sums.
@compute @workgroup_size(256)
fn update(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid3: vec3<u32>) {
    let lid = lid3.x;
    let i = small[0];
    let a = sum_parts(lid, shape.partial_a);
    if (wid.x == 0u && lid == 0u) {
        small[shape.alpha + i] = bitcast<u32>(a);
    }
    var b = 0.0;
    var prev = row(i);
    if (i > 0u) {
        b = bitcast<f32>(small[shape.beta + i - 1u]);
        prev = row(i - 1u);
    }
    let cur = row(i);
    let w_row = row(shape.max_iter + 2u);
    var acc = 0.0;
    for (var j = wid.x * WG + lid; j < shape.n; j += shape.parts * WG) {
        let w = product[j] - a * basis_rows[cur + j] - b * basis_rows[prev + j];
        basis_rows[w_row + j] = w;
        acc += w * w;
    }
    let total = reduce_tree(lid, acc);
    if (lid == 0u) {
        small[shape.partial_b + wid.x] = bitcast<u32>(total);
    }
}

// beta_i = |w|, v_{i+1} = w / beta_i (zero after a breakdown: the host stops there).
@compute @workgroup_size(256)
fn next_vector(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid3: vec3<u32>) {
    let lid = lid3.x;
    let i = small[0];
    let b = sqrt(sum_parts(lid, shape.partial_b));
    if (wid.x == 0u && lid == 0u) {
        small[shape.beta + i] = bitcast<u32>(b);
    }
    let inv = select(0.0, 1.0 / b, b > 0.0);
    let next = row(min(i + 1u, shape.max_iter + 1u));
    let w_row = row(shape.max_iter + 2u);
    for (var j = wid.x * WG + lid; j < shape.n; j += shape.parts * WG) {
        let v = basis_rows[w_row + j] * inv;
        basis_rows[next + j] = v;
        basis[j] = v;
    }
}

@compute @workgroup_size(1)
fn advance() {
    small[0] = small[0] + 1u;
}

// result = sum over the first m basis vectors of coefficient_k v_k.
@compute @workgroup_size(256)
fn combine(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_id) lid3: vec3<u32>) {
    let j = (wid.y * nwg.x + wid.x) * WG + lid3.x;
    if (j >= shape.n) {
        return;
    }
    let m = small[shape.answer];
    var acc = 0.0;
    for (var k = 0u; k < m; k++) {
        acc += bitcast<f32>(small[shape.answer + 1u + k]) * basis_rows[row(k) + j];
    }
    result[j] = acc;
}
