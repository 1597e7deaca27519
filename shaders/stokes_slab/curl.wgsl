// slab_curl: scale x curl of a field given by its half spectrum in x, y and Chebyshev
// coefficients in z, with the coefficients of its z derivative: (i ky v_z - dv_y,
// dv_x - i kx v_z, i kx v_y - i ky v_x). One thread per (z, k).
#import common/index.wgsl
#import stokes_slab/slab.wgsl

@group(0) @binding(0) var<storage, read> v: array<f32>;
@group(0) @binding(1) var<storage, read> dv: array<f32>;
@group(0) @binding(2) var<storage, read_write> out: array<f32>;
@group(0) @binding(3) var<uniform> s: Slab;

fn load_v(c: u32, z: u32, k: u32) -> vec2<f32> {
    let w = slab_word(c, z, k, s.nz, s.nk);
    return vec2<f32>(v[w], v[w + 1u]);
}

fn load_dv(c: u32, z: u32, k: u32) -> vec2<f32> {
    let w = slab_word(c, z, k, s.nz, s.nk);
    return vec2<f32>(dv[w], dv[w + 1u]);
}

fn store(c: u32, z: u32, k: u32, x: vec2<f32>) {
    let w = slab_word(c, z, k, s.nz, s.nk);
    out[w] = s.scale * x.x;
    out[w + 1u] = s.scale * x.y;
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
    let vx = load_v(0u, z, k);
    let vy = load_v(1u, z, k);
    let vz = load_v(2u, z, k);
    store(0u, z, k, times_i(q.y * vz) - load_dv(1u, z, k));
    store(1u, z, k, load_dv(0u, z, k) - times_i(q.x * vz));
    store(2u, z, k, times_i(q.x * vy - q.y * vx));
}
