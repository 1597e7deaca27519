// One radix-sort pass over 8-bit digits, tile path (nodes/sort.rs has the variants): the
// stable ranking of scatter_subgroup.wgsl (8 subgroupBallots per key find the lanes with
// the same digit; one lane per digit bumps a per-subgroup counter), rebuilt around one
// constraint: every loop over a thread's keys is written out, so keys, ranks and payload
// stay in registers with all of a thread's loads in flight at once. naga emits every
// loop with its exit test inside, which drivers often leave rolled (gfx-rs/wgpu#6521);
// a rolled loop over a register array keeps the array in local memory and waits on each
// load before issuing the next. The subgroup kernel, written with such loops, moved
// 430-510 GB/s on an H100, and its payload reads (passes 2 to 4) cost what about one
// scalar load in flight per thread would.
//
// A thread holds 4 * QUADS keys as QUADS vec4 (QUADS = 1..4, a tile of 1024 * QUADS keys):
//   1. load keys (and this tile's output starts) from global memory, zero the counters;
//   2. rank each key among the earlier keys of its subgroup with the same digit;
//   3. scan the per-subgroup counters into each subgroup's start per digit in the tile;
//   4. place keys in the stage in sorted order; load the payload meanwhile;
//   5. write the sorted keys out (each digit a contiguous run), keeping their digits;
//   6. place the payload in the stage by the same ranks and write it out the same way.
// Bytes per key and pass: 4 read by tile_counts, 8 read and 8 written here (4 read in the
// first pass, whose payload is the key's index), and 4 per digit and tile for its output
// start. Works for any subgroup size from 4 to 128 that fills its subgroups.
#import common/index.wgsl
#import sort/common.wgsl
#import sort/ballot.wgsl

// vec4 of keys per thread (1 to 4) and keys per tile (1024 * QUADS; set together by
// nodes/sort.rs).
override QUADS: u32 = 4u;
override TILE: u32 = 4096u;
// Words of `region`: the larger of 128 per subgroup (for the most subgroups a workgroup
// can have) and TILE / 4 + 256.
override REGION_WORDS: u32 = 1280u;

@group(0) @binding(0) var<storage, read> keys_in: array<u32>;
@group(0) @binding(1) var<storage, read> vals_in: array<u32>;
@group(0) @binding(2) var<storage, read> offsets: array<u32>;
@group(0) @binding(3) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(4) var<storage, read_write> vals_out: array<u32>;
@group(0) @binding(5) var<uniform> cfg: Pass;

// The tile in sorted order: its keys, then its payload. Before that, the first 64 words
// hold the subgroup totals of the workgroup scan.
var<workgroup> stage: array<u32, TILE>;
// Until the keys are placed: per-subgroup digit counters, a row of 128 words per
// subgroup, two 16-bit counters a word (digit 2w low, 2w + 1 high; a tile holds fewer
// than 2^16 keys). Then: the sorted keys' digits, four to a word (word q * 256 + t holds
// those of positions (4q + c) * 256 + t, c = 0..3), and at TILE / 4 each digit's output
// start minus its start in the tile. Sharing the words keeps lavapipe's subgroups of 8
// (32 rows) inside 32 KiB with a tile of 4096 keys.
var<workgroup> region: array<atomic<u32>, REGION_WORDS>;

// Four keys of this lane, `step` apart from global index g. Past the end of the input,
// all-ones keys: the largest digit of every pass and the last keys in tile order, so
// they rank after every real key.
fn load_keys(g: u32, step: u32) -> vec4<u32> {
    var k = vec4<u32>(0xffffffffu);
    if (g < cfg.n) {
        k.x = keys_in[g];
    }
    if (g + step < cfg.n) {
        k.y = keys_in[g + step];
    }
    if (g + 2u * step < cfg.n) {
        k.z = keys_in[g + 2u * step];
    }
    if (g + 3u * step < cfg.n) {
        k.w = keys_in[g + 3u * step];
    }
    return k;
}

// The payload of the same four keys: their input indices in the first pass.
fn load_vals(g: u32, step: u32) -> vec4<u32> {
    let i = vec4<u32>(g) + vec4<u32>(0u, 1u, 2u, 3u) * step;
    if (cfg.first != 0u) {
        return i;
    }
    var v = vec4<u32>(0u);
    if (i.x < cfg.n) {
        v.x = vals_in[i.x];
    }
    if (i.y < cfg.n) {
        v.y = vals_in[i.y];
    }
    if (i.z < cfg.n) {
        v.z = vals_in[i.z];
    }
    if (i.w < cfg.n) {
        v.w = vals_in[i.w];
    }
    return v;
}

