// template: composed with a window file (window_phi) and an add file (grid_add, binding 2).
//
// Spreading, one workgroup per particle: f[c][cell] += delta(r_cell - q) F[c], with the
// separable window's DIMS x NS weights computed once into workgroup memory and the
// NS^DIMS support cells shared among the threads.
#import common/index.wgsl
#import spread/geometry.wgsl

override NS: u32 = 4u;
override DIMS: u32 = 3u;
override COMPS: u32 = 1u;
const WG: u32 = 64u;

@group(0) @binding(0) var<storage, read> pos: array<f32>;
@group(0) @binding(1) var<storage, read> vals: array<f32>;
@group(0) @binding(3) var<uniform> geo: Geometry;

var<workgroup> weights: array<f32, 96>;
var<workgroup> first: array<i32, 3>;
var<workgroup> value: array<f32, 4>;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let p = wid.y * nwg.x + wid.x;
    if (p >= geo.count) {
        return;
    }
    if (lid < DIMS * NS) {
        let a = lid / NS;
        let k = lid % NS;
        let t = centre_units(pos[p * DIMS + a], a, geo);
        let j0 = floor(t - 0.5 * f32(NS)) + 1.0;
        weights[lid] = window_phi(j0 + f32(k) - t, geo.win[a]) * geo.inv_h[a];
        if (k == 0u) {
            first[a] = i32(j0);
        }
    }
    if (lid < COMPS) {
        value[lid] = vals[p * COMPS + lid];
    }
    workgroupBarrier();
    var total = NS * NS;
    if (DIMS == 3u) {
        total = total * NS;
    }
    let cells = geo.n.w;
    for (var j = lid; j < total; j = j + WG) {
        let ix = j % NS;
        let iy = (j / NS) % NS;
        var w = weights[ix] * weights[NS + iy];
        var cz = 0u;
        if (DIMS == 3u) {
            let iz = j / (NS * NS);
            w = w * weights[2u * NS + iz];
            cz = wrap_cell(first[2] + i32(iz), geo.n.z);
        }
        let cell = wrap_cell(first[0] + i32(ix), geo.n.x) + geo.n.x * (wrap_cell(first[1] + i32(iy), geo.n.y) + geo.n.y * cz);
        for (var c = 0u; c < COMPS; c = c + 1u) {
            grid_add(c * cells + cell, w * value[c]);
        }
    }
}
