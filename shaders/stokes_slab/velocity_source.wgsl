// slab_velocity_source: per k, the sources of the three velocity boundary-value problems,
// ((i k p - f) / eta, (dp/dz - f_z) / eta), and their boundary values from the pressure at
// the ends of the domain (digest section 7.2): alpha = (-i k_par p(top) / (2 eta |k|),
// p(top) / (2 eta)), beta = (i k_par p(bottom) / (2 eta |k|), p(bottom) / (2 eta)); zero at
// k = 0 (Dirichlet zero: the k = 0 mode is the walls' business). One thread per (z, k),
// neighbouring threads at neighbouring k; the threads at z = 0 sum their k's boundary values.
#import common/index.wgsl
#import stokes_slab/slab.wgsl

@group(0) @binding(0) var<storage, read> f: array<f32>;
@group(0) @binding(1) var<storage, read> p: array<f32>;
@group(0) @binding(2) var<storage, read> dp: array<f32>;
@group(0) @binding(3) var<storage, read_write> rhs: array<f32>;
@group(0) @binding(4) var<storage, read_write> boundary: array<f32>;
@group(0) @binding(5) var<uniform> s: Slab;

fn put_boundary(c: u32, end: u32, k: u32, v: vec2<f32>) {
    let w = slab_word(c, end, k, 2u, s.nk);
    boundary[w] = v.x;
    boundary[w + 1u] = v.y;
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let t = flat_index(wid, nwg, lid, 256u);
    if (t >= s.nk * s.nz) {
        return;
    }
    let k = t % s.nk;
    let z = t / s.nk;
    let q = slab_wave(s, k, true);
    let w = slab_word(0u, z, k, s.nz, s.nk);
    let ipz = times_i(vec2<f32>(p[w], p[w + 1u]));
    for (var c = 0u; c < 3u; c++) {
        let wc = slab_word(c, z, k, s.nz, s.nk);
        var drive: vec2<f32>;
        if (c == 2u) {
            drive = vec2<f32>(dp[w], dp[w + 1u]);
        } else {
            drive = q[c] * ipz;
        }
        let v = (drive - vec2<f32>(f[wc], f[wc + 1u])) * s.inv_eta;
        rhs[wc] = v.x;
        rhs[wc + 1u] = v.y;
    }
    if (z != 0u) {
        return;
    }
    // The pressure at the ends from its coefficients: p(top) = sum p_z, p(bottom) =
    // sum (-1)^z p_z.
    var top = vec2<f32>(0.0);
    var bottom = vec2<f32>(0.0);
    for (var i = 0u; i < s.nz; i++) {
        let wi = slab_word(0u, i, k, s.nz, s.nk);
        let pz = vec2<f32>(p[wi], p[wi + 1u]);
        top += pz;
        bottom += select(pz, -pz, i % 2u == 1u);
    }
    let kk = slab_wave(s, k, false);
    let kabs = length(kk);
    if (kabs == 0.0) {
        for (var c = 0u; c < 3u; c++) {
            put_boundary(c, 0u, k, vec2<f32>(0.0));
            put_boundary(c, 1u, k, vec2<f32>(0.0));
        }
        return;
    }
    let half_inv_eta = 0.5 * s.inv_eta;
    let itop = times_i(top) * (half_inv_eta / kabs);
    let ibottom = times_i(bottom) * (half_inv_eta / kabs);
    for (var c = 0u; c < 2u; c++) {
        put_boundary(c, 0u, k, -q[c] * itop);
        put_boundary(c, 1u, k, q[c] * ibottom);
    }
    put_boundary(2u, 0u, k, top * half_inv_eta);
    put_boundary(2u, 1u, k, bottom * half_inv_eta);
}
