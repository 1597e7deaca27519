// template: composed after `const SEG`, `const LANES_WG` and a window (shaders/window/).
// nodes/chebyshev_spread.rs, kernel `lanes`: see chebyshev/lanes.wgsl. Each lane sums its
// columns' u delta~ over the support's z points (the z factor times the quadrature
// weight), then a shuffle butterfly adds the segment, in a fixed order.
@group(0) @binding(0) var<storage, read> pos: array<f32>;
@group(0) @binding(1) var<storage, read> grid: array<f32>;
@group(0) @binding(2) var<storage, read_write> out: array<f32>;
@group(0) @binding(3) var<uniform> geo: Geometry;
@group(0) @binding(4) var<storage, read> table: array<f32>;

#import chebyshev/grid.wgsl
#import chebyshev/lanes.wgsl

@compute @workgroup_size(LANES_WG)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32,
        @builtin(subgroup_invocation_id) lane: u32) {
    let lp = lane_particle(wid.y * nwg.x + wid.x, lid, lane, true);
    let sp = lp.sp;
    let comps = geo.shape.y;
    let plane = geo.n.x * geo.n.y;
    let comp_stride = geo.n.z * plane;
    var acc = vec4<f32>(0.0);
    for (var b = 0u; b < lp.columns; b += SEG) {
        let col = lane_column(sp, b + lp.k);
        var at = sp.zr.x * plane + col.cell;
        for (var t = 0u; t < lp.count; t++) {
            let wz = lane_z(sp, t, lp.base, true);
            if (wz != 0.0 && col.w != 0.0) {
                let w = col.w * wz;
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
            }
            at += plane;
        }
    }
    // Every lane of every segment: the butterfly stays inside the segment.
    for (var o = SEG / 2u; o > 0u; o >>= 1u) {
        acc += subgroupShuffleXor(acc, o);
    }
    if (lp.live && lp.k == 0u) {
        for (var c = 0u; c < comps; c++) {
            out[comps * lp.p + c] = acc[c];
        }
    }
}
