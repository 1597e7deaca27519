// template: composed after a pair kernel (pair_term, self_term; shaders/pairs/*.wgsl).
//
// Every pair, open boundaries: each workgroup holds TILE particles i (one per thread)
// and walks the others in tiles of TILE loaded into workgroup memory. The tiles of j
// are cut into `slices` runs (the dispatch's z index) so that small N still fills the
// GPU: with one slice the sums go to the output, with more each slice writes its partial
// sums (row slice * n + i of `out`, then a scratch buffer) and all_pairs_sum.wgsl adds
// them in slice order.
#import common/index.wgsl

const TILE: u32 = 128u;  // nodes/pairs/mod.rs TILE

struct Shape {
    n: u32,
    cutoff2: f32,
    tiles_per_slice: u32,
    slices: u32,
}

@group(0) @binding(0) var<storage, read> pos: array<f32>;
@group(0) @binding(1) var<storage, read> vals: array<f32>;
@group(0) @binding(2) var<storage, read_write> out: array<f32>;
@group(0) @binding(3) var<uniform> shape: Shape;
@group(0) @binding(4) var<storage, read> pair_params_buffer: array<f32>;

// The pair kernel's params (at most PAIR_PARAMS words: nodes/pairs/mod.rs), read once
// into registers: the kernels read them at every pair.
const PAIR_PARAMS: u32 = 8u;
var<private> pair_params: array<f32, PAIR_PARAMS>;
@group(0) @binding(5) var<storage, read> pair_table: array<f32>;

var<workgroup> tile_pos: array<vec3<f32>, TILE>;
var<workgroup> tile_val: array<Row, TILE>;

#import pairs/values.wgsl

@compute @workgroup_size(TILE)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let words = arrayLength(&pair_params_buffer);
    for (var q = 0u; q < PAIR_PARAMS; q++) {
        pair_params[q] = select(0.0, pair_params_buffer[min(q, words - 1u)], q < words);
    }
    let i = flat_index(vec3<u32>(wid.xy, 0u), nwg, lid, TILE);
    let slice = wid.z;
    let n = shape.n;
    let inside = i < n;
    let ii = min(i, max(n, 1u) - 1u);
    let xi = vec3<f32>(pos[3u * ii], pos[3u * ii + 1u], pos[3u * ii + 2u]);
    let vi = value_row(ii);
    var acc = Row(vec4<f32>(0.0), vec4<f32>(0.0));
    if (slice == 0u) {
        acc = self_term(xi, vi);
    }
    let tiles = (n + TILE - 1u) / TILE;
    let first = slice * shape.tiles_per_slice;
    let last = min(tiles, first + shape.tiles_per_slice);
    for (var t = first; t < last; t++) {
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
        store_out(slice * n + i, acc);
    }
}
