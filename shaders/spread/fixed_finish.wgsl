// Deterministic spreading, last step (nodes/spread/fixed.rs): each cell's 64-bit
// fixed-point sum (two's complement, low word first) back to f32, divided by the scale
// 2^SHIFT of spread/add_fixed.wgsl; NaN everywhere when an add was out of range or a
// value not finite (flag word, or the max word's exponent all ones).
#import common/index.wgsl

struct Count { words: u32 }

@group(0) @binding(0) var<storage, read> fixed: array<u32>;
@group(0) @binding(1) var<storage, read_write> grid: array<f32>;
@group(0) @binding(2) var<uniform> count: Count;

override FIXED_WORDS: u32 = 0u;
override FIXED_EXP: i32 = 0;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i >= count.words) {
        return;
    }
    let max_bits = fixed[FIXED_WORDS];
    let biased = (max_bits >> 23u) & 255u;
    if (fixed[FIXED_WORDS + 1u] != 0u || biased == 255u) {
        grid[i] = bitcast<f32>(0x7fc00000u);
        return;
    }
    var lo = fixed[2u * i];
    var hi = fixed[2u * i + 1u];
    let negative = (hi & 0x80000000u) != 0u;
    if (negative) {
        lo = ~lo + 1u;
        hi = ~hi + select(0u, 1u, lo == 0u);
    }
    var m = f32(hi) * 4294967296.0 + f32(lo);
    if (negative) {
        m = -m;
    }
    let shift = 60 - (i32(biased) - 127) - FIXED_EXP;
    grid[i] = ldexp(ldexp(m, -(shift / 2)), -(shift - shift / 2));
}
