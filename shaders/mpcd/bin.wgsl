// MPCD binning, one thread per particle: the cell of each particle in the randomly shifted
// grid of this step, and per cell the count, sum v and sum |v|^2 as exact 64-bit
// fixed-point sums (mpcd/common.wgsl), by atomics. The sums start at zero (a fill before).
//
// Particles sorted by cell (mpcd.json's sort_particles, by the previous step's grid) give
// a workgroup a compact block of cells: it sums them in workgroup memory first (a block
// of LX x LY x LZ cells from its lowest cell per axis: a run along x, spread over a few
// rows by the new grid shift) and adds each touched cell to the grid once; a particle
// outside the block (unsorted input, a block across a periodic face) adds straight to
// the grid. Integer sums: the result is the same either way.
#import common/index.wgsl
#import mpcd/common.wgsl

@group(0) @binding(0) var<uniform> m: Mpcd;
@group(0) @binding(1) var<storage, read> clock: array<u32>;
@group(0) @binding(2) var<storage, read> pos: array<f32>;
@group(0) @binding(3) var<storage, read> vel: array<f32>;
@group(0) @binding(4) var<storage, read_write> cell: array<u32>;
@group(0) @binding(5) var<storage, read_write> sums: array<atomic<u32>>;

fn add64(i: u32, q: vec2<u32>) {
    let old = atomicAdd(&sums[i], q.x);
    let hi = q.y + select(0u, 1u, old + q.x < old);
    if (hi != 0u) {
        atomicAdd(&sums[i + 1u], hi);
    }
}

const LX: u32 = 32u;
const LY: u32 = 4u;
const LZ: u32 = 4u;
const LOCAL_CELLS: u32 = 512u;   // LX * LY * LZ

var<workgroup> wg_low: array<atomic<u32>, 3>;
var<workgroup> local_sums: array<atomic<u32>, 4608>;  // LOCAL_CELLS * CELL_WORDS

// The cell coordinates of a linear cell index.
fn cell_coords(c: u32) -> vec3<u32> {
    let nx = m.cells.x;
    if (DIMS == 3u) {
        let ny = m.cells.y;
        return vec3<u32>(c % nx, (c / nx) % ny, c / (nx * ny));
    }
    return vec3<u32>(c % nx, c / nx, 0u);
}

fn add64_local(i: u32, q: vec2<u32>) {
    let old = atomicAdd(&local_sums[i], q.x);
    let hi = q.y + select(0u, 1u, old + q.x < old);
    if (hi != 0u) {
        atomicAdd(&local_sums[i + 1u], hi);
    }
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let p = flat_index(wid, nwg, lid, 256u);
    let valid = p < m.n;
    if (lid < 3u) {
        atomicStore(&wg_low[lid], 0xffffffffu);
    }
    for (var w = lid; w < LOCAL_CELLS * CELL_WORDS; w = w + 256u) {
        atomicStore(&local_sums[w], 0u);
    }
    var c = 0u;
    var q = vec3<u32>(0u);
    var v = vec3<f32>(0.0);
    if (valid) {
        let s = grid_shift(m, clock[0]);
        var x = vec3<f32>(0.0);
        for (var a = 0u; a < DIMS; a = a + 1u) {
            x[a] = pos[p * DIMS + a];
            v[a] = vel[p * DIMS + a];
        }
        c = cell_of(m, x, s);
        cell[p] = c;
        q = cell_coords(c);
    }
    workgroupBarrier();
    if (valid) {
        atomicMin(&wg_low[0], q.x);
        atomicMin(&wg_low[1], q.y);
        atomicMin(&wg_low[2], q.z);
    }
    workgroupBarrier();
    let low = vec3<u32>(atomicLoad(&wg_low[0]), atomicLoad(&wg_low[1]), atomicLoad(&wg_low[2]));
    if (valid) {
        let d = q - low;
        let e = u32(round(min(dot(v, v) * m.fix_e, 4294967040.0)));
        if (d.x < LX && d.y < LY && d.z < LZ) {
            let base = (d.x + LX * (d.y + LY * d.z)) * CELL_WORDS;
            atomicAdd(&local_sums[base], 1u);
            for (var a = 0u; a < DIMS; a = a + 1u) {
                add64_local(base + 1u + 2u * a, fx_of_i32(fx_round(v[a] * m.fix_v)));
            }
            add64_local(base + 7u, vec2<u32>(e, 0u));
        } else {
            let base = c * CELL_WORDS;
            atomicAdd(&sums[base], 1u);
            for (var a = 0u; a < DIMS; a = a + 1u) {
                add64(base + 1u + 2u * a, fx_of_i32(fx_round(v[a] * m.fix_v)));
            }
            add64(base + 7u, vec2<u32>(e, 0u));
        }
    }
    workgroupBarrier();
    // Each thread adds its local cells to the grid (those with particles).
    for (var lc = lid; lc < LOCAL_CELLS; lc = lc + 256u) {
        let lbase = lc * CELL_WORDS;
        let count = atomicLoad(&local_sums[lbase]);
        if (count > 0u) {
            let g = low + vec3<u32>(lc % LX, (lc / LX) % LY, lc / (LX * LY));
            var gc = g.x + m.cells.x * g.y;
            if (DIMS == 3u) {
                gc = g.x + m.cells.x * (g.y + m.cells.y * g.z);
            }
            let gbase = gc * CELL_WORDS;
            atomicAdd(&sums[gbase], count);
            for (var w = 1u; w < CELL_WORDS; w = w + 2u) {
                add64(gbase + w, vec2<u32>(atomicLoad(&local_sums[lbase + w]), atomicLoad(&local_sums[lbase + w + 1u])));
            }
        }
    }
}
