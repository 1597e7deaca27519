// MPCD averages from the accumulated observables of mpcd/measure.wgsl: mean v_x per
// profile bin (NaN for a bin that saw no particle), the temperature
// m sum |v - u_c|^2 / (d sum (n_c - 1)), and the mean total momentum m sum v / samples
// (NaN before the first sample).
#import common/index.wgsl
#import mpcd/common.wgsl

@group(0) @binding(0) var<uniform> m: Mpcd;
@group(0) @binding(1) var<storage, read> acc: array<u32>;
@group(0) @binding(2) var<storage, read_write> profile: array<f32>;
@group(0) @binding(3) var<storage, read_write> temperature: array<f32>;
@group(0) @binding(4) var<storage, read_write> momentum: array<f32>;

fn pair(i: u32) -> f32 {
    return fx_to_f32(vec2<u32>(acc[i], acc[i + 1u]));
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let b = flat_index(wid, nwg, lid, 256u);
    let nan = bitcast<f32>(0x7fc00000u);
    if (b < m.bins) {
        let n = pair(13u + 4u * b);
        profile[b] = select(nan, pair(11u + 4u * b) / (n * m.fix_v), n > 0.0);
    }
    if (b == 0u) {
        let dof = pair(9u);
        // The sums over the particles in real units first, then the mean, then m: each
        // intermediate within f32 for m and kT/m in their ranges (nodes/mpcd/mod.rs).
        temperature[0] = select(nan, m.mass * (pair(7u) / m.fix_e / (f32(DIMS) * dof)), dof > 0.0);
        let samples = f32(acc[0]);
        for (var a = 0u; a < DIMS; a = a + 1u) {
            momentum[a] = select(nan, m.mass * (pair(1u + 2u * a) / m.fix_v / samples), samples > 0.0);
        }
    }
}
