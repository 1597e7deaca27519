// Signed wave number of index i on an axis of n points: i for i <= n/2, else i - n (so the
// Nyquist index n/2 of an even axis is +n/2, as on the x axis of a half spectrum).
fn wave_number(i: u32, n: u32) -> i32 {
    return select(i32(i), i32(i) - i32(n), i > n / 2u);
}
