// template: the cell-sum atomics of mpcd_bin with native 64-bit atomics (SHADER_INT64 and
// SHADER_INT64_ATOMIC_ALL_OPS): one return-less add per sum. Declares the kernel's binding 5.
// Word indices are those of the u32 layout (even: every pair is 8-byte aligned).
#import mpcd/common.wgsl

@group(0) @binding(5) var<storage, read_write> sums64: array<atomic<u64>>;

fn add_count(word: u32) {
    atomicAdd(&sums64[word >> 1u], 1lu);
}

fn add_signed(word: u32, q: i32) {
    atomicAdd(&sums64[word >> 1u], bitcast<u64>(i64(q)));
}

fn add_unsigned(word: u32, q: u32) {
    atomicAdd(&sums64[word >> 1u], u64(q));
}
