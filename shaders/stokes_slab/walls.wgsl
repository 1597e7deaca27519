// slab_walls: the no-slip walls of the doubly periodic Stokes solver on the free-space
// velocity, values along z (j = 0 the top, j = nz - 1 the bottom), per k (digest sections
// 7.3 and 7.4; nodes/stokes_slab.rs derives the forms). One thread per (z, k), neighbouring
// threads at neighbouring k: each finds its k's homogeneous flow from the end values (the
// threads of a k read the same few words) and adds it at its z.
//
// k != 0: u_b = -v(bottom), u_t = -v(top) are cancelled by the homogeneous Stokes solution
// [a zeta (-i k, |k|) + C] e^{-|k| zeta} + [b zeta (i k, |k|) + D] e^{|k| (zeta - Lz)},
// zeta = z - zmin, a = C_z - i k.C / |k|, b = -D_z - i k.D / |k| (divergence-free); bottom:
// C = u_b, D = 0; slit: (C, D) = Minv (u_b, u_t), Minv per k from the host (f64, the
// growing exponential rescaled so nothing overflows). k = 0: none drops the mode; bottom
// adds -v(bottom) + s zeta to v_x, v_y with s = -dv/dz(top) (zero at the wall, free above:
// bounded flow); slit adds the linear function that zeroes both walls; v_z = 0.
// tables: zeta_j (nz), the weights of dv/dz at the top from the values (nz), then for the
// slit Minv: word ((r 6 + c) 2 + part) nk + k.
#import common/index.wgsl
#import stokes_slab/slab.wgsl
#import stokes_slab/wall_flow.wgsl

@group(0) @binding(0) var<storage, read> v: array<f32>;
@group(0) @binding(1) var<storage, read_write> out: array<f32>;
@group(0) @binding(2) var<storage, read> tables: array<f32>;
@group(0) @binding(3) var<uniform> s: Slab;

fn load(c: u32, z: u32, k: u32) -> vec2<f32> {
    let w = slab_word(c, z, k, s.nz, s.nk);
    return vec2<f32>(v[w], v[w + 1u]);
}

fn store(c: u32, z: u32, k: u32, x: vec2<f32>) {
    let w = slab_word(c, z, k, s.nz, s.nk);
    out[w] = x.x;
    out[w + 1u] = x.y;
}

fn minv(r: u32, c: u32, k: u32) -> vec2<f32> {
    let base = 2u * s.nz;
    let w = ((r * 6u + c) * 2u) * s.nk + k;
    return vec2<f32>(tables[base + w], tables[base + w + s.nk]);
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let t = flat_index(wid, nwg, lid, 256u);
    if (t >= s.nk * s.nz) {
        return;
    }
    let k = t % s.nk;
    let j = t / s.nk;
    let n = s.nz;
    let zeta = tables[j];
    let q = slab_wave(s, k, false);
    let kabs = length(q);
    if (kabs == 0.0) {
        // Linear functions of z solve the k = 0 problem's homogeneous part: the one that
        // meets the walls' conditions is added (bottom: zero at zmin, free slope at zmax;
        // slit: zero at both).
        for (var c = 0u; c < 2u; c++) {
            let bottom = load(c, n - 1u, k);
            var x = vec2<f32>(0.0);
            if (s.walls == 1u) {
                var slope = vec2<f32>(0.0);
                for (var i = 0u; i < n; i++) {
                    slope -= tables[n + i] * load(c, i, k);
                }
                x = load(c, j, k) - bottom + zeta * slope;
            } else if (s.walls == 2u) {
                let h = zeta / s.height;
                x = load(c, j, k) - bottom * (1.0 - h) - load(c, 0u, k) * h;
            }
            store(c, j, k, x);
        }
        store(2u, j, k, vec2<f32>(0.0));
        return;
    }
    if (s.walls == 0u) {
        for (var c = 0u; c < 3u; c++) {
            store(c, j, k, load(c, j, k));
        }
        return;
    }
    // The walls' constants from the velocity at the bottom (and the top, for the slit).
    let bottom = mat3x2<f32>(load(0u, n - 1u, k), load(1u, n - 1u, k), load(2u, n - 1u, k));
    var top = mat3x2<f32>();
    if (s.walls == 2u) {
        top = mat3x2<f32>(load(0u, 0u, k), load(1u, 0u, k), load(2u, 0u, k));
    }
    let cd = wall_constants(s.walls, bottom, top, k);
    let ab = wall_factors(cd, q, kabs);
    let decay = exp(-kabs * zeta);
    let grow = exp(kabs * (zeta - s.height));
    let az = ab[0] * zeta;
    let bz = ab[1] * zeta;
    let corr = array<vec2<f32>, 3>(
        (times_i(-q.x * az) + cd.c[0]) * decay + (times_i(q.x * bz) + cd.d[0]) * grow,
        (times_i(-q.y * az) + cd.c[1]) * decay + (times_i(q.y * bz) + cd.d[1]) * grow,
        (kabs * az + cd.c[2]) * decay + (kabs * bz + cd.d[2]) * grow,
    );
    for (var c = 0u; c < 3u; c++) {
        store(c, j, k, load(c, j, k) + corr[c]);
    }
}
