// The Chebyshev coefficients of a derivative along z (nodes/chebyshev.rs): one thread per
// z line (component c, word p of a level), the backward recurrence
// d_{k-1} = d_{k+1} + 2 k c_k from d_{n-1} = 0, d_0 halved, all times `scale`; x read
// from word x_offset on.
#import common/index.wgsl

struct Shape { comps: u32, n: u32, plane: u32, scale: f32, x_offset: u32, pad0: u32, pad1: u32, pad2: u32 }

@group(0) @binding(0) var<storage, read> x: array<f32>;
@group(0) @binding(1) var<storage, read_write> out: array<f32>;
@group(0) @binding(2) var<uniform> shape: Shape;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let line = flat_index(wid, nwg, lid, 256u);
    if (line >= shape.comps * shape.plane) {
        return;
    }
    let c = line / shape.plane;
    let p = line % shape.plane;
    let base = c * shape.n * shape.plane + p;
    let n = shape.n;
    out[base + (n - 1u) * shape.plane] = 0.0;
    var next = 0.0;
    var here = 0.0;
    for (var k = n - 1u; k >= 1u; k--) {
        let prev = next + 2.0 * f32(k) * x[shape.x_offset + base + k * shape.plane];
        let scaled = select(prev, 0.5 * prev, k == 1u);
        out[base + (k - 1u) * shape.plane] = shape.scale * scaled;
        next = here;
        here = prev;
    }
}
