// template: the walls' homogeneous flow of one wave number k != 0 (slab_walls' correction,
// nodes/stokes_slab.rs), imported by slab_walls (stokes_slab/walls.wgsl) and the slab
// solve kernels (chebyshev/slab_solve.wgsl, slab_solve_line.wgsl, slab_staged.wgsl,
// slab_lanes.wgsl), with `cmul`, which they all use. At
// height zeta its x, y components are (C_c - i k_c a zeta) exp(-|k| zeta) + (D_c + i k_c b
// zeta) exp(|k| (zeta - H)), its z component (C_z + |k| a zeta) exp(-|k| zeta) + (D_z +
// |k| b zeta) exp(|k| (zeta - H)). The importer defines `minv(r, c, k)`, entry (r, c) of
// k's 6 x 6 complex inverse (nodes/stokes_slab.rs `slit_inverse`, built in f64 on the
// host); stokes_slab/slab.wgsl gives `times_i`.
// The constants and factors travel as matrices of complex columns (x, y, z), every index
// a constant: as arrays returned by value and indexed in loops (the helpers before
// 2026-12-07) they made the fused slab solve kernels 2x to 4x slower on NVIDIA.

// The walls' constants: C (c) and D (d), columns x, y, z, complex (re, im).
struct WallConstants {
    c: mat3x2<f32>,
    d: mat3x2<f32>,
}

fn cmul(a: vec2<f32>, b: vec2<f32>) -> vec2<f32> {
    return vec2<f32>(a.x * b.x - a.y * b.y, a.x * b.y + a.y * b.x);
}

// Row r of (C_x, C_y, C_z, D_x, D_y, D_z) = Minv w for the walls' velocities w =
// (-v(bottom), -v(top)) (3 components each): C_r for r < 3, D_(r-3) past.
fn slit_row(r: u32, w: array<vec2<f32>, 6>, k: u32) -> vec2<f32> {
    var x = vec2<f32>(0.0);
    for (var i = 0u; i < 6u; i++) {
        x += cmul(minv(r, i, k), w[i]);
    }
    return x;
}

// The constants for wall mode `walls` (1 bottom, 2 slit) from the velocity's values at the
// bottom and the top (columns x, y, z): the bottom wall's C = -v(bottom), D = 0; the
// slit's (C, D) = Minv w for its walls' velocities w = (-v(bottom), -v(top)).
fn wall_constants(walls: u32, bottom: mat3x2<f32>, top: mat3x2<f32>, k: u32) -> WallConstants {
    if (walls != 2u) {
        return WallConstants(-1.0 * bottom, mat3x2<f32>());
    }
    let w = array<vec2<f32>, 6>(-bottom[0], -bottom[1], -bottom[2], -top[0], -top[1], -top[2]);
    return WallConstants(
        mat3x2<f32>(slit_row(0u, w, k), slit_row(1u, w, k), slit_row(2u, w, k)),
        mat3x2<f32>(slit_row(3u, w, k), slit_row(4u, w, k), slit_row(5u, w, k)),
    );
}

// The flow's factors (columns a, b) on zeta from its constants and k's wave vector kk
// (|kk| = kabs > 0): a = C_z - i (k . C) / |k|, b = -D_z - i (k . D) / |k|.
fn wall_factors(cd: WallConstants, kk: vec2<f32>, kabs: f32) -> mat2x2<f32> {
    let a = cd.c[2] - times_i(kk.x * cd.c[0] + kk.y * cd.c[1]) / kabs;
    let b = -cd.d[2] - times_i(kk.x * cd.d[0] + kk.y * cd.d[1]) / kabs;
    return mat2x2<f32>(a, b);
}
