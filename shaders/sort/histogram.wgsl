// Digit histogram of each tile: hist[digit * ntiles + tile], the digit-major order whose
// exclusive scan is every (digit, tile)'s first output position. Keys are read as vec4
// (4 bytes per key, coalesced); counting uses u32 atomics in workgroup memory.
#import common/index.wgsl
#import sort/common.wgsl

// Keys per tile: the scatter kernel's tile (nodes/sort.rs sets it per path).
override TILE: u32 = 3840u;

@group(0) @binding(0) var<storage, read> keys: array<vec4<u32>>;
@group(0) @binding(1) var<storage, read_write> hist: array<u32>;
@group(0) @binding(2) var<uniform> cfg: Pass;

var<workgroup> bins: array<atomic<u32>, 256>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) t: u32) {
    let tile = flat_index(wid, nwg, 0u, 1u);
    if (tile >= cfg.ntiles) {
        return;
    }
    atomicStore(&bins[t], 0u);
    workgroupBarrier();
    // TILE is a multiple of 4, so every tile starts on a vec4.
    let q0 = tile * (TILE / 4u);
    let count = min(TILE, cfg.n - tile * TILE);
    for (var i = t; 4u * i < count; i += 256u) {
        let k = keys[q0 + i];
        if (4u * i + 4u <= count) {
            atomicAdd(&bins[digit_of(k.x, cfg)], 1u);
            atomicAdd(&bins[digit_of(k.y, cfg)], 1u);
            atomicAdd(&bins[digit_of(k.z, cfg)], 1u);
            atomicAdd(&bins[digit_of(k.w, cfg)], 1u);
        } else {
            for (var c = 0u; 4u * i + c < count; c++) {
                atomicAdd(&bins[digit_of(k[c], cfg)], 1u);
            }
        }
    }
    workgroupBarrier();
    if (t < cfg.radix) {
        hist[t * cfg.ntiles + tile] = atomicLoad(&bins[t]);
    }
}
