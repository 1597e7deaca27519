// template: the cell-sum atomics of mpcd_bin on pairs of 32-bit words (any adapter): the
// low word by atomic, then the high word with the carry (mpcd/add64.wgsl). Declares the
// kernel's binding 5.
#import mpcd/common.wgsl

@group(0) @binding(5) var<storage, read_write> sums64: array<atomic<u32>>;

#import mpcd/add64.wgsl

fn add_count(word: u32) {
    atomicAdd(&sums64[word], 1u);
}

fn add_signed(word: u32, q: i32) {
    add64(word, fx_of_i32(q));
}

fn add_unsigned(word: u32, q: u32) {
    add64(word, vec2<u32>(q, 0u));
}
