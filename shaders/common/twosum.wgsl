// Compensated (double-f32) accumulation: a value is carried as (sum, error) with
// Knuth's TwoSum, so a long f32 sum keeps nearly f64 accuracy.
//
// Shader compilers treat float arithmetic as reassociable unless told otherwise (WGSL
// cannot tell them), and rewrite (s + x) - s into x, which silently turns TwoSum into a
// plain sum (seen on Mesa's lavapipe). `one` must be a 1.0 read from a buffer at run
// time: z = t * one - s cannot be simplified, and is exactly t - s (t * 1 is exact, also
// when contracted into an fma).

// Adds x to (s, c).
fn twosum_add(acc: vec2<f32>, x: f32, one: f32) -> vec2<f32> {
    let t = acc.x + x;
    let z = t * one - acc.x;
    let e = (acc.x - (t - z)) + (x - z);
    return vec2<f32>(t, acc.y + e);
}

// Merges two compensated values.
fn twosum_merge(a: vec2<f32>, b: vec2<f32>, one: f32) -> vec2<f32> {
    let r = twosum_add(a, b.x, one);
    return vec2<f32>(r.x, r.y + b.y);
}
