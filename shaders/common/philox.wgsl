// Philox4x32-10 (Salmon, Moraes, Dror, Shaw, SC'11), a counter-based generator: the same
// (counter, key) gives the same four u32 on every device and in the Rust twin
// (nodes/random.rs), whatever the dispatch shape. WGSL has no 32x32->64 multiply, so the
// high half is built from 16-bit halves.
//
// mesoflow's convention: key = (seed low 32 bits, stream), counter = (block, step,
// seed high 32 bits, 0), where block = element index / 4 and the element takes lane
// element % 4 of the block.

const PHILOX_M0: u32 = 0xD2511F53u;
const PHILOX_M1: u32 = 0xCD9E8D57u;
const PHILOX_W0: u32 = 0x9E3779B9u;
const PHILOX_W1: u32 = 0xBB67AE85u;

// High 32 bits of the 64-bit product a * b. On adapters with 64-bit integers the engine
// replaces this function, between the markers, by one 64-bit multiply (same bits;
// src/gpu/shaders.rs, `specialise`).
// begin portable philox_mulhi
fn philox_mulhi(a: u32, b: u32) -> u32 {
    let a_lo = a & 0xFFFFu;
    let a_hi = a >> 16u;
    let b_lo = b & 0xFFFFu;
    let b_hi = b >> 16u;
    let ll = a_lo * b_lo;
    let hl = a_hi * b_lo;
    let lh = a_lo * b_hi;
    let hh = a_hi * b_hi;
    let mid = (ll >> 16u) + (hl & 0xFFFFu) + (lh & 0xFFFFu);
    return hh + (hl >> 16u) + (lh >> 16u) + (mid >> 16u);
}
// end portable philox_mulhi

fn philox_round(c: vec4<u32>, k: vec2<u32>) -> vec4<u32> {
    let hi0 = philox_mulhi(PHILOX_M0, c.x);
    let lo0 = PHILOX_M0 * c.x;
    let hi1 = philox_mulhi(PHILOX_M1, c.z);
    let lo1 = PHILOX_M1 * c.z;
    return vec4<u32>(hi1 ^ c.y ^ k.x, lo1, hi0 ^ c.w ^ k.y, lo0);
}

fn philox4x32_10(counter: vec4<u32>, key: vec2<u32>) -> vec4<u32> {
    var c = counter;
    var k = key;
    for (var r = 0u; r < 9u; r = r + 1u) {
        c = philox_round(c, k);
        k = k + vec2<u32>(PHILOX_W0, PHILOX_W1);
    }
    return philox_round(c, k);
}

// The four words of element `idx`'s block for (seed bits, stream, step).
fn philox_block(idx: u32, step: u32, seed_lo: u32, seed_hi: u32, stream: u32) -> vec4<u32> {
    return philox4x32_10(vec4<u32>(idx >> 2u, step, seed_hi, 0u), vec2<u32>(seed_lo, stream));
}

// Uniform in (0, 1]: 24 random bits, never 0 (safe for log).
fn philox_open01(x: u32) -> f32 {
    return f32((x >> 8u) + 1u) * (1.0 / 16777216.0);
}

// Standard normal for element `idx`: Box-Muller on the lane pair (0,1) or (2,3) of its
// block; even lanes take the cosine, odd lanes the sine.
fn philox_normal(idx: u32, step: u32, seed_lo: u32, seed_hi: u32, stream: u32) -> f32 {
    let w = philox_block(idx, step, seed_lo, seed_hi, stream);
    let lane = idx & 3u;
    let pair = select(w.xy, w.zw, lane >= 2u);
    let r = sqrt(-2.0 * log(philox_open01(pair.x)));
    let theta = 6.283185307179586 * philox_open01(pair.y);
    return select(r * cos(theta), r * sin(theta), (lane & 1u) == 1u);
}

// Uniform in [0, 1) for element `idx`.
fn philox_uniform(idx: u32, step: u32, seed_lo: u32, seed_hi: u32, stream: u32) -> f32 {
    let w = philox_block(idx, step, seed_lo, seed_hi, stream);
    return f32(w[idx & 3u] >> 8u) * (1.0 / 16777216.0);
}
