// Tile paths (nodes/sort.rs): where each tile's keys of each digit go,
//   offsets[d * stride + tile] = (keys whose digit is below d, from the digit totals)
//                              + (keys of digit d in earlier tiles, a scan of row d),
// the exclusive scan of the digit-major counts in one dispatch instead of three: one
// workgroup per digit scans its row in chunks of 1024 tile counts (a vec4 per thread,
// subgroup scans), carrying the sum from chunk to chunk. Rows are short (a tile per 1024
// to 4096 keys), so this reads and writes 2 words per tile and digit.
#import common/index.wgsl
#import sort/common.wgsl

@group(0) @binding(0) var<storage, read> counts: array<vec4<u32>>;
@group(0) @binding(1) var<storage, read> totals: array<u32>;
@group(0) @binding(2) var<storage, read_write> offsets: array<vec4<u32>>;
@group(0) @binding(3) var<uniform> cfg: Pass;

// Subgroup totals of the workgroup scan (at most 64 subgroups).
var<workgroup> partial: array<u32, 64>;

// (exclusive prefix of x over the workgroup, workgroup total).
fn wg_scan(x: u32, sg: u32, nsg: u32, lane: u32, sg_size: u32) -> vec2<u32> {
    let ex = subgroupExclusiveAdd(x);
    let sum = subgroupAdd(x);
    if (lane == 0u) {
        partial[sg] = sum;
    }
    workgroupBarrier();
    var below = 0u;
    var all = 0u;
    for (var c = 0u; c < nsg; c += sg_size) {
        let k = c + lane;
        var v = 0u;
        if (k < nsg) {
            v = partial[k];
        }
        below += subgroupAdd(select(0u, v, k < sg));
        all += subgroupAdd(v);
    }
    workgroupBarrier();
    return vec2<u32>(below + ex, all);
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(subgroup_id) sg: u32, @builtin(num_subgroups) nsg: u32,
        @builtin(subgroup_size) sg_size: u32, @builtin(subgroup_invocation_id) lane: u32) {
    let d = flat_index(wid, nwg, 0u, 1u);
    if (d >= cfg.radix) {
        return;
    }
    let t = sg * sg_size + lane;
    var smaller = 0u;
    if (t < d) {
        smaller = totals[cfg.index * 256u + t];
    }
    var carry = wg_scan(smaller, sg, nsg, lane, sg_size).y;
    let row = d * (cfg.stride / 4u);
    for (var c = 0u; c < cfg.stride; c += 1024u) {
        // Tiles 4q .. 4q + 3 of the row; the padding past ntiles holds no counts.
        let q = c / 4u + t;
        var v = vec4<u32>(0u);
        if (4u * q < cfg.stride) {
            v = counts[row + q];
        }
        let tiles = vec4<u32>(4u * q) + vec4<u32>(0u, 1u, 2u, 3u);
        v = select(vec4<u32>(0u), v, tiles < vec4<u32>(cfg.ntiles));
        let scan = wg_scan((v.x + v.y) + (v.z + v.w), sg, nsg, lane, sg_size);
        let p = carry + scan.x;
        if (4u * q < cfg.stride) {
            offsets[row + q] = vec4<u32>(p, p + v.x, p + v.x + v.y, p + v.x + v.y + v.z);
        }
        carry += scan.y;
    }
}
