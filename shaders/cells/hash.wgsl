// Cell index of each particle in a box centred at the origin: along each axis,
// i = floor(x * n / L + n / 2), wrapped into [0, n) on periodic axes (any number of box
// lengths away) and clamped on the others. Linear order: ix + nx * (iy + ny * iz).
// Morton order: the bits of (ix, iy, iz) interleaved (10 bits per axis in 3D, 16 in 2D),
// so cells close in space get close keys.
#import common/index.wgsl

override DIMS: u32 = 3u;
override MORTON: bool = false;

struct Grid {
    scale: vec4<f32>,     // n / L per axis
    half: vec4<f32>,      // n / 2 per axis
    cells: vec4<u32>,     // n per axis
    periodic: vec4<u32>,  // 1 for a periodic axis
    n: u32,
}

@group(0) @binding(0) var<storage, read> pos: array<f32>;
@group(0) @binding(1) var<storage, read_write> out: array<u32>;
@group(0) @binding(2) var<uniform> grid: Grid;

fn axis_cell(x: f32, a: u32) -> u32 {
    let n = i32(grid.cells[a]);
    let i = i32(floor(fma(x, grid.scale[a], grid.half[a])));
    if (grid.periodic[a] == 1u) {
        return u32(((i % n) + n) % n);
    }
    return u32(clamp(i, 0, n - 1));
}

// Spreads the low 10 bits of v so that two zero bits separate them.
fn spread3(v: u32) -> u32 {
    var x = v & 0x3ffu;
    x = (x | (x << 16u)) & 0x030000ffu;
    x = (x | (x << 8u)) & 0x0300f00fu;
    x = (x | (x << 4u)) & 0x030c30c3u;
    x = (x | (x << 2u)) & 0x09249249u;
    return x;
}

// Spreads the low 16 bits of v so that one zero bit separates them.
fn spread2(v: u32) -> u32 {
    var x = v & 0xffffu;
    x = (x | (x << 8u)) & 0x00ff00ffu;
    x = (x | (x << 4u)) & 0x0f0f0f0fu;
    x = (x | (x << 2u)) & 0x33333333u;
    x = (x | (x << 1u)) & 0x55555555u;
    return x;
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let p = flat_index(wid, nwg, lid, 256u);
    if (p >= grid.n) {
        return;
    }
    let ix = axis_cell(pos[p * DIMS], 0u);
    let iy = axis_cell(pos[p * DIMS + 1u], 1u);
    var iz = 0u;
    if (DIMS == 3u) {
        iz = axis_cell(pos[p * DIMS + 2u], 2u);
    }
    if (MORTON) {
        if (DIMS == 3u) {
            out[p] = spread3(ix) | (spread3(iy) << 1u) | (spread3(iz) << 2u);
        } else {
            out[p] = spread2(ix) | (spread2(iy) << 1u);
        }
    } else {
        out[p] = ix + grid.cells.x * (iy + grid.cells.y * iz);
    }
}
