// template: composed with a window file (window_phi).
//
// Interpolation, one workgroup per particle: u[c] = sum over the support of
// delta(q - r_cell) v[c][cell] dV(cell), the adjoint of spreading with the same window
// (dV: per-cell weights when HAS_WEIGHTS, else the uniform cell volume).
#import common/index.wgsl
#import spread/geometry.wgsl

override NS: u32 = 4u;
override DIMS: u32 = 3u;
override COMPS: u32 = 1u;
override HAS_WEIGHTS: bool = false;
const WG: u32 = 64u;

@group(0) @binding(0) var<storage, read> pos: array<f32>;
@group(0) @binding(1) var<storage, read> grid: array<f32>;
@group(0) @binding(2) var<storage, read> quadrature: array<f32>;
@group(0) @binding(3) var<storage, read_write> out: array<f32>;
@group(0) @binding(4) var<uniform> geo: Geometry;

var<workgroup> weights: array<f32, 96>;
var<workgroup> first: array<i32, 3>;
var<workgroup> partial: array<vec4<f32>, 64>;

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
    workgroupBarrier();
    var total = NS * NS;
    if (DIMS == 3u) {
        total = total * NS;
    }
    let cells = geo.n.w;
    var acc = vec4<f32>(0.0);
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
        var dv = geo.dv;
        if (HAS_WEIGHTS) {
            dv = quadrature[cell];
        }
        for (var c = 0u; c < COMPS; c = c + 1u) {
            acc[c] = acc[c] + w * dv * grid[c * cells + cell];
        }
    }
    partial[lid] = acc;
    workgroupBarrier();
    for (var s = WG / 2u; s > 0u; s = s >> 1u) {
        if (lid < s) {
            partial[lid] = partial[lid] + partial[lid + s];
        }
        workgroupBarrier();
    }
    if (lid < COMPS) {
        out[p * COMPS + lid] = partial[0][lid];
    }
}
