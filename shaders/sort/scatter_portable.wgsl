// One radix-sort pass over 4-bit digits without subgroup operations. Thread t owns keys
// t * KPT .. t * KPT + KPT - 1 of its tile (so thread, then j, is key order) and counts
// their digits in sixteen 16-bit counters; one workgroup scan of those counters gives
// every key its stable rank. Keys and payload pass through workgroup memory both ways,
// so global reads and writes stay coalesced.
//
// Per key and pass: 4 bytes read by `histogram`, 8 read and 8 written here; 4-bit digits
// take twice the passes of the subgroup path.
#import common/index.wgsl
#import sort/common.wgsl

// Keys per thread and per tile (256 * KPT); nodes/sort.rs mirrors TILE.
const KPT: u32 = 8u;
const TILE: u32 = 2048u;
const RADIX: u32 = 16u;

@group(0) @binding(0) var<storage, read> keys_in: array<u32>;
@group(0) @binding(1) var<storage, read> vals_in: array<u32>;
@group(0) @binding(2) var<storage, read> offsets: array<u32>;
@group(0) @binding(3) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(4) var<storage, read_write> vals_out: array<u32>;
@group(0) @binding(5) var<uniform> cfg: Pass;

// Keys and payload of the tile; while ranking, the threads' counters: word w of thread t
// at w * 256 + t (digits 2w and 2w + 1), 8 * 256 = TILE words.
var<workgroup> stage: array<u32, TILE>;
// Totals of 8-counter segments of each row of counters.
var<workgroup> seg: array<u32, 256>;
var<workgroup> row_total: array<u32, 8>;
var<workgroup> start: array<u32, RADIX>;
// Output start minus tile start of each digit.
var<workgroup> move_by: array<u32, RADIX>;

fn half16(w: u32, d: u32) -> u32 {
    return (w >> ((d & 1u) * 16u)) & 0xffffu;
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) t: u32) {
    let tile = flat_index(wid, nwg, 0u, 1u);
    if (tile >= cfg.ntiles) {
        return;
    }
    let base = tile * TILE;
    let valid = min(TILE, cfg.n - base);

    for (var j = 0u; j < KPT; j++) {
        let i = j * 256u + t;
        if (i < valid) {
            stage[i] = keys_in[base + i];
        }
    }
    workgroupBarrier();
    // Keys past the end take the largest digit and, being last, rank after all others.
    var key: array<u32, KPT>;
    var dig: array<u32, KPT>;
    var cnt: array<u32, 8>;
    for (var j = 0u; j < KPT; j++) {
        let i = t * KPT + j;
        dig[j] = RADIX - 1u;
        if (i < valid) {
            key[j] = stage[i];
            dig[j] = digit_of(key[j], cfg);
        }
        cnt[dig[j] >> 1u] += 1u << ((dig[j] & 1u) * 16u);
    }
    workgroupBarrier();
    for (var w = 0u; w < 8u; w++) {
        stage[w * 256u + t] = cnt[w];
    }
    workgroupBarrier();

    // Exclusive scan of each row of 256 counter words: 32 threads per row, 8 words each.
    let r = t / 32u;
    let s = t % 32u;
    let e0 = r * 256u + s * 8u;
    var run = 0u;
    for (var e = 0u; e < 8u; e++) {
        let c = stage[e0 + e];
        stage[e0 + e] = run;
        run += c;
    }
    seg[t] = run;
    workgroupBarrier();
    var before = 0u;
    for (var k = 0u; k < s; k++) {
        before += seg[r * 32u + k];
    }
    for (var e = 0u; e < 8u; e++) {
        stage[e0 + e] += before;
    }
    if (s == 31u) {
        row_total[r] = before + run;
    }
    workgroupBarrier();
    if (t < RADIX) {
        var acc = 0u;
        for (var d = 0u; d < t; d++) {
            acc += half16(row_total[d >> 1u], d);
        }
        start[t] = acc;
        if (t < cfg.radix) {
            move_by[t] = offsets[t * cfg.ntiles + tile] - acc;
        }
    }
    workgroupBarrier();

    var mine: array<u32, 8>;
    for (var w = 0u; w < 8u; w++) {
        mine[w] = stage[w * 256u + t];
    }
    var rank: array<u32, KPT>;
    for (var j = 0u; j < KPT; j++) {
        let d = dig[j];
        rank[j] = start[d] + half16(mine[d >> 1u], d);
        mine[d >> 1u] += 1u << ((d & 1u) * 16u);
    }
    workgroupBarrier();

    for (var j = 0u; j < KPT; j++) {
        stage[rank[j]] = key[j];
    }
    workgroupBarrier();
    var dest: array<u32, KPT>;
    for (var j = 0u; j < KPT; j++) {
        let i = j * 256u + t;
        if (i < valid) {
            let k = stage[i];
            dest[j] = move_by[digit_of(k, cfg)] + i;
            keys_out[dest[j]] = k;
        }
    }
    workgroupBarrier();

    // Payload: coalesced in, into this thread's order, to the ranks, coalesced out.
    for (var j = 0u; j < KPT; j++) {
        let i = j * 256u + t;
        if (i < valid) {
            if (cfg.first != 0u) {
                stage[i] = base + i;
            } else {
                stage[i] = vals_in[base + i];
            }
        }
    }
    workgroupBarrier();
    var val: array<u32, KPT>;
    for (var j = 0u; j < KPT; j++) {
        val[j] = stage[t * KPT + j];
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
