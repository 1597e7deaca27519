// template: composed with a window file (window_phi) and an add file (grid_add, binding 2).
//
// Spreading: f[c][cell] += delta(r_cell - q) F[c] over each particle's support (see
// spread/stencil.wgsl for the thread layout).
#import common/index.wgsl
#import spread/geometry.wgsl
#import spread/stencil.wgsl

override NS: u32 = 4u;
override DIMS: u32 = 3u;
override COMPS: u32 = 1u;   // components in this dispatch (at most 4)
override TOTAL: u32 = 1u;   // components per particle

@group(0) @binding(0) var<storage, read> pos: array<f32>;
@group(0) @binding(1) var<storage, read> vals: array<f32>;
@group(0) @binding(3) var<uniform> geo: Geometry;

var<workgroup> value: array<f32, 512>;  // up to 128 particles x 4 components

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let seg = seg_size();
    let ppw = WG / seg;
    let first_slot = (wid.y * nwg.x + wid.x) * ppw;
    stencil_setup(first_slot, lid, ppw);
    if (lid < ppw * COMPS) {
        let p = slot_particle(first_slot + lid / COMPS);
        if (p < geo.count) {
            value[lid] = vals[p * TOTAL + geo.comp_offset + lid % COMPS];
        }
    }
    workgroupBarrier();
    let s = lid / seg;
    if (s >= ppw || stencil_p[s] >= geo.count) {
        return;
    }
    let tw = s * DIMS * NS;
    let cells = geo.n.w;
    for (var pair = lid % seg; pair < NS * NS; pair = pair + seg) {
        let ix = pair % NS;
        let iy = pair / NS;
        let wxy = stencil_w[tw + ix] * stencil_w[tw + NS + iy];
        let oxy = stencil_o[tw + ix] + stencil_o[tw + NS + iy];
        if (DIMS == 2u) {
            for (var c = 0u; c < COMPS; c = c + 1u) {
                grid_add((geo.comp_offset + c) * cells + oxy, wxy * value[s * COMPS + c]);
            }
        } else {
            for (var iz = 0u; iz < NS; iz = iz + 1u) {
                let w = wxy * stencil_w[tw + 2u * NS + iz];
                let cell = oxy + stencil_o[tw + 2u * NS + iz];
                for (var c = 0u; c < COMPS; c = c + 1u) {
                    grid_add((geo.comp_offset + c) * cells + cell, w * value[s * COMPS + c]);
                }
            }
        }
    }
}
