// out = A x for a dense square matrix A (row-major, n x n): one thread per row.

struct Shape {
    n: u32,
}

@group(0) @binding(0) var<storage, read> matrix: array<f32>;
@group(0) @binding(1) var<storage, read> x: array<f32>;
@group(0) @binding(2) var<storage, read_write> out: array<f32>;
@group(0) @binding(3) var<uniform> shape: Shape;

#import common/index.wgsl

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let i = flat_index(wid, nwg, lid.x, 256u);
    if (i >= shape.n) {
        return;
    }
    var acc = 0.0;
    let base = i * shape.n;
    for (var j = 0u; j < shape.n; j++) {
        acc += matrix[base + j] * x[j];
    }
    out[i] = acc;
}
