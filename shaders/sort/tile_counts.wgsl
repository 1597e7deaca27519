// Tile paths (nodes/sort.rs): the digit count of each tile, counts[digit * stride + tile]
// (rows padded to a multiple of 4 tiles, so that `offsets` reads them as vec4), and each
// digit's total over all tiles added into totals[index * 256 + digit] (zeroed before the
// first pass), from which `offsets` learns where a digit's keys start without reading
// the other digits' rows.
//
// Keys are read as vec4 and every load of a thread is issued before the first is counted,
// so a workgroup has its whole tile in flight at once (4 bytes per key and pass).
#import common/index.wgsl
#import sort/common.wgsl

// vec4 loads per thread (1 to 4): the tile holds 1024 * QUADS keys, the scatter kernel's.
override QUADS: u32 = 4u;

@group(0) @binding(0) var<storage, read> keys: array<vec4<u32>>;
@group(0) @binding(1) var<storage, read_write> counts: array<u32>;
@group(0) @binding(2) var<storage, read_write> totals: array<atomic<u32>>;
@group(0) @binding(3) var<uniform> cfg: Pass;

var<workgroup> bins: array<atomic<u32>, 256>;

// Keys of the tile's vec4 number `q` that exist (0 to 4), out of the tile's `count`.
fn live(q: u32, count: u32) -> u32 {
    return min(4u, count - min(4u * q, count));
}

fn load(q0: u32, q: u32, n: u32) -> vec4<u32> {
    if (n == 0u) {
        return vec4<u32>(0u);
    }
    return keys[q0 + q];
}

fn count(k: vec4<u32>, n: u32) {
    if (n > 0u) {
        atomicAdd(&bins[digit_of(k.x, cfg)], 1u);
    }
    if (n > 1u) {
        atomicAdd(&bins[digit_of(k.y, cfg)], 1u);
    }
    if (n > 2u) {
        atomicAdd(&bins[digit_of(k.z, cfg)], 1u);
    }
    if (n > 3u) {
        atomicAdd(&bins[digit_of(k.w, cfg)], 1u);
    }
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) t: u32) {
    let tile = flat_index(wid, nwg, 0u, 1u);
    if (tile >= cfg.ntiles) {
        return;
    }
    let tile_keys = 1024u * QUADS;
    let q0 = tile * (tile_keys / 4u);
    let total = min(tile_keys, cfg.n - tile * tile_keys);
    // vec4 number r * 256 + t of the tile, written out per r (no loop, no array).
    let n0 = live(t, total);
    let k0 = load(q0, t, n0);
    var n1 = 0u;
    var k1 = vec4<u32>(0u);
    var n2 = 0u;
    var k2 = vec4<u32>(0u);
    var n3 = 0u;
    var k3 = vec4<u32>(0u);
    if (QUADS > 1u) {
        n1 = live(256u + t, total);
        k1 = load(q0, 256u + t, n1);
    }
    if (QUADS > 2u) {
        n2 = live(512u + t, total);
        k2 = load(q0, 512u + t, n2);
    }
    if (QUADS > 3u) {
        n3 = live(768u + t, total);
        k3 = load(q0, 768u + t, n3);
    }
    atomicStore(&bins[t], 0u);
    workgroupBarrier();
    count(k0, n0);
    count(k1, n1);
    count(k2, n2);
    count(k3, n3);
    workgroupBarrier();
    if (t < cfg.radix) {
        let c = atomicLoad(&bins[t]);
        counts[t * cfg.stride + tile] = c;
        if (c != 0u) {
            atomicAdd(&totals[cfg.index * 256u + t], c);
        }
    }
}
