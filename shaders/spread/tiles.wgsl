// template: composed with a window file (window_phi).
//
// The set-up kernels of tiled spreading (nodes/spread/tilegen.rs writes the spreading
// kernel itself).
//
// The grid is cut into tiles (8 x 8 x 8 cells in 3D, 16 x 16 in 2D; the last tile
// along an axis may be shorter). Each particle is filed under the tile of its anchor,
// the first cell of its support; a counting sort lists the particles tile by tile:
//   tile_count:   the anchor and the window weights of each particle, its tile, and its
//                 rank among the tile's particles (one u32 atomic per particle);
//   tile_scan:    the first list slot of each tile (exclusive scan, one workgroup);
//   tile_scatter: the particle at each slot.
// The spreading kernel then serves one tile per workgroup from the lists of the tiles
// whose particles can reach it, and writes every cell of its tile once: no float
// atomics, and any input order.
#import common/index.wgsl
#import spread/geometry.wgsl

override NS: u32 = 4u;
override DIMS: u32 = 3u;

// Tiles per axis (w: all tiles) and cells per tile per axis.
struct Tiles {
    nt: vec4<u32>,
    size: vec4<u32>,
}

@group(0) @binding(0) var<storage, read> pos: array<f32>;
@group(0) @binding(1) var<uniform> geo: Geometry;
@group(0) @binding(2) var<uniform> tiles: Tiles;
@group(0) @binding(3) var<storage, read_write> count: array<atomic<u32>>;
@group(0) @binding(4) var<storage, read_write> start: array<u32>;
@group(0) @binding(5) var<storage, read_write> ptile: array<u32>;
@group(0) @binding(6) var<storage, read_write> rank: array<u32>;
@group(0) @binding(7) var<storage, read_write> order: array<u32>;
// Per particle: its anchor cell per axis (x, y, z) and its window weights (per unit
// length) at support index k of axis a, at p * 3 * NS + a * NS + k: the anchor and the
// weights come from one computation, so the tile lists and the weights agree.
@group(0) @binding(8) var<storage, read_write> anchors: array<vec4<u32>>;
@group(0) @binding(9) var<storage, read_write> weights: array<f32>;

@compute @workgroup_size(256)
fn tile_count(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
              @builtin(local_invocation_index) lid: u32) {
    let p = flat_index(wid, nwg, lid, 256u);
    if (p >= geo.count) {
        return;
    }
    var anchor = vec4<u32>(0u);
    var tile = 0u;
    var tile_stride = 1u;
    for (var a = 0u; a < DIMS; a = a + 1u) {
        let t = centre_units(pos[p * DIMS + a], a, geo);
        let j0 = floor(t - 0.5 * f32(NS)) + 1.0;
        for (var k = 0u; k < NS; k = k + 1u) {
            weights[(p * 3u + a) * NS + k] = window_phi(j0 + f32(k) - t, geo.win[a]) * geo.inv_h[a];
        }
        let c = wrap_cell(i32(j0), geo.n[a]);
        anchor[a] = c;
        tile = tile + (c / tiles.size[a]) * tile_stride;
        tile_stride = tile_stride * tiles.nt[a];
    }
    anchors[p] = anchor;
    ptile[p] = tile;
    rank[p] = atomicAdd(&count[tile], 1u);
}

var<workgroup> sums: array<u32, 256>;

@compute @workgroup_size(256)
fn tile_scan(@builtin(local_invocation_index) lid: u32) {
    let n = tiles.nt.w;
    let chunk = (n + 255u) / 256u;
    let first = min(lid * chunk, n);
    let last = min(first + chunk, n);
    var total = 0u;
    for (var i = first; i < last; i = i + 1u) {
        total = total + atomicLoad(&count[i]);
    }
    sums[lid] = total;
    workgroupBarrier();
    // Inclusive scan of the 256 chunk totals (Hillis-Steele).
    for (var o = 1u; o < 256u; o = o << 1u) {
        var v = 0u;
        if (lid >= o) {
            v = sums[lid - o];
        }
        workgroupBarrier();
        sums[lid] = sums[lid] + v;
        workgroupBarrier();
    }
    var run = sums[lid] - total;
    for (var i = first; i < last; i = i + 1u) {
        start[i] = run;
        run = run + atomicLoad(&count[i]);
    }
}

@compute @workgroup_size(256)
fn tile_scatter(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
                @builtin(local_invocation_index) lid: u32) {
    let p = flat_index(wid, nwg, lid, 256u);
    if (p >= geo.count) {
        return;
    }
    order[start[ptile[p]] + rank[p]] = p;
}
