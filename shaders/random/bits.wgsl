// Raw Philox4x32-10 words: out[i] is word i % 4 of the block for element i (see
// common/philox.wgsl for the key and counter convention).
#import common/index.wgsl
#import common/philox.wgsl

struct Params { count: u32, seed_lo: u32, seed_hi: u32, stream: u32 }

@group(0) @binding(0) var<storage, read_write> out: array<u32>;
@group(0) @binding(1) var<storage, read> clock: array<u32>;
@group(0) @binding(2) var<uniform> prm: Params;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i < prm.count) {
        let w = philox_block(i, clock[0], prm.seed_lo, prm.seed_hi, prm.stream);
        out[i] = w[i & 3u];
    }
}
