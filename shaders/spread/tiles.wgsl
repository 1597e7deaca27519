// The set-up kernels of tiled spreading (nodes/spread/tilegen.rs writes the spreading
// kernel itself).
//
// Tiled spreading (cuFINUFFT's shared-memory method): the grid is cut into tiles of
// TILE^3 cells, each particle is filed under the tile of its anchor (its first support
// cell, wrapped), and one workgroup per tile adds its particles' supports into the padded
// tile, (TILE + NS - 1)^3 cells, in workgroup memory, then adds each padded cell to the
// grid once. Workgroup memory has integer atomics only (wgpu has no workgroup float
// atomics), so the tile holds fixed-point sums, scaled per tile so that no sum can
// overflow (see the generated kernel). The set-up is a counting sort by tile:
//   tiles_rank:  each particle's tile, its anchor inside the tile and its rank among the
//                tile's particles (one u32 atomic per particle);
//   tiles_scan:  the first list slot of each tile (exclusive scan, one workgroup);
//   tiles_place: the particle at each list slot.
#import common/index.wgsl
#import spread/geometry.wgsl
#import scan/wg_inclusive.wgsl
#import spread/first_cell.wgsl

override NS: u32 = 4u;
override TILE: u32 = 8u;

// Tiles per axis (w: all tiles).
struct Tiles {
    nt: vec4<u32>,
}

@group(0) @binding(0) var<storage, read> pos: array<f32>;
@group(0) @binding(1) var<uniform> geo: Geometry;
@group(0) @binding(2) var<uniform> tiles: Tiles;
@group(0) @binding(3) var<storage, read_write> count: array<atomic<u32>>;
@group(0) @binding(4) var<storage, read_write> start: array<u32>;
// Per particle: its tile, its rank in the tile's list, its anchor inside the tile
// (x | y << 8 | z << 16), and per list slot the particle.
@group(0) @binding(5) var<storage, read_write> ptile: array<u32>;
@group(0) @binding(6) var<storage, read_write> rank: array<u32>;
@group(0) @binding(7) var<storage, read_write> local_anchor: array<u32>;
@group(0) @binding(8) var<storage, read_write> order: array<u32>;

@compute @workgroup_size(256)
fn tiles_rank(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
              @builtin(local_invocation_index) lid: u32) {
    let p = flat_index(wid, nwg, lid, 256u);
    if (p >= geo.count) {
        return;
    }
    var tile = 0u;
    var stride = 1u;
    var packed = 0u;
    for (var a = 0u; a < 3u; a = a + 1u) {
        let anchor = tile_anchor(pos[p * 3u + a], a);
        tile = tile + (anchor / TILE) * stride;
        stride = stride * tiles.nt[a];
        packed = packed | ((anchor % TILE) << (8u * a));
    }
    ptile[p] = tile;
    local_anchor[p] = packed;
    rank[p] = atomicAdd(&count[tile], 1u);
}

// The wrapped first support cell of coordinate x on axis a: the same arithmetic as the
// tile kernel's weights (first_cell), so a particle's weights start at its anchor.
fn tile_anchor(x: f32, a: u32) -> u32 {
    return wrap_cell(first_cell(centre_units(x, a, geo)), geo.n[a]);
}

alias Elem = u32;
const WG: u32 = 256u;
var<workgroup> ping: array<u32, 512>;

@compute @workgroup_size(256)
fn tiles_scan(@builtin(local_invocation_index) lid: u32) {
    let n = tiles.nt.w;
    let chunk = (n + 255u) / 256u;
    let first = min(lid * chunk, n);
    let last = min(first + chunk, n);
    var total = 0u;
    for (var i = first; i < last; i = i + 1u) {
        total = total + atomicLoad(&count[i]);
    }
    let half = wg_inclusive(lid, total);
    var run = ping[half + lid] - total;
    for (var i = first; i < last; i = i + 1u) {
        start[i] = run;
        run = run + atomicLoad(&count[i]);
    }
}

@compute @workgroup_size(256)
fn tiles_place(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
               @builtin(local_invocation_index) lid: u32) {
    let p = flat_index(wid, nwg, lid, 256u);
    if (p >= geo.count) {
        return;
    }
    order[start[ptile[p]] + rank[p]] = p;
}
