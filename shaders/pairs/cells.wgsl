// template: shared by the cell-list traversals (neighbour_sum.wgsl, neighbour_list.wgsl), which
// bind `pos` and `geo`: the geometry, positions, and the cell offsets to visit. DIM is
// the positions' columns: 3, or 2 for a plane (z read as 0; the host gives the padded z
// axis one open cell, so every walk visits z offset 0 only).

override DIM: u32 = 3u;

struct Geometry {
    lengths: vec4<f32>,
    cells: vec4<u32>,
    periodic: vec4<u32>,
    n: u32,
    cutoff2: f32,
}

fn load3(a: u32) -> vec3<f32> {
    if (DIM == 2u) {
        return vec3<f32>(pos[2u * a], pos[2u * a + 1u], 0.0);
    }
    return vec3<f32>(pos[3u * a], pos[3u * a + 1u], pos[3u * a + 2u]);
}

// The range of cell offsets to visit along one axis, as (first, last): 3 cells, or the
// distinct ones on periodic axes of fewer than 3 cells, or those inside on open axes.
fn offsets(c: i32, n: i32, periodic: bool) -> vec2<i32> {
    if (periodic) {
        if (n >= 3) {
            return vec2<i32>(-1, 1);
        }
        return vec2<i32>(0, n - 1);
    }
    return vec2<i32>(max(-1, -c), min(1, n - 1 - c));
}

// The cell coordinates of a linear cell index. The index comes from a graph's indices
// port and may be anything: it is clamped to the last cell (valid keys are unchanged),
// so every cell visited lies in the cell arrays (their lengths the host checks).
fn cell_coords(key: u32) -> vec3<i32> {
    let k = min(key, geo.cells.x * geo.cells.y * geo.cells.z - 1u);
    return vec3<i32>(i32(k % geo.cells.x), i32((k / geo.cells.x) % geo.cells.y),
                     i32(k / (geo.cells.x * geo.cells.y)));
}

// The sorted slots first..last of a cell's particles, clamped to 0..geo.n whatever
// cell_start and cell_count hold (a graph may wire its own arrays there): at most n
// iterations and no slot past the particles; a valid cell list is unchanged.
fn cell_slots(cell: u32) -> vec2<u32> {
    let first = min(cell_start[cell], geo.n);
    return vec2<u32>(first, first + min(cell_count[cell], geo.n - first));
}

// The displacement x_i - x_j, minimum image on the periodic axes.
fn displacement(xi: vec3<f32>, j: u32) -> vec3<f32> {
    return minimum_image(xi - load3(j));
}

// x_i - x_j folded to the nearest image on periodic axes.
fn minimum_image(r: vec3<f32>) -> vec3<f32> {
    let l = geo.lengths.xyz;
    return select(r, r - l * round(r / l), geo.periodic.xyz == vec3<u32>(1u));
}
