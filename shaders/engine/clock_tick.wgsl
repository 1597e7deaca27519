// Advances the engine clock by one step at the end of each step, so a multi-step run
// needs no host write between steps. clock[0] is the step index nodes read.
@group(0) @binding(0) var<storage, read_write> clock: array<u32>;

@compute @workgroup_size(1)
fn main() {
    clock[0] = clock[0] + 1u;
}
