// Copies `count` columns of each row: out[row][out_first + c] = x[row][in_first + c], words
// copied as raw bits. The `columns` and `concat` nodes (nodes/permute.rs) run it.
#import common/index.wgsl

struct Shape { rows: u32, in_cols: u32, out_cols: u32, in_first: u32, out_first: u32, count: u32 }

@group(0) @binding(0) var<storage, read> x: array<u32>;
@group(0) @binding(1) var<storage, read_write> out: array<u32>;
@group(0) @binding(2) var<uniform> shape: Shape;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i >= shape.rows * shape.count) {
        return;
    }
    let row = i / shape.count;
    let c = i - row * shape.count;
    out[row * shape.out_cols + shape.out_first + c] = x[row * shape.in_cols + shape.in_first + c];
}
