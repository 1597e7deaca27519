// out[index[row]] = values[row], K words per row, raw bits. Indices past the output are
// skipped; rows nobody writes keep the zeros of the preceding fill. With repeated
// indices the winner is unspecified (pass a permutation).
#import common/index.wgsl

struct Shape { in_rows: u32, out_rows: u32, k: u32 }

@group(0) @binding(0) var<storage, read> values: array<u32>;
@group(0) @binding(1) var<storage, read> index: array<u32>;
@group(0) @binding(2) var<storage, read_write> out: array<u32>;
@group(0) @binding(3) var<uniform> shape: Shape;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i >= shape.in_rows * shape.k) {
        return;
    }
    let row = i / shape.k;
    let dst = index[row];
    if (dst < shape.out_rows) {
        out[dst * shape.k + (i - row * shape.k)] = values[i];
    }
}
