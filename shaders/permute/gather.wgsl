// out[row] = values[index[row]], K words per row, copied as raw bits (f32 or u32 alike).
// An index past the last row gives a row of zeros.
#import common/index.wgsl

struct Shape { out_rows: u32, in_rows: u32, k: u32 }

@group(0) @binding(0) var<storage, read> values: array<u32>;
@group(0) @binding(1) var<storage, read> index: array<u32>;
@group(0) @binding(2) var<storage, read_write> out: array<u32>;
@group(0) @binding(3) var<uniform> shape: Shape;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i >= shape.out_rows * shape.k) {
        return;
    }
    let row = i / shape.k;
    let src = index[row];
    var v = 0u;
    if (src < shape.in_rows) {
        v = values[src * shape.k + (i - row * shape.k)];
    }
    out[i] = v;
}
