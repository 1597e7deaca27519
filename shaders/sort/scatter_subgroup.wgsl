// One radix-sort pass over 8-bit digits, subgroup path: stable ranking inside a tile by
// warp-level multi-split (each key finds the lanes holding the same digit with 8
// subgroupBallots), then the tile is reordered in workgroup memory so that the global
// writes of each digit's run are contiguous.
//
// Per key and pass: 4 bytes read by `histogram`, 8 read and 8 written here (key and
// payload; the first pass reads no payload), and one u32 of histogram per digit and tile.
// Works for any subgroup size from 4 to 128 that fills its subgroups; invocations are
// placed by (subgroup_id, subgroup_invocation_id), never by local_invocation_index.
#import common/index.wgsl
#import sort/common.wgsl
#import sort/ballot.wgsl

// Keys per thread and per tile (256 * KPT); nodes/sort.rs mirrors TILE.
const KPT: u32 = 15u;
const TILE: u32 = 3840u;
// Words of per-subgroup counters: 128 per subgroup, for 256 / (smallest subgroup size)
// subgroups (set by nodes/sort.rs from the device's subgroup sizes).
override COUNTER_WORDS: u32 = 4096u;

@group(0) @binding(0) var<storage, read> keys_in: array<u32>;
@group(0) @binding(1) var<storage, read> vals_in: array<u32>;
@group(0) @binding(2) var<storage, read> offsets: array<u32>;
@group(0) @binding(3) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(4) var<storage, read_write> vals_out: array<u32>;
@group(0) @binding(5) var<uniform> cfg: Pass;

// Per-subgroup digit counters, two 16-bit counters per word (digit 2w low, 2w + 1 high;
// a subgroup holds at most 128 * KPT keys); after ranking, the first 256 words hold
// each digit's output start minus its tile start.
var<workgroup> counts: array<atomic<u32>, COUNTER_WORDS>;
// The tile's digit starts, then its keys and then its payload in sorted order.
var<workgroup> stage: array<u32, TILE>;
// Subgroup totals of the workgroup scan.
var<workgroup> partial: array<u32, 64>;

// Exclusive scan of one u32 per invocation over the workgroup.
fn wg_exclusive(x: u32, sg: u32, nsg: u32, lane: u32, sg_size: u32) -> u32 {
    let ex = subgroupExclusiveAdd(x);
    let total = subgroupAdd(x);
    if (lane == 0u) {
        partial[sg] = total;
    }
    workgroupBarrier();
    var below = 0u;
    for (var c = 0u; c < nsg; c += sg_size) {
        let k = c + lane;
        var v = 0u;
        if (k < sg) {
            v = partial[k];
        }
        below += subgroupAdd(v);
    }
    workgroupBarrier();
    return below + ex;
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(subgroup_id) sg: u32, @builtin(num_subgroups) nsg: u32,
        @builtin(subgroup_size) sg_size: u32, @builtin(subgroup_invocation_id) lane: u32) {
    let tile = flat_index(wid, nwg, 0u, 1u);
    if (tile >= cfg.ntiles) {
        return;
    }
    let t = sg * sg_size + lane;
    let base = tile * TILE;
    let valid = min(TILE, cfg.n - base);

    for (var i = t; i < nsg * 128u; i += 256u) {
        atomicStore(&counts[i], 0u);
    }

    // Subgroup sg owns keys [first, first + sg_size * KPT), lane-striped so that each
    // load is coalesced and (j, lane) order is key order.
    let first = base + sg * sg_size * KPT + lane;
    var key: array<u32, KPT>;
    var val: array<u32, KPT>;
    for (var j = 0u; j < KPT; j++) {
        let i = first + j * sg_size;
        if (i < cfg.n) {
            key[j] = keys_in[i];
            if (cfg.first != 0u) {
                val[j] = i;
            } else {
                val[j] = vals_in[i];
            }
        }
    }
    workgroupBarrier();

    // Rank among the equal digits of the subgroup, in key order. Keys past the end take
    // digit 255 and, being last in key order, rank after every real key.
    let below = lanes_below(lane);
    let row = sg * 128u;
    var rank: array<u32, KPT>;
    for (var j = 0u; j < KPT; j++) {
        var d = 255u;
        if (first + j * sg_size < cfg.n) {
            d = digit_of(key[j], cfg);
        }
        let eq = peers(d, subgroupBallot(true));
        let lower = popcount(eq & below);
        let sh = (d & 1u) * 16u;
        var before = 0u;
        if (lower == 0u) {
            let old = atomicAdd(&counts[row + (d >> 1u)], popcount(eq) << sh);
            before = (old >> sh) & 0xffffu;
        }
        rank[j] = subgroupShuffle(before, lowest_lane(eq)) + lower;
    }
    workgroupBarrier();

    // Counters -> per-subgroup starts (exclusive over subgroups); pair = the tile's count
    // of digits 2t and 2t + 1 (16 bits each: a tile holds at most TILE < 2^16 keys).
    var pair = 0u;
    if (t < 128u) {
        for (var s = 0u; s < nsg; s++) {
            let c = atomicLoad(&counts[s * 128u + t]);
            atomicStore(&counts[s * 128u + t], pair);
            pair += c;
        }
    }
    let low = pair & 0xffffu;
    let start = wg_exclusive(low + (pair >> 16u), sg, nsg, lane, sg_size);
    if (t < 128u) {
        stage[2u * t] = start;
        stage[2u * t + 1u] = start + low;
    }
    workgroupBarrier();

    for (var j = 0u; j < KPT; j++) {
        var d = 255u;
        if (first + j * sg_size < cfg.n) {
            d = digit_of(key[j], cfg);
        }
        let c = atomicLoad(&counts[row + (d >> 1u)]);
        rank[j] += stage[d] + ((c >> ((d & 1u) * 16u)) & 0xffffu);
    }
    var move_by = 0u;
    if (t < cfg.radix) {
        move_by = offsets[t * cfg.ntiles + tile] - stage[t];
    }
    workgroupBarrier();

    // Keys through workgroup memory in sorted order, then out in runs per digit.
    if (t < cfg.radix) {
        atomicStore(&counts[t], move_by);
    }
    for (var j = 0u; j < KPT; j++) {
        stage[rank[j]] = key[j];
    }
    workgroupBarrier();
    var dest: array<u32, KPT>;
    for (var j = 0u; j < KPT; j++) {
        let i = j * 256u + t;
        if (i < valid) {
            let k = stage[i];
            dest[j] = atomicLoad(&counts[digit_of(k, cfg)]) + i;
            keys_out[dest[j]] = k;
        }
    }
    workgroupBarrier();
    for (var j = 0u; j < KPT; j++) {
        stage[rank[j]] = val[j];
    }
    workgroupBarrier();
    for (var j = 0u; j < KPT; j++) {
        let i = j * 256u + t;
        if (i < valid) {
            vals_out[dest[j]] = stage[i];
        }
    }
}
