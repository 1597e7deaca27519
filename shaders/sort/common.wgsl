// Declarations shared by the passes of the LSD radix sort (nodes/sort.rs). One pass sorts
// by one digit: `histogram` counts the digits of each tile, the host scans the counts in
// digit-major order (the scan kernels), and a `scatter` kernel ranks each key stably
// inside its tile and writes keys and payload to their sorted places.

struct Pass {
    // Keys to sort.
    n: u32,
    // Tiles of the scatter kernel's size.
    ntiles: u32,
    // Lowest key bit of this pass's digit.
    shift: u32,
    // Digit mask after the shift (radix - 1).
    mask: u32,
    // Digit values of this pass: rows of the histogram.
    radix: u32,
    // 1: the payload is each key's index (first pass), else read from vals_in.
    first: u32,
}

fn digit_of(key: u32, cfg: Pass) -> u32 {
    return (key >> cfg.shift) & cfg.mask;
}
