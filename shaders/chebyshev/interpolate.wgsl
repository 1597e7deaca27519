// template: composed after a window (shaders/window/). nodes/chebyshev_spread.rs.
//
// One workgroup per particle; its threads take the (support + 1)^2 columns in turn and
// sum u delta~ times the quadrature weight over each column's z points; the 64 partial
// sums are added in a fixed tree order.
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
    let s = geo.shape.x;
    let comps = geo.shape.y;
    let ux = centre_units(pos[3u * pp], 0u);
    let uy = centre_units(pos[3u * pp + 1u], 1u);
    let qz = pos[3u * pp + 2u];
    let x0 = i32(ceil(ux - geo.radius.x));
    let y0 = i32(ceil(uy - geo.radius.x));
    let zr = z_range(qz);
    let side = s + 1u;
    let plane = geo.n.x * geo.n.y;
    var acc = vec4<f32>(0.0);
    for (var c = lid; c < side * side; c += 64u) {
        let ix = x0 + i32(c % side);
        let iy = y0 + i32(c / side);
        let wxy = phi_x(f32(ix) - ux) * phi_y(f32(iy) - uy);
        if (wxy == 0.0) {
            continue;
        }
        let cell = wrap_cell(ix, geo.n.x) + geo.n.x * wrap_cell(iy, geo.n.y);
        for (var j = zr.x; j <= zr.y; j++) {
            let w = wxy * z_kernel(z_point(j), qz) * z_weight(j);
            if (w == 0.0) {
                continue;
            }
            for (var k = 0u; k < comps; k++) {
                acc[k] += w * grid[(k * geo.n.z + j) * plane + cell];
            }
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
