// template: composed after a pair kernel (pair_term, self_term; shaders/pairs/*.wgsl).
//
// Every pair, open boundaries: each workgroup holds TILE particles i (one per thread)
// and walks the others in tiles of TILE loaded into workgroup memory.
#import common/index.wgsl

const TILE: u32 = 128u;  // nodes/pairs/mod.rs TILE

struct Shape {
    n: u32,
    cutoff2: f32,
}

@group(0) @binding(0) var<storage, read> pos: array<f32>;
@group(0) @binding(1) var<storage, read> vals: array<f32>;
@group(0) @binding(2) var<storage, read_write> out: array<f32>;
@group(0) @binding(3) var<uniform> shape: Shape;
@group(0) @binding(4) var<storage, read> pair_params: array<f32>;
@group(0) @binding(5) var<storage, read> pair_table: array<f32>;

var<workgroup> tile_pos: array<vec3<f32>, TILE>;
var<workgroup> tile_val: array<Row, TILE>;

#import pairs/values.wgsl

@compute @workgroup_size(TILE)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, TILE);
    let n = shape.n;
    let inside = i < n;
    let ii = min(i, max(n, 1u) - 1u);
    let xi = vec3<f32>(pos[3u * ii], pos[3u * ii + 1u], pos[3u * ii + 2u]);
    let vi = value_row(ii);
    var acc = self_term(xi, vi);
    let tiles = (n + TILE - 1u) / TILE;
    for (var t = 0u; t < tiles; t++) {
        let j = t * TILE + lid;
        if (j < n) {
            tile_pos[lid] = vec3<f32>(pos[3u * j], pos[3u * j + 1u], pos[3u * j + 2u]);
            tile_val[lid] = value_row(j);
        }
        workgroupBarrier();
        let count = min(TILE, n - t * TILE);
        for (var k = 0u; k < count; k++) {
            let xj = tile_pos[k];
            let r = xi - xj;
            let r2 = dot(r, r);
            if (t * TILE + k != i && r2 <= shape.cutoff2) {
                acc = row_add(acc, pair_term(xi, xj, r, r2, vi, tile_val[k]));
            }
        }
        workgroupBarrier();
    }
    if (inside) {
        store_out(i, acc);
    }
}
