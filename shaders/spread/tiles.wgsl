// The first step of tiled spreading (nodes/spread/tilegen.rs writes the spreading kernel
// itself; nodes/spread/mod.rs lists the particles tile by tile with bin_sort's counting
// sort).
//
// Tiled spreading (cuFINUFFT's shared-memory method): the grid is cut into tiles of
// TILE^3 cells, each particle is filed under the tile of its anchor (its first support
// cell, wrapped), and one workgroup per tile adds its particles' supports into the padded
// tile, (TILE + NS - 1)^3 cells, in workgroup memory, then adds each padded cell to the
// grid once. Workgroup memory has integer atomics only (wgpu has no workgroup float
// atomics), so the tile holds fixed-point sums, scaled per tile so that no sum can
// overflow (see the generated kernel). This kernel writes each particle's tile (the sort
// key) and its anchor inside the tile.
#import common/index.wgsl
#import spread/geometry.wgsl
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
// Per particle: its tile, and its anchor inside the tile (x | y << 8 | z << 16).
@group(0) @binding(3) var<storage, read_write> tile_of: array<u32>;
@group(0) @binding(4) var<storage, read_write> local_anchor: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let p = flat_index(wid, nwg, lid, 256u);
    if (p >= geo.count) {
        return;
    }
    var tile = 0u;
    var stride = 1u;
    var packed = 0u;
    for (var a = 0u; a < 3u; a = a + 1u) {
        // The same arithmetic as the tile kernel's weights (first_cell), so a particle's
        // weights start at its anchor.
        let anchor = wrap_cell(first_cell(centre_units(pos[p * 3u + a], a)), geo.n[a]);
        tile = tile + (anchor / TILE) * stride;
        stride = stride * tiles.nt[a];
        packed = packed | ((anchor % TILE) << (8u * a));
    }
    tile_of[p] = tile;
    local_anchor[p] = packed;
}
