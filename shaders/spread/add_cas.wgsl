// Grid accumulation for adapters without float atomics: compare-and-swap on the bits.
@group(0) @binding(2) var<storage, read_write> grid: array<atomic<u32>>;

fn grid_add(i: u32, v: f32) {
    var old = atomicLoad(&grid[i]);
    loop {
        let r = atomicCompareExchangeWeak(&grid[i], old, bitcast<u32>(bitcast<f32>(old) + v));
        if (r.exchanged) {
            break;
        }
        old = r.old_value;
    }
}
