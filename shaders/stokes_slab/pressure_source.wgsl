// slab_pressure_source: s = i kx f_x + i ky f_y + (d/dz f)_z per (z, k), the source of the
// pressure's boundary-value problem (digest section 7.2); df holds (d/dz f)_z alone. One
// thread per (z, k).
#import common/index.wgsl
#import stokes_slab/slab.wgsl

@group(0) @binding(0) var<storage, read> f: array<f32>;
@group(0) @binding(1) var<storage, read> df: array<f32>;
@group(0) @binding(2) var<storage, read_write> out: array<f32>;
@group(0) @binding(3) var<uniform> s: Slab;

fn load(c: u32, z: u32, k: u32) -> vec2<f32> {
    let w = slab_word(c, z, k, s.nz, s.nk);
    return vec2<f32>(f[w], f[w + 1u]);
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let t = flat_index(wid, nwg, lid, 256u);
    if (t >= s.nz * s.nk) {
        return;
    }
    let k = t % s.nk;
    let z = t / s.nk;
    let q = slab_wave(s, k, true);
    let wz = slab_word(0u, z, k, s.nz, s.nk);
    let v = times_i(q.x * load(0u, z, k) + q.y * load(1u, z, k)) + vec2<f32>(df[wz], df[wz + 1u]);
    let w = slab_word(0u, z, k, s.nz, s.nk);
    out[w] = v.x;
    out[w + 1u] = v.y;
}
