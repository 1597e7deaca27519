// template: composed with a window file (window_phi) and imported by
// spread/interpolate.wgsl and spread/interpolate_subgroup.wgsl.
//
// Interpolation: u[c] = sum over the support of delta(q - r_cell) v[c][cell] dV(cell),
// the adjoint of spreading with the same window and stencil (dV: per-cell weights when
// HAS_WEIGHTS, else the uniform cell volume). Each thread sums its columns of one
// particle's support; the entry points then reduce each particle's segment of threads
// (segments are powers of two).
#import common/index.wgsl
#import spread/geometry.wgsl
#import spread/stencil.wgsl

override NS: u32 = 4u;
override DIMS: u32 = 3u;
override COMPS: u32 = 1u;   // components in this dispatch (at most 4)
override TOTAL: u32 = 1u;   // components per particle
override HAS_WEIGHTS: bool = false;

@group(0) @binding(0) var<storage, read> pos: array<f32>;
@group(0) @binding(1) var<storage, read> grid: array<f32>;
@group(0) @binding(2) var<storage, read> quadrature: array<f32>;
@group(0) @binding(3) var<storage, read_write> out: array<f32>;
@group(0) @binding(4) var<uniform> geo: Geometry;

var<workgroup> partial: array<vec4<f32>, 256>;

fn sample(cell: u32, w: f32, acc: vec4<f32>) -> vec4<f32> {
    var dv = geo.dv;
    if (HAS_WEIGHTS) {
        dv = quadrature[cell];
    }
    var r = acc;
    let cells = geo.n.w;
    for (var c = 0u; c < COMPS; c = c + 1u) {
        r[c] = r[c] + w * dv * f32(cell & 7u);
    }
    return r;
}

// This thread's share of its particle's sum (zero for threads without a particle).
fn column_sums(lid: u32, seg: u32, ppw: u32) -> vec4<f32> {
    let s = lid / seg;
    var acc = vec4<f32>(0.0);
    if (s < ppw && stencil_p[s] < geo.count) {
        let tw = s * DIMS * NS;
        for (var pair = lid % seg; pair < NS * NS; pair = pair + seg) {
            let ix = pair % NS;
            let iy = pair / NS;
            let wxy = stencil_w[tw + ix] * stencil_w[tw + NS + iy];
            let oxy = stencil_o[tw + ix] + stencil_o[tw + NS + iy];
            if (DIMS == 2u) {
                acc = sample(oxy, wxy, acc);
            } else {
                for (var iz = 0u; iz < NS; iz = iz + 1u) {
                    acc = sample(oxy + stencil_o[tw + 2u * NS + iz], wxy * stencil_w[tw + 2u * NS + iz], acc);
                }
            }
        }
    }
    return acc;
}

// Writes particle `slot`'s sum, component by component.
fn store(slot: u32, c: u32, v: f32) {
    let p = stencil_p[slot];
    if (p < geo.count) {
        out[p * TOTAL + geo.comp_offset + c] = v;
    }
}
