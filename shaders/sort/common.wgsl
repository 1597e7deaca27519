// Declarations shared by the passes of the LSD radix sort (nodes/sort.rs). One pass sorts
// by one digit: a histogram kernel counts the digits of each tile, the counts are scanned
// in digit-major order (the scan kernels, or `offsets` on the tile paths), and a scatter
// kernel ranks each key stably inside its tile and writes keys and payload to their
// sorted places.

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
    // Tile paths: words from one digit's row of tile counts to the next (ntiles rounded
    // up to a multiple of 4, so that rows can be read as vec4).
    stride: u32,
    // Tile paths: index of this pass (its row of digit totals).
    index: u32,
}

fn digit_of(key: u32, cfg: Pass) -> u32 {
    return (key >> cfg.shift) & cfg.mask;
}
