// out[w] = table[x[w]] for the words w in columns first .. first + count of each row of
// `stride` words whose value is below the table's length; every other word is copied.
// The `relabel` node (nodes/permute.rs): a mesh's vertex ids renamed when its points are
// renumbered.
#import common/index.wgsl

struct Shape { words: u32, stride: u32, first: u32, count: u32, table_len: u32 }

@group(0) @binding(0) var<storage, read> x: array<u32>;
@group(0) @binding(1) var<storage, read> table: array<u32>;
@group(0) @binding(2) var<storage, read_write> out: array<u32>;
@group(0) @binding(3) var<uniform> shape: Shape;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i >= shape.words) {
        return;
    }
    let v = x[i];
    let col = i % shape.stride;
    var o = v;
    if (col >= shape.first && col < shape.first + shape.count && v < shape.table_len) {
        o = table[v];
    }
    out[i] = o;
}
