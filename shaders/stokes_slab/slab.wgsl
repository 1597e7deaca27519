// Shared by the stokes_slab kernels (nodes/stokes_slab.rs): the geometry uniform, the
// word of a half spectrum's coefficient and the in-plane wave vector of a k index.
struct Slab {
    nx: u32, ny: u32, nz: u32, nk: u32,
    kx_unit: f32, ky_unit: f32, inv_eta: f32, scale: f32,
    height: f32, walls: u32, pad0: u32, pad1: u32,
}

// Word of component c, z index z, in-plane index k (real part; + 1 the imaginary).
fn slab_word(c: u32, z: u32, k: u32, nz: u32, nk: u32) -> u32 {
    return 2u * ((c * nz + z) * nk + k);
}

// The in-plane wave vector (kx, ky) of index k of the half spectrum; with `paired`, zero on
// an unpaired Nyquist index (where an odd operator has no real counterpart).
fn slab_wave(s: Slab, k: u32, paired: bool) -> vec2<f32> {
    let hx = s.nx / 2u + 1u;
    let x = k % hx;
    let y = k / hx;
    var fy = f32(y);
    if (y > s.ny / 2u) {
        fy = f32(y) - f32(s.ny);
    }
    var q = vec2<f32>(f32(x) * s.kx_unit, fy * s.ky_unit);
    if (paired) {
        if (s.nx % 2u == 0u && s.nx > 1u && x == s.nx / 2u) {
            q.x = 0.0;
        }
        if (s.ny % 2u == 0u && s.ny > 1u && y == s.ny / 2u) {
            q.y = 0.0;
        }
    }
    return q;
}

// i z for z = (re, im).
fn times_i(z: vec2<f32>) -> vec2<f32> {
    return vec2<f32>(-z.y, z.x);
}
