// Sets `quads` groups of four 4-byte words to `value`: 16-byte stores (a quarter of the
// threads and store instructions of engine/fill.wgsl) for buffers whose size is a
// multiple of 16 bytes, as every engine buffer is (words past the value's own, up to 3,
// lie in its buffer's padding or in slack no other live value uses).
#import common/index.wgsl

struct Fill { quads: u32, value: u32 }

@group(0) @binding(0) var<storage, read_write> dst: array<vec4<u32>>;
@group(0) @binding(1) var<uniform> fill: Fill;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i < fill.quads) {
        dst[i] = vec4<u32>(fill.value);
    }
}
