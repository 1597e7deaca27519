// template: the slit's homogeneous flow constants of one wave number k, imported by
// slab_walls (stokes_slab/walls.wgsl) and the slab solve kernels (chebyshev/
// slab_solve.wgsl, slab_staged.wgsl). The importer defines `minv(r, c, k)`, entry (r, c)
// of k's 6 x 6 complex inverse (nodes/stokes_slab.rs `slit_inverse`, built in f64 on the
// host), and `cmul`.

// Row r of (C_x, C_y, C_z, D_x, D_y, D_z) = Minv w for the walls' velocities w =
// (-v(bottom), -v(top)) (3 components each): C_r for r < 3, D_(r-3) past.
fn slit_row(r: u32, w: array<vec2<f32>, 6>, k: u32) -> vec2<f32> {
    var x = vec2<f32>(0.0);
    for (var i = 0u; i < 6u; i++) {
        x += cmul(minv(r, i, k), w[i]);
    }
    return x;
}
