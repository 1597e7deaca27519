// MPCD binning, one thread per particle: the cell of each particle in the randomly shifted
// grid of this step, and per cell the count, sum v and sum |v|^2 as exact 64-bit
// fixed-point sums (mpcd/common.wgsl), by atomics. The sums start at zero (a fill before).
//
// Particles sorted by cell (mpcd.json's sort_particles) give a workgroup a few
// consecutive cells: it sums them in workgroup memory first (LOCAL_CELLS from its
// lowest cell) and adds each touched cell to the grid once; a particle outside that
// range (unsorted input) adds straight to the grid. Integer sums: the result is the same
// either way.
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

const LOCAL_CELLS: u32 = 256u;

var<workgroup> wg_low: atomic<u32>;
var<workgroup> local_sums: array<atomic<u32>, 2304>;  // LOCAL_CELLS * CELL_WORDS

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
    if (lid == 0u) {
        atomicStore(&wg_low, 0xffffffffu);
    }
    for (var w = lid; w < LOCAL_CELLS * CELL_WORDS; w = w + 256u) {
        atomicStore(&local_sums[w], 0u);
    }
    var c = 0u;
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
    }
    workgroupBarrier();
    if (valid) {
        atomicMin(&wg_low, c);
    }
    workgroupBarrier();
    let low = atomicLoad(&wg_low);
    if (valid) {
        let local = c - low;
        let e = u32(round(min(dot(v, v) * m.fix_e, 4294967040.0)));
        if (local < LOCAL_CELLS) {
            let base = local * CELL_WORDS;
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
    // One thread per local cell adds its sums to the grid.
    let lc = lid;
    let count = atomicLoad(&local_sums[lc * CELL_WORDS]);
    if (count > 0u) {
        let gbase = (low + lc) * CELL_WORDS;
        let lbase = lc * CELL_WORDS;
        atomicAdd(&sums[gbase], count);
        for (var w = 1u; w < CELL_WORDS; w = w + 2u) {
            add64(gbase + w, vec2<u32>(atomicLoad(&local_sums[lbase + w]), atomicLoad(&local_sums[lbase + w + 1u])));
        }
    }
}
