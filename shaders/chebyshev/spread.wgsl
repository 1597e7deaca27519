// template: composed after a window (shaders/window/) and an add (shaders/spread/add_*.wgsl,
// which binds `grid` at 2 and defines grid_add). nodes/chebyshev_spread.rs.
//
// One workgroup per particle: the window's factors per axis are computed once into
// workgroup memory, then its threads take the support's columns, each its z points: grid += v delta~ (a density).
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
    fill_factors(lid, ux, uy, qz, x0, y0, zr, false);
    let side = s + 1u;
    let columns = side * side;
    let plane = geo.n.x * geo.n.y;
    var v = vec4<f32>(0.0);
    for (var k = 0u; k < comps; k++) {
        v[k] = vals[comps * p + k];
    }
    // One column per thread, its z points in turn (the factors from workgroup memory).
    let nz_support = zr.y - zr.x + 1u;
    for (var c = lid; c < columns; c += 64u) {
        let wxy = factor_x[c % side] * factor_y[c / side];
        if (wxy == 0.0) {
            continue;
        }
        let cell = wrap_cell(x0 + i32(c % side), geo.n.x) + geo.n.x * wrap_cell(y0 + i32(c / side), geo.n.y);
        for (var jt = 0u; jt < nz_support; jt++) {
            let w = wxy * cached_z(jt, zr, qz, false);
            if (w == 0.0) {
                continue;
            }
            let j = zr.x + jt;
            for (var k = 0u; k < comps; k++) {
                grid_add((k * geo.n.z + j) * plane + cell, w * v[k]);
            }
        }
    }
}
