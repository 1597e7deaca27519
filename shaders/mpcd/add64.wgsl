// template: imported by the MPCD kernels that accumulate exact 64-bit sums into a
// storage binding named `sums64: array<atomic<u32>>`.
//
// Adds the 64-bit (lo, hi) pair q to words i, i + 1: the low word by atomic, then the
// high word plus the carry the low add produced (skipped when zero).
fn add64(i: u32, q: vec2<u32>) {
    let old = atomicAdd(&sums64[i], q.x);
    let hi = q.y + select(0u, 1u, old + q.x < old);
    if (hi != 0u) {
        atomicAdd(&sums64[i + 1u], hi);
    }
}
