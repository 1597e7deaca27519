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
    let comps = geo.shape.y;
    let sp = particle_support(p, lid, false);
    let side = geo.shape.x + 1u;
    let plane = geo.n.x * geo.n.y;
    var v = vec4<f32>(0.0);
    for (var k = 0u; k < comps; k++) {
        v[k] = vals[comps * p + k];
    }
    // One column per thread, its z points in turn (the factors from workgroup memory).
    // No test in the z loop but the components'.
    let zt = nonzero_z(sp, false);
    let comp_stride = geo.n.z * plane;
    for (var c = lid; c < side * side; c += 64u) {
        let wxy = column_weight(c);
        if (wxy == 0.0) {
            continue;
        }
        var at = (sp.zr.x + zt.x) * plane + column_cell(c, sp);
        for (var jt = zt.x; jt < zt.y; jt++) {
            let w = wxy * cached_z(jt, sp.zr, sp.qz, false);
            grid_add(at, w * v.x);
            if (comps > 1u) {
                grid_add(at + comp_stride, w * v.y);
            }
            if (comps > 2u) {
                grid_add(at + 2u * comp_stride, w * v.z);
            }
            if (comps > 3u) {
                grid_add(at + 3u * comp_stride, w * v.w);
            }
            at += plane;
        }
    }
}