// Rank of `key` among the keys of this subgroup ranked so far with its digit, plus the
// lanes below with it: the lowest such lane adds them all to the subgroup's counter.
fn rank_key(key: u32, row: u32, lanes: vec4<u32>, below: vec4<u32>) -> u32 {
    let d = digit_of(key, cfg);
    let eq = peers(d, lanes);
    let lower = popcount(eq & below);
    let sh = (d & 1u) * 16u;
    var before = 0u;
    if (lower == 0u) {
        let old = atomicAdd(&region[row + (d >> 1u)], popcount(eq) << sh);
        before = (old >> sh) & 0xffffu;
    }
    return subgroupShuffle(before, lowest_lane(eq)) + lower;
}

// Ranks of four keys, in key order (stability depends on it).
fn rank_keys(k: vec4<u32>, row: u32, lanes: vec4<u32>, below: vec4<u32>) -> vec4<u32> {
    let x = rank_key(k.x, row, lanes, below);
    let y = rank_key(k.y, row, lanes, below);
    let z = rank_key(k.z, row, lanes, below);
    let w = rank_key(k.w, row, lanes, below);
    return vec4<u32>(x, y, z, w);
}

// Position in the sorted tile: the rank plus the subgroup's start for the key's digit.
fn position(key: u32, rank: u32, row: u32) -> u32 {
    let d = digit_of(key, cfg);
    let w = atomicLoad(&region[row + (d >> 1u)]);
    return rank + ((w >> ((d & 1u) * 16u)) & 0xffffu);
}

// Places four keys in the stage; returns their positions (for the payload).
fn place_keys(k: vec4<u32>, r: vec4<u32>, row: u32) -> vec4<u32> {
    let p = vec4<u32>(position(k.x, r.x, row), position(k.y, r.y, row),
                      position(k.z, r.z, row), position(k.w, r.w, row));
    stage[p.x] = k.x;
    stage[p.y] = k.y;
    stage[p.z] = k.z;
    stage[p.w] = k.w;
    return p;
}

fn place_vals(p: vec4<u32>, v: vec4<u32>) {
    stage[p.x] = v.x;
    stage[p.y] = v.y;
    stage[p.z] = v.z;
    stage[p.w] = v.w;
}

// Output index of sorted position i of digit d.
fn destination(d: u32, i: u32) -> u32 {
    return atomicLoad(&region[TILE / 4u + d]) + i;
}

// Writes the sorted key at position i (if it is a key) and returns its digit.
fn store_key(i: u32, valid: u32) -> u32 {
    let k = stage[i];
    let d = digit_of(k, cfg);
    if (i < valid) {
        keys_out[destination(d, i)] = k;
    }
    return d;
}

// Sorted positions (4q + c) * 256 + t, c = 0..3: consecutive threads write consecutive
// positions, so each digit's run goes out as contiguous stores. Their digits are kept
// for the payload, whose stage replaces the keys.
fn store_keys(q: u32, t: u32, valid: u32) {
    let i = 1024u * q + t;
    let digits = store_key(i, valid) | (store_key(i + 256u, valid) << 8u)
        | (store_key(i + 512u, valid) << 16u) | (store_key(i + 768u, valid) << 24u);
    atomicStore(&region[256u * q + t], digits);
}

fn store_val(i: u32, d: u32, valid: u32) {
    if (i < valid) {
        vals_out[destination(d & 0xffu, i)] = stage[i];
    }
}

fn store_vals(q: u32, t: u32, valid: u32) {
    let i = 1024u * q + t;
    let digits = atomicLoad(&region[256u * q + t]);
    store_val(i, digits, valid);
    store_val(i + 256u, digits >> 8u, valid);
    store_val(i + 512u, digits >> 16u, valid);
    store_val(i + 768u, digits >> 24u, valid);
}

