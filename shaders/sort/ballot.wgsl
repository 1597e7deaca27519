// Ballot masks for the subgroup scatter kernels: which lanes of a subgroup hold the same
// digit (a warp-level multi-split with one subgroupBallot per digit bit, since WGSL has no
// match instruction), and the mask arithmetic around it. Masks are vec4<u32> because a
// subgroup may have up to 128 lanes.

// false when no subgroup is wider than 32 lanes: only the first ballot word is used, so
// the compiler drops the other three (nodes/sort.rs sets it from the device).
override WIDE: bool = true;

// Lanes of the mask `lanes` whose 8-bit digit equals d: one ballot per digit bit, written out
// so that no loop is left to the compiler.
fn peers(d: u32, lanes: vec4<u32>) -> vec4<u32> {
    var eq = lanes & same_bit(d, 0u) & same_bit(d, 1u) & same_bit(d, 2u) & same_bit(d, 3u);
    eq &= same_bit(d, 4u) & same_bit(d, 5u) & same_bit(d, 6u) & same_bit(d, 7u);
    if (!WIDE) {
        eq = vec4<u32>(eq.x, 0u, 0u, 0u);
    }
    return eq;
}

// Lanes whose digit has the same bit b as d.
fn same_bit(d: u32, b: u32) -> vec4<u32> {
    let bit = ((d >> b) & 1u) == 1u;
    let ballot = subgroupBallot(bit);
    return select(~ballot, ballot, bit);
}

fn popcount(m: vec4<u32>) -> u32 {
    let c = countOneBits(m);
    return (c.x + c.y) + (c.z + c.w);
}

fn lowest_lane(m: vec4<u32>) -> u32 {
    if (m.x != 0u) {
        return firstTrailingBit(m.x);
    }
    if (m.y != 0u) {
        return 32u + firstTrailingBit(m.y);
    }
    if (m.z != 0u) {
        return 64u + firstTrailingBit(m.z);
    }
    return 96u + firstTrailingBit(m.w);
}

// Ballot mask of the lanes below `lane`: per word of 32 lanes from `lo`, all of them
// when lane >= lo + 32, the lanes lo .. lane - 1 when lo < lane < lo + 32, else none.
fn lanes_below(lane: u32) -> vec4<u32> {
    let l = vec4<u32>(lane);
    let lo = vec4<u32>(0u, 32u, 64u, 96u);
    let part = (vec4<u32>(1u) << ((l - lo) & vec4<u32>(31u))) - vec4<u32>(1u);
    let some = select(vec4<u32>(0u), part, l > lo);
    return select(some, vec4<u32>(0xffffffffu), l >= lo + vec4<u32>(32u));
}
