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
        r[c] = r[c] + w * dv * grid[(geo.comp_offset + c) * cells + cell];
    }
    return r;
}

// This thread's share of its particle's sum (zero for threads without a particle).
// Variant: support 8 in 3D written out (all eight z loads of a column issued together).
fn column_sums(lid: u32, seg: u32, ppw: u32) -> vec4<f32> {
    let s = lid / seg;
    var acc = vec4<f32>(0.0);
    if (s < ppw && stencil_p[s] < geo.count) {
        let tw = s * DIMS * NS;
        let cells = geo.n.w;
        for (var pair = lid % seg; pair < NS * NS; pair = pair + seg) {
            let ix = pair % NS;
            let iy = pair / NS;
            let wxy = stencil_w[tw + ix] * stencil_w[tw + NS + iy];
            let oxy = stencil_o[tw + ix] + stencil_o[tw + NS + iy];
            let tz = tw + 2u * NS;
            let o0 = oxy + stencil_o[tz + 0u];
            let o1 = oxy + stencil_o[tz + 1u];
            let o2 = oxy + stencil_o[tz + 2u];
            let o3 = oxy + stencil_o[tz + 3u];
            let o4 = oxy + stencil_o[tz + 4u];
            let o5 = oxy + stencil_o[tz + 5u];
            let o6 = oxy + stencil_o[tz + 6u];
            let o7 = oxy + stencil_o[tz + 7u];
            let b0 = geo.comp_offset * cells;
            acc[0] = acc[0] + wxy * geo.dv * (stencil_w[tz + 0u] * grid[b0 + o0] + stencil_w[tz + 1u] * grid[b0 + o1] + stencil_w[tz + 2u] * grid[b0 + o2] + stencil_w[tz + 3u] * grid[b0 + o3] + stencil_w[tz + 4u] * grid[b0 + o4] + stencil_w[tz + 5u] * grid[b0 + o5] + stencil_w[tz + 6u] * grid[b0 + o6] + stencil_w[tz + 7u] * grid[b0 + o7]);
            if (COMPS > 1u) {
                let b1 = b0 + cells;
            acc[1] = acc[1] + wxy * geo.dv * (stencil_w[tz + 0u] * grid[b1 + o0] + stencil_w[tz + 1u] * grid[b1 + o1] + stencil_w[tz + 2u] * grid[b1 + o2] + stencil_w[tz + 3u] * grid[b1 + o3] + stencil_w[tz + 4u] * grid[b1 + o4] + stencil_w[tz + 5u] * grid[b1 + o5] + stencil_w[tz + 6u] * grid[b1 + o6] + stencil_w[tz + 7u] * grid[b1 + o7]);
            }
            if (COMPS > 2u) {
                let b2 = b0 + 2u * cells;
            acc[2] = acc[2] + wxy * geo.dv * (stencil_w[tz + 0u] * grid[b2 + o0] + stencil_w[tz + 1u] * grid[b2 + o1] + stencil_w[tz + 2u] * grid[b2 + o2] + stencil_w[tz + 3u] * grid[b2 + o3] + stencil_w[tz + 4u] * grid[b2 + o4] + stencil_w[tz + 5u] * grid[b2 + o5] + stencil_w[tz + 6u] * grid[b2 + o6] + stencil_w[tz + 7u] * grid[b2 + o7]);
            }
            if (COMPS > 3u) {
                let b3 = b0 + 3u * cells;
            acc[3] = acc[3] + wxy * geo.dv * (stencil_w[tz + 0u] * grid[b3 + o0] + stencil_w[tz + 1u] * grid[b3 + o1] + stencil_w[tz + 2u] * grid[b3 + o2] + stencil_w[tz + 3u] * grid[b3 + o3] + stencil_w[tz + 4u] * grid[b3 + o4] + stencil_w[tz + 5u] * grid[b3 + o5] + stencil_w[tz + 6u] * grid[b3 + o6] + stencil_w[tz + 7u] * grid[b3 + o7]);
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
