// template: composed with a window file (window_phi) and an add file (grid_add, binding 2).
//
// Spreading of particles sorted in space, box by box (see spread/box.wgsl): a workgroup
// takes up to P consecutive particles and sums their contributions over the box in
// registers, one thread per (x, y) column of the box holding all its z cells, then adds
// each nonzero box cell to the grid once: P NS^3 grid atomics become one per box cell
// (about 25x fewer at support 8, density 1). The sums are dense over the box (weights
// zero-padded), so the inner loop is a broadcast load and a fused multiply-add. A run
// whose box is larger than BMAX per axis (unsorted or sparse input) spreads directly,
// one atomic per support cell. One dispatch carries up to 4 components.
#import common/index.wgsl
#import spread/geometry.wgsl
#import spread/box.wgsl

override NS: u32 = 8u;
override DIMS: u32 = 3u;
override COMPS: u32 = 1u;   // components in this dispatch (at most 4)
override TOTAL: u32 = 1u;   // components per particle

@group(0) @binding(0) var<storage, read> pos: array<f32>;
@group(0) @binding(1) var<storage, read> vals: array<f32>;
@group(0) @binding(3) var<uniform> geo: Geometry;

var<workgroup> value: array<vec4<f32>, 64>;   // P particles' components

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let p0 = (wid.y * nwg.x + wid.x) * P;
    let count = min(P, select(0u, geo.count - p0, p0 < geo.count));
    if (lid < P) {
        var v = vec4<f32>(0.0);
        if (lid < count) {
            for (var c = 0u; c < COMPS; c = c + 1u) {
                v[c] = vals[(p0 + lid) * TOTAL + geo.comp_offset + c];
            }
        }
        value[lid] = v;
    }
    let b = box_setup(p0, count, lid);
    let cells = geo.n.w;
    if (!b.fits) {
        let nz = select(1u, NS, DIMS == 3u);
        for (var q = lid; q < count * NS * NS; q = q + BOX_WG) {
            let s = q / (NS * NS);
            let ix = q % NS;
            let iy = (q / NS) % NS;
            let wxy = direct_weight(s, 0u, ix) * direct_weight(s, 1u, iy);
            for (var iz = 0u; iz < nz; iz = iz + 1u) {
                let w = wxy * direct_weight(s, 2u, iz);
                let cell = direct_cell(s, ix, iy, iz);
                for (var c = 0u; c < COMPS; c = c + 1u) {
                    grid_add((geo.comp_offset + c) * cells + cell, w * value[s][c]);
                }
            }
        }
        return;
    }
    let x = lid % b.n.x;
    let y = min(lid / b.n.x, BMAX - 1u);
    let owner = lid < b.n.x * b.n.y;
    let zmax = select(1u, BMAX, DIMS == 3u);
    if (COMPS == 1u) {
        var acc: array<f32, 16>;
        for (var s = 0u; s < count; s = s + 1u) {
            let a = box_w[(s * 3u) * BMAX + x] * box_w[(s * 3u + 1u) * BMAX + y];
            if (a != 0.0) {
                let av = a * value[s].x;
                let wz = (s * 3u + 2u) * BMAX;
                for (var z = 0u; z < zmax; z = z + 1u) {
                    acc[z] = fma(box_w[wz + z], av, acc[z]);
                }
            }
        }
        if (owner) {
            for (var z = 0u; z < b.n.z; z = z + 1u) {
                if (acc[z] != 0.0) {
                    grid_add(geo.comp_offset * cells + box_cell(b, x, y, z), acc[z]);
                }
            }
        }
    } else {
        var acc: array<vec4<f32>, 16>;
        for (var s = 0u; s < count; s = s + 1u) {
            let a = box_w[(s * 3u) * BMAX + x] * box_w[(s * 3u + 1u) * BMAX + y];
            if (a != 0.0) {
                let av = a * value[s];
                let wz = (s * 3u + 2u) * BMAX;
                for (var z = 0u; z < zmax; z = z + 1u) {
                    acc[z] = fma(vec4<f32>(box_w[wz + z]), av, acc[z]);
                }
            }
        }
        if (owner) {
            for (var z = 0u; z < b.n.z; z = z + 1u) {
                let cell = box_cell(b, x, y, z);
                for (var c = 0u; c < COMPS; c = c + 1u) {
                    if (acc[z][c] != 0.0) {
                        grid_add((geo.comp_offset + c) * cells + cell, acc[z][c]);
                    }
                }
            }
        }
    }
}
