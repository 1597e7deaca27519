// The start of an evaluation of shaders/disks/flip.wgsl (its rounds then flip in place): the mesh copied to the output in
// 16-byte words (a quarter of the threads and loads of a word-wise copy; the mesh's 12N
// words are 3N of them), every claim to 0xFFFFFFFF, both arrays of marks and the two counts
// to 0. Where the output is the input's buffer (in place: nodes/disks/flip.rs), quads is 0
// and `mesh` a stand-in, unread.
#import common/index.wgsl

struct Params { quads: u32, triangles: u32 }

@group(0) @binding(0) var<storage, read> mesh: array<vec4<u32>>;
@group(0) @binding(1) var<storage, read_write> out: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read_write> claims: array<u32>;
@group(0) @binding(3) var<storage, read_write> count: array<u32>;
@group(0) @binding(4) var<uniform> params: Params;
@group(0) @binding(5) var<storage, read_write> marks_a: array<u32>;
@group(0) @binding(6) var<storage, read_write> marks_b: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i < params.quads) {
        out[i] = mesh[i];
    }
    if (i < params.triangles) {
        claims[i] = 0xFFFFFFFFu;
        marks_a[i] = 0u;
        marks_b[i] = 0u;
    }
    if (i < 2u) {
        count[i] = 0u;
    }
}
