// MPCD collisional pressure (nodes/mpcd/virial.rs): `particles` (one thread per particle)
// sums dv . (i & 1) over its workgroup exactly (16-bit split integers), then one 64-bit
// atomic add; `finish` (one thread) counts the sample and writes the mean pressure
// sum * unit / samples (unit m a / (d V dt fix_v) in the uniform's `ratio`).
#import common/index.wgsl
#import mpcd/common.wgsl

@group(0) @binding(0) var<uniform> m: Mpcd;
@group(0) @binding(1) var<storage, read> clock: array<u32>;
@group(0) @binding(2) var<storage, read> before: array<f32>;
@group(0) @binding(3) var<storage, read> after: array<f32>;
@group(0) @binding(4) var<storage, read> cell: array<u32>;
@group(0) @binding(5) var<storage, read_write> sums64: array<atomic<u32>>;
@group(0) @binding(6) var<storage, read_write> pressure: array<f32>;

#import mpcd/add64.wgsl

var<workgroup> w_lo: atomic<u32>;
var<workgroup> w_hi: atomic<i32>;

@compute @workgroup_size(256)
fn particles(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
             @builtin(local_invocation_index) lid: u32) {
    let p = flat_index(wid, nwg, lid, 256u);
    let on = sampled(m, clock[0]);
    if (lid == 0u) {
        atomicStore(&w_lo, 0u);
        atomicStore(&w_hi, 0);
    }
    workgroupBarrier();
    if (on && p < m.n) {
        let c = cell[p];
        let nx = m.cells.x;
        let ny = m.cells.y;
        var i = vec3<u32>(c % nx, (c / nx) % ny, 0u);
        if (DIMS == 3u) {
            i.z = c / (nx * ny);
        }
        let bit = i & vec3<u32>(1u);
        for (var a = 0u; a < DIMS; a = a + 1u) {
            if (bit[a] == 1u) {
                let q = fx_round((after[p * DIMS + a] - before[p * DIMS + a]) * m.fix_v);
                atomicAdd(&w_lo, bitcast<u32>(q) & 0xffffu);
                atomicAdd(&w_hi, q >> 16u);
            }
        }
    }
    workgroupBarrier();
    if (on && lid == 0u) {
        add64(1u, fx_compose(atomicLoad(&w_hi), atomicLoad(&w_lo)));
    }
}

@compute @workgroup_size(1)
fn finish() {
    if (sampled(m, clock[0])) {
        atomicAdd(&sums64[0], 1u);
    }
    let samples = f32(atomicLoad(&sums64[0]));
    let total = fx_to_f32(vec2<u32>(atomicLoad(&sums64[1]), atomicLoad(&sums64[2])));
    pressure[0] = select(bitcast<f32>(0x7fc00000u), total * m.ratio / samples, samples > 0.0);
}
