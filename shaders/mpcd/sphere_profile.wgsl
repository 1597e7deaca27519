// The solvent's velocity tangential to a sphere along a cylinder through its centre
// (nodes/mpcd/sphere_profile.rs; S2 Eqs. 5.14-5.16). On sampled steps `count` adds a
// sample, `particles` (one thread per solvent particle) finds the particle's bin, if it
// is in the cylinder, and adds its velocity relative to the sphere's along `tangent` and
// 1 to the bin's exact 64-bit sums (global atomics: few particles are in the cylinder);
// `finish` (one thread per bin) writes the bin's centre, mean and number density.
#import common/index.wgsl
#import mpcd/common.wgsl

struct Cylinder {
    axis: vec4<f32>,
    tangent: vec4<f32>,
    length: f32,
    radius: f32,
    per_length: f32,       // bins per unit length
    sphere: u32,
    bins: u32,
    moving: u32,           // 1: sphere_vel holds the spheres' velocities
    spheres: u32,
    pad: u32,
}

@group(0) @binding(0) var<uniform> m: Mpcd;
@group(0) @binding(1) var<uniform> cyl: Cylinder;
@group(0) @binding(2) var<storage, read> clock: array<u32>;
@group(0) @binding(3) var<storage, read> pos: array<f32>;
@group(0) @binding(4) var<storage, read> vel: array<f32>;
@group(0) @binding(5) var<storage, read> centres: array<f32>;
@group(0) @binding(6) var<storage, read> sphere_vel: array<f32>;
@group(0) @binding(7) var<storage, read_write> sums64: array<atomic<u32>>;
@group(0) @binding(8) var<storage, read_write> profile: array<f32>;

#import mpcd/add64.wgsl

@compute @workgroup_size(1)
fn count() {
    if (sampled(m, clock[0])) {
        atomicAdd(&sums64[0], 1u);
    }
}

@compute @workgroup_size(256)
fn particles(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
             @builtin(local_invocation_index) lid: u32) {
    let p = flat_index(wid, nwg, lid, 256u);
    if (p >= m.n || !sampled(m, clock[0])) {
        return;
    }
    let j = 3u * cyl.sphere;
    let c = vec3<f32>(centres[j], centres[j + 1u], centres[j + 2u]);
    let x = vec3<f32>(pos[3u * p], pos[3u * p + 1u], pos[3u * p + 2u]);
    var r = x - c;
    let l = m.box.xyz;
    let w = r - l * floor(r / l + vec3<f32>(0.5));
    r = select(w, r, vec3<bool>(false, false, m.walls == 1u));
    let e = cyl.axis.xyz;
    let ap = r + 0.5 * cyl.length * e;
    let k = dot(ap, e);
    let q = ap - k * e;
    if (k < 0.0 || k >= cyl.length || dot(q, q) >= cyl.radius * cyl.radius) {
        return;
    }
    let b = min(u32(floor(k * cyl.per_length)), cyl.bins - 1u);
    var vs = vec3<f32>(0.0);
    if (cyl.moving == 1u) {
        vs = vec3<f32>(sphere_vel[j], sphere_vel[j + 1u], sphere_vel[j + 2u]);
    }
    let v = vec3<f32>(vel[3u * p], vel[3u * p + 1u], vel[3u * p + 2u]);
    let vt = dot(v - vs, cyl.tangent.xyz);
    add64(1u + 4u * b, fx_of_i32(fx_round(vt * m.fix_v)));
    add64(3u + 4u * b, vec2<u32>(1u, 0u));
}

@compute @workgroup_size(256)
fn finish(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
          @builtin(local_invocation_index) lid: u32) {
    let b = flat_index(wid, nwg, lid, 256u);
    if (b >= cyl.bins) {
        return;
    }
    let nan = bitcast<f32>(0x7fc00000u);
    let n = fx_to_f32(vec2<u32>(atomicLoad(&sums64[3u + 4u * b]), atomicLoad(&sums64[4u + 4u * b])));
    let sv = fx_to_f32(vec2<u32>(atomicLoad(&sums64[1u + 4u * b]), atomicLoad(&sums64[2u + 4u * b])));
    let samples = f32(atomicLoad(&sums64[0]));
    let volume = 3.14159265 * cyl.radius * cyl.radius / cyl.per_length;
    profile[3u * b] = (f32(b) + 0.5) / cyl.per_length - 0.5 * cyl.length;
    profile[3u * b + 1u] = select(nan, sv / (n * m.fix_v), n > 0.0);
    profile[3u * b + 2u] = select(nan, n / samples / volume, samples > 0.0);
}
