// template: composed after a window (shaders/window/) and an add (shaders/spread/add_*.wgsl,
// which binds `grid` at 2 and defines grid_add). nodes/chebyshev_spread.rs.
//
// One workgroup per particle; its threads take the (support + 1)^2 columns in turn, each
// column its z points within the support: grid += v delta~ (a density).
#import common/index.wgsl

@group(0) @binding(0) var<storage, read> pos: array<f32>;
@group(0) @binding(1) var<storage, read> vals: array<f32>;
@group(0) @binding(3) var<uniform> geo: Geometry;
@group(0) @binding(4) var<storage, read> table: array<f32>;

#import chebyshev/grid.wgsl

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let p = wid.y * nwg.x + wid.x;
    if (p >= geo.n.w) {
        return;
    }
    let s = geo.shape.x;
    let comps = geo.shape.y;
    let ux = centre_units(pos[3u * p], 0u);
    let uy = centre_units(pos[3u * p + 1u], 1u);
    let qz = pos[3u * p + 2u];
    let x0 = i32(ceil(ux - geo.radius.x));
    let y0 = i32(ceil(uy - geo.radius.x));
    let zr = z_range(qz);
    let side = s + 1u;
    let plane = geo.n.x * geo.n.y;
    for (var c = lid; c < side * side; c += 64u) {
        let ix = x0 + i32(c % side);
        let iy = y0 + i32(c / side);
        let wxy = phi_x(f32(ix) - ux) * phi_y(f32(iy) - uy);
        if (wxy == 0.0) {
            continue;
        }
        let cell = wrap_cell(ix, geo.n.x) + geo.n.x * wrap_cell(iy, geo.n.y);
        for (var j = zr.x; j <= zr.y; j++) {
            let w = wxy * z_kernel(z_point(j), qz);
            if (w == 0.0) {
                continue;
            }
            for (var k = 0u; k < comps; k++) {
                grid_add((k * geo.n.z + j) * plane + cell, w * vals[comps * p + k]);
            }
        }
    }
}
