// template: composed after `const SEG`, `const LANES_WG`, a window (shaders/window/) and an add
// (shaders/spread/add_*.wgsl, which binds `grid` at 2 and defines grid_add).
// nodes/chebyshev_spread.rs, kernel `lanes`: see chebyshev/lanes.wgsl. Each lane adds
// its column's value at every z point of the support: one warp instruction per point and
// component covers the support's rows in that plane (runs of consecutive grid words).
@group(0) @binding(0) var<storage, read> pos: array<f32>;
@group(0) @binding(1) var<storage, read> vals: array<f32>;
@group(0) @binding(3) var<uniform> geo: Geometry;
@group(0) @binding(4) var<storage, read> table: array<f32>;

#import chebyshev/grid.wgsl
#import chebyshev/lanes.wgsl

@compute @workgroup_size(LANES_WG)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32,
        @builtin(subgroup_invocation_id) lane: u32) {
    let lp = lane_particle(wid.y * nwg.x + wid.x, lid, lane, false);
    let sp = lp.sp;
    let comps = geo.shape.y;
    var v = vec4<f32>(0.0);
    for (var c = 0u; c < comps; c++) {
        v[c] = vals[comps * lp.pp + c];
    }
    let plane = geo.n.x * geo.n.y;
    let comp_stride = geo.n.z * plane;
    for (var b = 0u; b < lp.columns; b += SEG) {
        let col = lane_column(sp, b + lp.k);
        var at = sp.zr.x * plane + col.cell;
        for (var t = 0u; t < lp.count; t++) {
            let wz = lane_z(sp, t, lp.base, false);
            if (wz != 0.0 && col.w != 0.0) {
                let w = col.w * wz;
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
            }
            at += plane;
        }
    }
}
