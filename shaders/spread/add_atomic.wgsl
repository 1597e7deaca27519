// Grid accumulation with float atomics (SHADER_FLOAT32_ATOMIC).
@group(0) @binding(2) var<storage, read_write> grid: array<atomic<f32>>;

fn grid_add(i: u32, v: f32) {
    atomicAdd(&grid[i], v);
}
