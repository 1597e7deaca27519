// template: the MPCD binning of one particle, shared by mpcd/bin.wgsl and
// mpcd/stream_bin.wgsl (which declare `m`, `clock` and `cell`, and are composed after
// mpcd/sums_int64.wgsl or mpcd/sums_int32.wgsl: binding 5 and the add_* functions).
//
// The cell of particle p at x in the randomly shifted grid of this step, and its count,
// v and (with `energy`) |v|^2 added to the cell's exact 64-bit fixed-point sums
// (mpcd/common.wgsl).
#import mpcd/common.wgsl

fn bin_particle(p: u32, x: vec3<f32>, v: vec3<f32>) {
    let c = cell_of(m, x, grid_shift(m, clock[0]));
    cell[p] = c;
    bin_add(c, v);
}

// Adds a particle of velocity v to the sums of cell c.
fn bin_add(c: u32, v: vec3<f32>) {
    let base = c * CELL_WORDS;
    add_count(base);
    for (var a = 0u; a < DIMS; a = a + 1u) {
        add_signed(base + SUM_V + 2u * a, fx_round(v[a] * m.fix_v));
    }
    if (m.energy == 1u) {
        add_unsigned(energy_word(m, c), u32(round(min(dot(v, v) * m.fix_e, 4294967040.0))));
    }
}
