// template: imported by the kernels that file particles by their first support cell (the
// box kernel, tiled spreading); the importer defines NS.

// The first support cell (unwrapped) of a coordinate t in cell-centre units: the NS cells
// nearest to t start here.
fn first_cell(t: f32) -> i32 {
    return i32(floor(t - 0.5 * f32(NS))) + 1;
}
