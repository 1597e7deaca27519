// MPCD observables, accumulated on sampled steps (step >= warmup, every `every` steps)
// into a persistent block of u32 words (64-bit fixed-point pairs, mpcd/common.wgsl):
//   [0] samples, [1 + 2a] sum of v_a over particles and samples, [7] sum over particles of
//   |v - u_c|^2 before the collision (u_c from the cell sums), [9] sum over occupied cells
//   of n_c - 1, then per profile bin b: [11 + 4b] sum of v_x, [13 + 4b] particle count.
// `cells`: one thread per cell (degrees of freedom, summed in the workgroup first);
// `particles`: one thread per particle (momentum and profile, summed exactly in
// workgroup memory as 16-bit split integers, then one 64-bit atomic per bin; the relative
// squares summed in the workgroup in f32, then one 64-bit atomic).
#import common/index.wgsl
#import mpcd/common.wgsl
#import mpcd/add64.wgsl

const MAX_BINS: u32 = 1024u;

@group(0) @binding(0) var<uniform> m: Mpcd;
@group(0) @binding(1) var<storage, read> clock: array<u32>;
@group(0) @binding(2) var<storage, read> pos: array<f32>;
@group(0) @binding(3) var<storage, read> vel: array<f32>;
@group(0) @binding(4) var<storage, read> sums: array<u32>;
@group(0) @binding(5) var<storage, read> cell: array<u32>;
@group(0) @binding(6) var<storage, read> before: array<f32>;
@group(0) @binding(7) var<storage, read_write> sums64: array<atomic<u32>>;

var<workgroup> rel_sum: array<f32, 256>;
var<workgroup> dof_sum: array<u32, 256>;
var<workgroup> bin_lo: array<atomic<u32>, MAX_BINS>;
var<workgroup> bin_hi: array<atomic<i32>, MAX_BINS>;
var<workgroup> bin_n: array<atomic<u32>, MAX_BINS>;
var<workgroup> mom_lo: array<atomic<u32>, 3>;
var<workgroup> mom_hi: array<atomic<i32>, 3>;

@compute @workgroup_size(256)
fn cells(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    let on = sampled(m, clock[0]);
    var dof = 0u;
    if (on && i < m.ncells) {
        let count = sums[i * CELL_WORDS];
        if (count > 0u) {
            dof = count - 1u;
        }
    }
    dof_sum[lid] = dof;
    workgroupBarrier();
    for (var w = 128u; w > 0u; w = w >> 1u) {
        if (lid < w) {
            dof_sum[lid] = dof_sum[lid] + dof_sum[lid + w];
        }
        workgroupBarrier();
    }
    if (on && lid == 0u) {
        add64(9u, vec2<u32>(dof_sum[0], 0u));
        if (i == 0u) {
            atomicAdd(&sums64[0], 1u);
        }
    }
}

@compute @workgroup_size(256)
fn particles(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
             @builtin(local_invocation_index) lid: u32) {
    let p = flat_index(wid, nwg, lid, 256u);
    let on = sampled(m, clock[0]);
    let bins = min(m.bins, MAX_BINS);
    for (var b = lid; b < bins; b = b + 256u) {
        atomicStore(&bin_lo[b], 0u);
        atomicStore(&bin_hi[b], 0);
        atomicStore(&bin_n[b], 0u);
    }
    if (lid < 3u) {
        atomicStore(&mom_lo[lid], 0u);
        atomicStore(&mom_hi[lid], 0);
    }
    var rel = 0.0;
    if (on && p < m.n) {
        let base = cell[p] * CELL_WORDS;
        let n = f32(sums[base]);
        var d = vec3<f32>(0.0);
        for (var a = 0u; a < DIMS; a = a + 1u) {
            let sv = fx_to_f32(vec2<u32>(sums[base + SUM_V + 2u * a], sums[base + SUM_V + 1u + 2u * a]));
            d[a] = before[p * DIMS + a] - sv / (n * m.fix_v);
        }
        rel = dot(d, d);
    }
    rel_sum[lid] = rel;
    workgroupBarrier();
    for (var w = 128u; w > 0u; w = w >> 1u) {
        if (lid < w) {
            rel_sum[lid] = rel_sum[lid] + rel_sum[lid + w];
        }
        workgroupBarrier();
    }
    if (on && p < m.n) {
        let w = DIMS - 1u;
        for (var a = 0u; a < DIMS; a = a + 1u) {
            let q = fx_round(vel[p * DIMS + a] * m.fix_v);
            atomicAdd(&mom_lo[a], bitcast<u32>(q) & 0xffffu);
            atomicAdd(&mom_hi[a], q >> 16u);
        }
        let z = pos[p * DIMS + w];
        let b = u32(clamp(i32(floor((z / m.box[w] + 0.5) * f32(bins))), 0, i32(bins) - 1));
        let q = fx_round(vel[p * DIMS] * m.fix_v);
        atomicAdd(&bin_lo[b], bitcast<u32>(q) & 0xffffu);
        atomicAdd(&bin_hi[b], q >> 16u);
        atomicAdd(&bin_n[b], 1u);
    }
    workgroupBarrier();
    if (!on) {
        return;
    }
    for (var b = lid; b < bins; b = b + 256u) {
        let n = atomicLoad(&bin_n[b]);
        if (n > 0u) {
            add64(11u + 4u * b, fx_compose(atomicLoad(&bin_hi[b]), atomicLoad(&bin_lo[b])));
            add64(13u + 4u * b, vec2<u32>(n, 0u));
        }
    }
    if (lid < DIMS) {
        add64(1u + 2u * lid, fx_compose(atomicLoad(&mom_hi[lid]), atomicLoad(&mom_lo[lid])));
    }
    if (lid == 0u) {
        add64(7u, fx_of_f32(rel_sum[0] * m.fix_e));
    }
}