// Exclusive scan of one u32 per invocation over the workgroup (subgroup totals in the
// stage, which holds nothing yet).
fn wg_exclusive(x: u32, sg: u32, nsg: u32, lane: u32, sg_size: u32) -> u32 {
    let ex = subgroupExclusiveAdd(x);
    let total = subgroupAdd(x);
    if (lane == 0u) {
        stage[sg] = total;
    }
    workgroupBarrier();
    var below = 0u;
    for (var c = 0u; c < nsg; c += sg_size) {
        let k = c + lane;
        var v = 0u;
        if (k < sg) {
            v = stage[k];
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

    // 1. Subgroup sg owns keys [sg * sg_size * 4 * QUADS, ...) of the tile, lane-striped:
    // its lane's j-th key is at g + j * sg_size, so (j, lane) is key order and every load
    // instruction of a subgroup reads consecutive words.
    let g = base + sg * sg_size * 4u * QUADS + lane;
    let quad = 4u * sg_size;
    // Thread t < 128 finishes digits 2t and 2t + 1; their output starts come early.
    var out_start = vec2<u32>(0u);
    if (2u * t < cfg.radix) {
        out_start.x = offsets[2u * t * cfg.stride + tile];
    }
    if (2u * t + 1u < cfg.radix) {
        out_start.y = offsets[(2u * t + 1u) * cfg.stride + tile];
    }
    let k0 = load_keys(g, sg_size);
    var k1 = vec4<u32>(0u);
    var k2 = vec4<u32>(0u);
    var k3 = vec4<u32>(0u);
    if (QUADS > 1u) {
        k1 = load_keys(g + quad, sg_size);
    }
    if (QUADS > 2u) {
        k2 = load_keys(g + 2u * quad, sg_size);
    }
    if (QUADS > 3u) {
        k3 = load_keys(g + 3u * quad, sg_size);
    }
    for (var i = t; i < nsg * 128u; i += 256u) {
        atomicStore(&region[i], 0u);
    }
    workgroupBarrier();

    // 2. Ranks within the subgroup.
    let row = sg * 128u;
    let lanes = subgroupBallot(true);
    let below = lanes_below(lane);
    let r0 = rank_keys(k0, row, lanes, below);
    var r1 = vec4<u32>(0u);
    var r2 = vec4<u32>(0u);
    var r3 = vec4<u32>(0u);
    if (QUADS > 1u) {
        r1 = rank_keys(k1, row, lanes, below);
    }
    if (QUADS > 2u) {
        r2 = rank_keys(k2, row, lanes, below);
    }
    if (QUADS > 3u) {
        r3 = rank_keys(k3, row, lanes, below);
    }
    workgroupBarrier();

    // 3. Counter row s of digit pair t -> start of subgroup s's keys of those digits:
    // the digits' start in the tile plus the counts of the subgroups before s.
    var pair = 0u;
    if (t < 128u) {
        for (var s = 0u; s < nsg; s++) {
            pair += atomicLoad(&region[s * 128u + t]);
        }
    }
    let low = pair & 0xffffu;
    let start = wg_exclusive(low + (pair >> 16u), sg, nsg, lane, sg_size);
    if (t < 128u) {
        var run = start | ((start + low) << 16u);
        for (var s = 0u; s < nsg; s++) {
            let c = atomicLoad(&region[s * 128u + t]);
            atomicStore(&region[s * 128u + t], run);
            run += c;
        }
    }
    let move_by = out_start - vec2<u32>(start, start + low);
    workgroupBarrier();

    // 4. Keys into the stage in sorted order; the payload's loads overlap what follows.
    let p0 = place_keys(k0, r0, row);
    var p1 = vec4<u32>(0u);
    var p2 = vec4<u32>(0u);
    var p3 = vec4<u32>(0u);
    if (QUADS > 1u) {
        p1 = place_keys(k1, r1, row);
    }
    if (QUADS > 2u) {
        p2 = place_keys(k2, r2, row);
    }
    if (QUADS > 3u) {
        p3 = place_keys(k3, r3, row);
    }
    let v0 = load_vals(g, sg_size);
    var v1 = vec4<u32>(0u);
    var v2 = vec4<u32>(0u);
    var v3 = vec4<u32>(0u);
    if (QUADS > 1u) {
        v1 = load_vals(g + quad, sg_size);
    }
    if (QUADS > 2u) {
        v2 = load_vals(g + 2u * quad, sg_size);
    }
    if (QUADS > 3u) {
        v3 = load_vals(g + 3u * quad, sg_size);
    }
    workgroupBarrier();
    // The counters are dead: their words take each digit's move.
    if (2u * t < cfg.radix) {
        atomicStore(&region[TILE / 4u + 2u * t], move_by.x);
    }
    if (2u * t + 1u < cfg.radix) {
        atomicStore(&region[TILE / 4u + 2u * t + 1u], move_by.y);
    }
    workgroupBarrier();

    // 5. Sorted keys out.
    store_keys(0u, t, valid);
    if (QUADS > 1u) {
        store_keys(1u, t, valid);
    }
    if (QUADS > 2u) {
        store_keys(2u, t, valid);
    }
    if (QUADS > 3u) {
        store_keys(3u, t, valid);
    }
    workgroupBarrier();

    // 6. The payload, the same way.
    place_vals(p0, v0);
    if (QUADS > 1u) {
        place_vals(p1, v1);
    }
    if (QUADS > 2u) {
        place_vals(p2, v2);
    }
    if (QUADS > 3u) {
        place_vals(p3, v3);
    }
    workgroupBarrier();
    store_vals(0u, t, valid);
    if (QUADS > 1u) {
        store_vals(1u, t, valid);
    }
    if (QUADS > 2u) {
        store_vals(2u, t, valid);
    }
    if (QUADS > 3u) {
        store_vals(3u, t, valid);
    }
}
