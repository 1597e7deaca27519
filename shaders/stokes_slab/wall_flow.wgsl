// template: the walls' homogeneous flow of one wave number k != 0 (slab_walls' correction,
// nodes/stokes_slab.rs), imported by slab_walls (stokes_slab/walls.wgsl) and the slab
// solve kernels (chebyshev/slab_solve.wgsl and slab_solve_line.wgsl take slit_row only and
// write the constants and factors out: through these array-valued calls they ran 2x to
// 4x slower on NVIDIA; slab_staged.wgsl takes wall_factors). At height zeta its x, y
// components are (C_c - i k_c a zeta) exp(-|k| zeta) + (D_c + i k_c b zeta) exp(|k| (zeta
// - H)), its z component (C_z + |k| a zeta) exp(-|k| zeta) + (D_z + |k| b zeta) exp(|k|
// (zeta - H)). The importer defines `minv(r, c, k)`, entry (r, c) of k's 6 x 6 complex
// inverse (nodes/stokes_slab.rs `slit_inverse`, built in f64 on the host), and `cmul`;
// stokes_slab/slab.wgsl gives `times_i`.

// Row r of (C_x, C_y, C_z, D_x, D_y, D_z) = Minv w for the walls' velocities w =
// (-v(bottom), -v(top)) (3 components each): C_r for r < 3, D_(r-3) past.
fn slit_row(r: u32, w: array<vec2<f32>, 6>, k: u32) -> vec2<f32> {
    var x = vec2<f32>(0.0);
    for (var i = 0u; i < 6u; i++) {
        x += cmul(minv(r, i, k), w[i]);
    }
    return x;
}

// (C_x, C_y, C_z, D_x, D_y, D_z) for wall mode `walls` (1 bottom, 2 slit) from the walls'
// velocities w = (-v(bottom), -v(top)): the bottom wall's C = -v(bottom), D = 0; the
// slit's Minv w.
fn wall_constants(walls: u32, w: array<vec2<f32>, 6>, k: u32) -> array<vec2<f32>, 6> {
    var cd = array<vec2<f32>, 6>(w[0], w[1], w[2], vec2<f32>(0.0), vec2<f32>(0.0), vec2<f32>(0.0));
    if (walls == 2u) {
        for (var r = 0u; r < 3u; r++) {
            cd[r] = slit_row(r, w, k);
            cd[3u + r] = slit_row(3u + r, w, k);
        }
    }
    return cd;
}

// The flow's factors (a, b) on zeta from its constants cd = (C, D) and k's wave vector kk
// (|kk| = kabs > 0): a = C_z - i (k . C) / |k|, b = -D_z - i (k . D) / |k|.
fn wall_factors(cd: array<vec2<f32>, 6>, kk: vec2<f32>, kabs: f32) -> array<vec2<f32>, 2> {
    let a = cd[2] - times_i(kk.x * cd[0] + kk.y * cd[1]) / kabs;
    let b = -cd[5] - times_i(kk.x * cd[3] + kk.y * cd[4]) / kabs;
    return array<vec2<f32>, 2>(a, b);
}
