// The Chebyshev transform along z (nodes/chebyshev.rs): out[c][k][p] = sum_j T[k][j] x[c][j][p]
// for every component c, output level k and word p of a z level (words `plane` apart).
// One thread per output word; neighbouring threads read neighbouring words of a level.
#import common/index.wgsl

struct Shape { comps: u32, n: u32, plane: u32, scale: f32 }

@group(0) @binding(0) var<storage, read> x: array<f32>;
@group(0) @binding(1) var<storage, read_write> out: array<f32>;
@group(0) @binding(2) var<storage, read> matrix: array<f32>;
@group(0) @binding(3) var<uniform> shape: Shape;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i >= shape.comps * shape.n * shape.plane) {
        return;
    }
    let p = i % shape.plane;
    let level = i / shape.plane;
    let k = level % shape.n;
    let base = (level - k) * shape.plane + p;
    var acc = 0.0;
    for (var j = 0u; j < shape.n; j++) {
        acc += matrix[k * shape.n + j] * x[base + j * shape.plane];
    }
    out[i] = acc;
}
