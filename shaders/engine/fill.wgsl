// Sets `len` 4-byte words to `value` (zero before atomic accumulation, say).
#import common/index.wgsl

struct Fill { len: u32, value: u32 }

@group(0) @binding(0) var<storage, read_write> dst: array<u32>;
@group(0) @binding(1) var<uniform> fill: Fill;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i < fill.len) {
        dst[i] = fill.value;
    }
}
