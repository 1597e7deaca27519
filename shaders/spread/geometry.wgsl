// template: imported by kernels that declare the uniform `geo: Geometry` (spread/*.wgsl,
// nodes/spread/*gen.rs). Grid geometry and window params shared by spreading and
// interpolation. Cells are centred at -L/2 + (j + 1/2) h per axis (boxes centred at the
// origin, periodic).
struct Geometry {
    n: vec4<u32>,          // cells per axis (nz = 1 in 2D); w: all cells
    inv_h: vec4<f32>,      // 1 / cell size per axis
    box_len: vec4<f32>,    // L per axis
    inv_box: vec4<f32>,    // 1 / L per axis
    win: array<vec4<f32>, 3>, // window params per axis
    count: u32,            // particles
    dv: f32,               // uniform quadrature weight h_x h_y (h_z)
    comp_offset: u32,      // first component of this dispatch (components go 4 at a time)
    run: u32,              // box kernels: particles per workgroup (at most 64)
}

fn wrap_cell(i: i32, n: u32) -> u32 {
    let m = i32(n);
    return u32(((i % m) + m) % m);
}

// Position of particle coordinate x along axis a in cell-centre units (cell j's centre is
// at j), after folding x into the box (keeps f32 precision for unwrapped trajectories).
// Reads the kernel's `geo` uniform itself: a Geometry passed by value and indexed by the
// axis is the construct that makes lavapipe recompile a kernel at every dispatch
// (mpcd/common.wgsl, cell_of).
fn centre_units(x: f32, a: u32) -> f32 {
    let folded = x - geo.box_len[a] * floor(x * geo.inv_box[a] + 0.5);
    return (folded + 0.5 * geo.box_len[a]) * geo.inv_h[a] - 0.5;
}
