// Shared by the MPCD kernels (nodes/mpcd/): the parameter block every MPCD kernel binds,
// 64-bit fixed-point sums built from pairs of u32 words, the random grid shift and the
// cell of a position.
//
// Fixed point: a velocity component v is summed as the integer round(v * fix_v) and a
// squared speed |v|^2 as round(|v|^2 * fix_e) (fix_v = 2^24 / v_th, fix_e = 2^16 / v_th^2,
// v_th = sqrt(kT / m)), in 64-bit two's complement held as (lo, hi) u32 words: integer
// sums are exact and independent of the order of the atomic additions.
#import common/philox.wgsl

override DIMS: u32 = 3u;

struct Mpcd {
    box: vec4<f32>,        // box length per axis
    cells: vec4<u32>,      // cells per axis (the walled axis has L / a + 1 layers)
    n: u32,                // particles
    ncells: u32,           // cells in all
    walls: u32,            // 1: plates perpendicular to the last axis at +-L/2
    wall_slip: u32,        // 1: specular (slip) walls, 0: bounce-back (no slip)
    seed_lo: u32,
    seed_hi: u32,
    stream: u32,
    shift: u32,            // 1: random grid shift
    cell: f32,             // cell size a
    dt: f32,
    mass: f32,
    kt: f32,
    cos_a: f32,
    sin_a: f32,
    density: f32,          // mean particles per cell (ghost filling target)
    thermostat: u32,       // 0 none, 1 rescale, 2 Monte-Carlo cell scaling
    accel: f32,            // body force / mass along x
    force_shape: u32,      // 0 constant, 1 sin(2 pi z / L_z) (z = last axis)
    mc_c: f32,             // Monte-Carlo scaling range: Psi in [1, 1 + c)
    ghosts: u32,           // 1: fill wall-cut cells with virtual particles
    fix_v: f32,
    fix_e: f32,
    bins: u32,
    warmup: u32,
    every: u32,
    rule: u32,             // 0 SRD, 1 biased collisions (MPCD-BC)
    accept_a: f32,         // MPCD-BC acceptance parameter A
    half_cos: f32,         // cos and sin of half the SRD angle (3D rotations)
    half_sin: f32,
    solute: u32,           // 1: the cell sums carry a solute (mpcd_bin_solute's layout)
    ratio: f32,            // solute mass over solvent mass M / m
    energy: u32,           // 1: the cell sums carry sum |v|^2 per cell (for a thermostat)
    shift_stream: u32,     // mpcd_collide: the stream of mpcd_bin's grid shift (MPCD-BC with plates)
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

// The cell sums (nodes/mpcd/mod.rs, SumsLayout): per cell CELL_WORDS words, the count and
// sum v as 64-bit pairs ([0, 1] count, [SUM_V + 2a, SUM_V + 2a + 1] sum v_a): 32 bytes, one
// aligned sector; then with `energy` the pair of sum |v|^2 per cell; then with a solute the
// solute count per cell and the f32 bits of M / m.
const CELL_WORDS: u32 = 8u;
const SUM_V: u32 = 2u;

// The low word of cell c's sum |v|^2.
// Whether an accumulating node samples `step`: from `warmup` on, every `every`-th (the
// host's twin: Uniform::sampled in nodes/mpcd/mod.rs).
fn sampled(m: Mpcd, step: u32) -> bool {
    return step >= m.warmup && (step - m.warmup) % m.every == 0u;
}

fn energy_word(m: Mpcd, c: u32) -> u32 {
    return m.ncells * CELL_WORDS + 2u * c;
}

// The first word after the cells' blocks and energies: the solute counts.
fn solute_base(m: Mpcd) -> u32 {
    return m.ncells * (CELL_WORDS + 2u * m.energy);
}

// The 64-bit two's complement pair of an i32.
fn fx_of_i32(q: i32) -> vec2<u32> {
    return vec2<u32>(bitcast<u32>(q), select(0u, 0xffffffffu, q < 0));
}

// round(x) as i32 with |x| clamped below 2^31.
fn fx_round(x: f32) -> i32 {
    return i32(round(clamp(x, -2147483520.0, 2147483520.0)));
}

// The pair of round(x) for 0 <= x < 2^63 (x an f32: exact for x < 2^24, else rounded).
fn fx_of_f32(x: f32) -> vec2<u32> {
    let y = max(round(x), 0.0);
    let hi = floor(y * (1.0 / 4294967296.0));
    return vec2<u32>(u32(y - hi * 4294967296.0), u32(hi));
}

// The 64-bit pair of round(x) for |x| < 2^63 (negatives as two's complement).
fn fx_of_signed(x: f32) -> vec2<u32> {
    let p = fx_of_f32(abs(x));
    if (x >= 0.0) {
        return p;
    }
    let lo = ~p.x + 1u;
    return vec2<u32>(lo, ~p.y + select(0u, 1u, lo == 0u));
}

// (lo, hi) + (lo, hi) without atomics.
fn fx_sum(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    let lo = a.x + b.x;
    return vec2<u32>(lo, a.y + b.y + select(0u, 1u, lo < a.x));
}

// The pair hi * 2^16 + lo of a workgroup's split sums (hi signed, lo < 2^32 unsigned).
fn fx_compose(hi: i32, lo: u32) -> vec2<u32> {
    return fx_sum(vec2<u32>(bitcast<u32>(hi) << 16u, bitcast<u32>(hi >> 16u)), vec2<u32>(lo, 0u));
}

// The value of a pair as f32 (rounded once per word; negatives through their negation so
// that small negative sums keep their digits).
fn fx_to_f32(p: vec2<u32>) -> f32 {
    if ((p.y & 0x80000000u) != 0u) {
        let lo = ~p.x + 1u;
        let hi = ~p.y + select(0u, 1u, lo == 0u);
        return -(f32(hi) * 4294967296.0 + f32(lo));
    }
    return f32(p.y) * 4294967296.0 + f32(p.x);
}

// The random grid shift of this step: uniform in [-a/2, a/2) per axis for SRD, in [-a, a)
// for MPCD-BC (collisions within supercells of 2 x 2 (x 2) cells), one Philox block
// (block 0 of (seed, stream) at this step); zero when the shift is off.
fn grid_shift(m: Mpcd, step: u32) -> vec3<f32> {
    return grid_shift_of(m, step, m.stream);
}

// The grid shift drawn from `stream` (mpcd_collide: mpcd_bin's).
fn grid_shift_of(m: Mpcd, step: u32, stream: u32) -> vec3<f32> {
    if (m.shift == 0u) {
        return vec3<f32>(0.0);
    }
    let w = philox_block(0u, step, m.seed_lo, m.seed_hi, stream);
    let u = vec3<f32>(vec3<u32>(w.x, w.y, w.z) >> vec3<u32>(8u)) * (1.0 / 16777216.0);
    return (u - vec3<f32>(0.5)) * (m.cell * f32(1u + m.rule));
}

// Linear cell index ix + nx (iy + ny iz) of a position x for grid shift s: per axis
// floor((x + L/2 + s) / a) wrapped on periodic axes; on the walled axis (the last)
// floor((x + L/2 + s + a/2) / a) in [0, L/a] (L/a + 1 layers, the first and last cut by
// the walls when shifted); with MPCD-BC (shift in [-a, a)) floor((x + L/2 + s + a) / a)
// in [0, L/a + 1] (L/a + 2 layers, an even count: whole supercells). In 2D the unused z axis has one cell (iz = 0).
//
// All axes at once in vector arithmetic, without indexing `m` by axis: the form before, a
// loop over the axes reading m.cells[a] and m.box[a] of the struct passed by value with
// the loop counter as index, made every dispatch leak host memory on lavapipe (Mesa 22.3.6,
// llvmpipe, LLVM 15), about 290 KB per step of graphs/mpcd.json in an 8x8x4 box (15 GB over
// the mpcd tests); reading the same fields through the uniform itself or by constant index
// does not. Keep it so: no dynamic index into a struct passed by value.
fn cell_of(m: Mpcd, x: vec3<f32>, s: vec3<f32>) -> u32 {
    let nc = vec3<i32>(m.cells.xyz);
    let y = x + 0.5 * m.box.xyz + s;
    let periodic = vec3<i32>(floor(y / m.cell));
    var i = vec3<u32>(((periodic % nc) + nc) % nc);
    if (m.walls == 1u) {
        let layer = clamp(vec3<i32>(floor((y + 0.5 * m.cell * f32(1u + m.rule)) / m.cell)), vec3<i32>(0), nc - 1);
        i = select(i, vec3<u32>(layer), vec3<u32>(0u, 1u, 2u) == vec3<u32>(DIMS - 1u));
    }
    return i.x + m.cells.x * (i.y + m.cells.y * i.z);
}

// The layer of a cell along the last axis.
fn cell_layer(m: Mpcd, c: u32) -> u32 {
    if (DIMS == 3u) {
        return c / (m.cells.x * m.cells.y);
    }
    return c / m.cells.x;
}

// Cell mean velocity and relative sum of squares from the cell sums at `base`:
// (u, n) and sum |v - u|^2.
fn cell_moments(count: u32, sv: vec3<f32>, se: f32, m: Mpcd) -> vec4<f32> {
    let n = f32(count);
    let u = sv / (n * m.fix_v);
    return vec4<f32>(u, max(se / m.fix_e - n * dot(u, u), 0.0));
}
