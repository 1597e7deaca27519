// Virtual particles filling the solid spheres' shells (S2 §5.3.2, Eqs. 5.7-5.9), one
// thread per virtual particle q = j K + i (K = sp.per per sphere j), redrawn every step:
// a direction uniform on the sphere (theta uniform in [0, 2 pi), z0 uniform in [-1, 1):
// Archimedes' cylinder projection), a radius q = p^(1/3) with p uniform in
// [R_in^3, R^3) (uniform density in the shell R_in = max(R - 2 sqrt(3) a, 0) to R, the
// supercell's body diagonal), at the sphere's centre; velocity the sphere's plus
// sqrt(kT / m) times a standard normal per component. Uniforms from Philox (seed, stream)
// at this step, elements 3q + a; normals from stream + 1. Positions wrapped into the box.
#import common/index.wgsl
#import mpcd/common.wgsl

@group(0) @binding(0) var<uniform> m: Mpcd;
@group(0) @binding(1) var<uniform> sp: Spheres;
@group(0) @binding(2) var<storage, read> clock: array<u32>;
@group(0) @binding(3) var<storage, read> centres: array<f32>;
@group(0) @binding(4) var<storage, read> radii: array<f32>;
@group(0) @binding(5) var<storage, read> sphere_vel: array<f32>;
@group(0) @binding(6) var<storage, read_write> pos_out: array<f32>;
@group(0) @binding(7) var<storage, read_write> vel_out: array<f32>;

#import mpcd/spheres.wgsl

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let q = flat_index(wid, nwg, lid, 256u);
    if (q >= sp.count * sp.per) {
        return;
    }
    let j = q / sp.per;
    let step = clock[0];
    let theta = 6.283185307179586 * philox_uniform(3u * q, step, m.seed_lo, m.seed_hi, m.stream);
    let z0 = 2.0 * philox_uniform(3u * q + 1u, step, m.seed_lo, m.seed_hi, m.stream) - 1.0;
    let u = philox_uniform(3u * q + 2u, step, m.seed_lo, m.seed_hi, m.stream);
    let rad = radii[j];
    let rin = max(rad - 3.4641016151377544 * m.cell, 0.0);
    let p = rin * rin * rin + u * (rad * rad * rad - rin * rin * rin);
    let r = pow(p, 1.0 / 3.0);
    let s0 = sqrt(max(1.0 - z0 * z0, 0.0));
    let x = sphere_centre(j) + r * vec3<f32>(s0 * cos(theta), s0 * sin(theta), z0);
    let vs = sphere_velocity(j);
    let vth = sqrt(m.kt / m.mass);
    for (var a = 0u; a < 3u; a = a + 1u) {
        var y = x[a];
        if (m.walls == 0u || a != 2u) {
            let l = m.box[a];
            y = y - l * floor(y / l + 0.5);
            if (y >= 0.5 * l) {
                y = y - l;
            }
        }
        pos_out[3u * q + a] = y;
        vel_out[3u * q + a] = vs[a] + vth * philox_normal(3u * q + a, step, m.seed_lo, m.seed_hi, m.stream + 1u);
    }
}
