// template: composed after a window (shaders/window/). nodes/chebyshev_spread.rs.
//
// One workgroup per particle: the window's factors per axis (z's times the quadrature
// weight) are computed once into workgroup memory, then its threads take the support's columns,
// each its z points, and sum u delta~; the 64 partial sums are added in
// a fixed tree order.
#import common/index.wgsl

@group(0) @binding(0) var<storage, read> pos: array<f32>;
@group(0) @binding(1) var<storage, read> grid: array<f32>;
@group(0) @binding(2) var<storage, read_write> out: array<f32>;
@group(0) @binding(3) var<uniform> geo: Geometry;
@group(0) @binding(4) var<storage, read> table: array<f32>;

#import chebyshev/grid.wgsl

var<workgroup> partial: array<vec4<f32>, 64>;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let p = wid.y * nwg.x + wid.x;
    // Every thread reaches the barriers: a workgroup past the particles sums nothing.
    let inside = p < geo.n.w;
    let pp = min(p, max(geo.n.w, 1u) - 1u);
    let comps = geo.shape.y;
    let sp = particle_support(pp, lid, true);
    let side = geo.shape.x + 1u;
    let plane = geo.n.x * geo.n.y;
    var acc = vec4<f32>(0.0);
    // One column per thread, its z points in turn (the factors from workgroup memory).
    // No test in the z loop, so its loads can be issued together.
    let zt = nonzero_z(sp, true);
    let comp_stride = geo.n.z * plane;
    for (var c = lid; c < side * side; c += 64u) {
        let wxy = column_weight(c);
        if (wxy == 0.0) {
            continue;
        }
        var at = (sp.zr.x + zt.x) * plane + column_cell(c, sp);
        for (var jt = zt.x; jt < zt.y; jt++) {
            let w = wxy * cached_z(jt, sp.zr, sp.qz, true);
            acc.x += w * grid[at];
            if (comps > 1u) {
                acc.y += w * grid[at + comp_stride];
            }
            if (comps > 2u) {
                acc.z += w * grid[at + 2u * comp_stride];
            }
            if (comps > 3u) {
                acc.w += w * grid[at + 3u * comp_stride];
            }
            at += plane;
        }
    }
    partial[lid] = acc;
    workgroupBarrier();
    for (var stride = 32u; stride > 0u; stride >>= 1u) {
        if (lid < stride) {
            partial[lid] += partial[lid + stride];
        }
        workgroupBarrier();
    }
    if (lid == 0u && inside) {
        for (var k = 0u; k < comps; k++) {
            out[comps * p + k] = partial[0][k];
        }
    }
}
