// Grid accumulation for deterministic runs (nodes/spread/fixed.rs): every add is rounded
// to a 64-bit fixed-point integer and summed exactly (two 32-bit words with a carry), so
// the order the atomics run in changes no bit. The scale is a power of two, 2^SHIFT with
// SHIFT = 60 - e - FIXED_EXP, from the largest |value| spread (2^e <= max < 2^(e + 1),
// its f32 bits at word FIXED_WORDS, written by spread/fixed_max.wgsl) and the host's
// bound on one cell's total weight (PEAK x particles x wraps <= 2^FIXED_EXP): no cell's
// sum reaches 2^61, far from the 2^63 of the words. An add that is not finite or would
// leave that range (NaN or inf values) sets the flag at word FIXED_WORDS + 1 instead, and
// spread/fixed_finish.wgsl then writes NaN over the grid: never a wrapped sum.
@group(0) @binding(2) var<storage, read_write> grid: array<atomic<u32>>;

override FIXED_WORDS: u32 = 0u;
override FIXED_EXP: i32 = 0;

fn grid_add(i: u32, v: f32) {
    let e = i32((atomicLoad(&grid[FIXED_WORDS]) >> 23u) & 255u) - 127;
    let shift = 60 - e - FIXED_EXP;
    // Two steps: ldexp is defined for exponents up to 127 only.
    let q = round(ldexp(ldexp(v, shift / 2), shift - shift / 2));
    let m = abs(q);
    if (!(m <= 2305843009213693952.0)) {
        atomicOr(&grid[FIXED_WORDS + 1u], 1u);
        return;
    }
    if (m == 0.0) {
        return;
    }
    // The magnitude's two words are exact: m has 24 significant bits, so its part below
    // 2^32 is a representable float.
    let hi_f = floor(m * 2.3283064365386963e-10);
    var hi = u32(hi_f);
    var lo = u32(m - hi_f * 4294967296.0);
    if (q < 0.0) {
        lo = ~lo + 1u;
        hi = ~hi + select(0u, 1u, lo == 0u);
    }
    let old = atomicAdd(&grid[2u * i], lo);
    let carry = select(0u, 1u, old + lo < old);
    // Adding zero changes nothing: small adds (and a negative one's carry) skip the
    // high word's atomic.
    if (hi + carry != 0u) {
        atomicAdd(&grid[2u * i + 1u], hi + carry);
    }
}
