// MPCD initial state: positions uniform in the box, velocities Maxwell-Boltzmann with
// zero total momentum. `draw` (one thread per particle) draws both from Philox at step 0
// of (seed, stream) and (seed, stream + 1) and sums the velocities in 64-bit fixed point
// (exactly per workgroup first, as 16-bit split integers, then one 64-bit atomic per
// workgroup and axis); `center` subtracts the mean velocity.
#import common/index.wgsl
#import mpcd/common.wgsl
#import mpcd/add64.wgsl

@group(0) @binding(0) var<uniform> m: Mpcd;
@group(0) @binding(1) var<storage, read_write> pos: array<f32>;
@group(0) @binding(2) var<storage, read_write> vel: array<f32>;
@group(0) @binding(3) var<storage, read_write> sums64: array<atomic<u32>>;

var<workgroup> wg_lo: array<atomic<u32>, 3>;
var<workgroup> wg_hi: array<atomic<i32>, 3>;


@compute @workgroup_size(256)
fn draw(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let p = flat_index(wid, nwg, lid, 256u);
    if (lid < 3u) {
        atomicStore(&wg_lo[lid], 0u);
        atomicStore(&wg_hi[lid], 0);
    }
    workgroupBarrier();
    if (p < m.n) {
        let vth = sqrt(m.kt / m.mass);
        for (var a = 0u; a < DIMS; a = a + 1u) {
            let e = p * DIMS + a;
            let x = (philox_uniform(e, 0u, m.seed_lo, m.seed_hi, m.stream) - 0.5) * m.box[a];
            pos[e] = min(x, 0.5 * m.box[a]);
            let v = vth * philox_normal(e, 0u, m.seed_lo, m.seed_hi, m.stream + 1u);
            vel[e] = v;
            let q = fx_round(v * m.fix_v);
            atomicAdd(&wg_lo[a], bitcast<u32>(q) & 0xffffu);
            atomicAdd(&wg_hi[a], q >> 16u);
        }
    }
    workgroupBarrier();
    if (lid < DIMS) {
        add64(2u * lid, fx_compose(atomicLoad(&wg_hi[lid]), atomicLoad(&wg_lo[lid])));
    }
}

@compute @workgroup_size(256)
fn center(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
          @builtin(local_invocation_index) lid: u32) {
    let p = flat_index(wid, nwg, lid, 256u);
    if (p >= m.n) {
        return;
    }
    for (var a = 0u; a < DIMS; a = a + 1u) {
        let mean = fx_to_f32(vec2<u32>(atomicLoad(&sums64[2u * a]), atomicLoad(&sums64[2u * a + 1u]))) / (f32(m.n) * m.fix_v);
        vel[p * DIMS + a] = vel[p * DIMS + a] - mean;
    }
}
