// The force on each solid sphere from one MPCD step (S2 Eqs. 5.10-5.13): its kinetic
// impulse (the bounces of mpcd_stream_spheres) plus the collisional one, the momentum
// its virtual particles gained in the collision, m (v_after - v_before) each, summed
// exactly in 64-bit fixed point (units m v_th / 2^24). `start` copies the kinetic
// impulse (one thread per word), `gather` adds the virtual particles' (one thread per
// virtual particle, sphere q / K), `finish` (one thread per sphere) writes the force
// J m / (fix_v dt) and, from step `warmup` on, adds J to the running totals (the last
// word counts the samples) and writes their mean force.
#import common/index.wgsl
#import mpcd/common.wgsl
#import mpcd/sphere_block.wgsl

@group(0) @binding(0) var<uniform> m: Mpcd;
@group(0) @binding(1) var<uniform> sp: Spheres;
@group(0) @binding(2) var<storage, read> clock: array<u32>;
@group(0) @binding(3) var<storage, read> kinetic: array<u32>;
@group(0) @binding(4) var<storage, read> before: array<f32>;
@group(0) @binding(5) var<storage, read> after: array<f32>;
@group(0) @binding(6) var<storage, read_write> sums64: array<atomic<u32>>;
@group(0) @binding(7) var<storage, read_write> forces: array<f32>;
@group(0) @binding(8) var<storage, read_write> totals: array<u32>;
@group(0) @binding(9) var<storage, read_write> mean: array<f32>;

#import mpcd/add64.wgsl

@compute @workgroup_size(256)
fn start(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i < 6u * sp.count) {
        atomicStore(&sums64[i], kinetic[i]);
    }
}

@compute @workgroup_size(256)
fn gather(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
          @builtin(local_invocation_index) lid: u32) {
    let q = flat_index(wid, nwg, lid, 256u);
    if (q >= sp.count * sp.per) {
        return;
    }
    let j = q / sp.per;
    for (var a = 0u; a < 3u; a = a + 1u) {
        add64(6u * j + 2u * a, fx_of_signed((after[3u * q + a] - before[3u * q + a]) * m.fix_v));
    }
}

@compute @workgroup_size(256)
fn finish(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
          @builtin(local_invocation_index) lid: u32) {
    let j = flat_index(wid, nwg, lid, 256u);
    if (j >= sp.count) {
        return;
    }
    let unit = m.mass / (m.fix_v * m.dt);
    let sample = clock[0] >= sp.warmup;
    let samples = totals[6u * sp.count] + select(0u, 1u, sample);
    for (var a = 0u; a < 3u; a = a + 1u) {
        let k = 6u * j + 2u * a;
        let q = vec2<u32>(atomicLoad(&sums64[k]), atomicLoad(&sums64[k + 1u]));
        forces[3u * j + a] = fx_to_f32(q) * unit;
        var t = vec2<u32>(totals[k], totals[k + 1u]);
        if (sample) {
            t = fx_sum(t, q);
            totals[k] = t.x;
            totals[k + 1u] = t.y;
        }
        mean[3u * j + a] = fx_to_f32(t) * unit / f32(max(samples, 1u));
    }
}

// The sample count, advanced after `finish` has read it in every sphere's thread (a
// dispatch of its own: threads of one dispatch run in any order).
@compute @workgroup_size(1)
fn count() {
    if (clock[0] >= sp.warmup) {
        totals[6u * sp.count] = totals[6u * sp.count] + 1u;
    }
}
