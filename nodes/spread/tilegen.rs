//! WGSL of the tile spreading kernel (the shared-memory method of cuFINUFFT; the tile
//! keys in shaders/spread/tiles.wgsl, sorted by bin_sort), generated for one support,
//! component count and segment width with every loop over the support written out.
//!
//! One workgroup serves one tile of TILE^3 cells: the particles filed under it (by their
//! first support cell) add their supports into the padded tile, P^3 cells with
//! P = TILE + support - 1, held in workgroup memory, and the tile then adds each nonzero
//! padded cell to the grid once. Why: on an H200 a float atomic add to the grid is bound
//! by the L2's rate of requests (a support-8 particle, 16 warp instructions of 4 rows of
//! 8 floats, spreads in 1.32 ns at best, the same in CUDA: BENCHMARKS.md), while
//! workgroup-memory integer atomics run about 8 times faster in the same pattern; at 0.1
//! particles per cell a padded tile takes 3375 grid adds for about 51 x 512.
//!
//! Workgroup memory has no float atomics in wgpu, so the tile sums fixed-point integers:
//! each component is scaled by 2^30 / B with B = PEAK x sum |v| over the tile's particles
//! (PEAK the largest weight one cell can get), which bounds every cell's sum, rounding
//! included, below 2^31. Each add is then exact to B / 2^31, about 2^-30 of the tile's
//! total: below the f32 rounding of the sums the other kernels do for every cell within
//! a few decades of the tile's largest. A tile whose B is zero adds nothing; one whose B is
//! not a normal float (NaN, infinite, below 1e-29) spreads directly with grid atomics, so
//! NaN still reaches the grid.
//!
//! The stencil follows interpgen.rs: a segment of `seg` subgroup lanes per particle, lane
//! k < NS evaluating support index k of every axis, the others fetching it by shuffle.

use std::fmt::Write;

/// Cells per tile edge.
pub const TILE: u32 = 8;

/// Threads per workgroup of the tile kernel.
const WG: u32 = 256;

/// Padded tile cells per axis for support `ns`.
pub fn padded(ns: u32) -> u32 {
    TILE + ns - 1
}

/// Tiles per axis of a grid.
pub fn tiles_per_axis(cells: &[u32]) -> Vec<u32> {
    cells.iter().map(|&n| n.div_ceil(TILE)).collect()
}

/// Most subgroups a workgroup holds on an adapter whose subgroups have at least
/// `min_subgroup` lanes.
fn max_subgroups(min_subgroup: u32) -> u32 {
    WG / min_subgroup.clamp(1, WG)
}

/// Bytes of workgroup memory the kernel takes for support `ns`, `comps` components and
/// subgroups of at least `min_subgroup` lanes.
pub fn workgroup_bytes(ns: u32, comps: u32, min_subgroup: u32) -> u32 {
    let p = padded(ns);
    4 * (comps * p * p * p + 3 * p + comps * max_subgroups(min_subgroup) + 4)
}

/// The tile kernel, composed after a window file (window_phi) and an add file
/// (grid_add, binding 2). Bindings: pos (0), vals (1), grid (2), geo (3), tiles (4),
/// count (5), start (6), order (7), local_anchor (8). `comps` components of the `total`
/// per particle, from geo.comp_offset; subgroups of at least `min_subgroup` lanes.
pub fn spread_source(ns: u32, comps: u32, total: u32, seg: u32, min_subgroup: u32) -> String {
    let p = padded(ns);
    let subgroups = max_subgroups(min_subgroup);
    let ppp = p * p * p;
    let mut w = String::new();
    let _ = write!(
        w,
        "#import spread/geometry.wgsl
#import spread/first_cell.wgsl

const NS: u32 = {ns}u;
const TILE: u32 = {TILE}u;
const P: u32 = {p}u;
const PPP: u32 = {ppp}u;
const COMPS: u32 = {comps}u;
const TOTAL: u32 = {total}u;
const SEG: u32 = {seg}u;
const WG: u32 = {WG}u;
const MAX_SUBGROUPS: u32 = {subgroups}u;
// The largest weight one support cell can get (the window's peak, per axis, multiplied).
override PEAK: f32 = 1.0;

struct Tiles {{
    nt: vec4<u32>,
}}

@group(0) @binding(0) var<storage, read> pos: array<f32>;
@group(0) @binding(1) var<storage, read> vals: array<f32>;
@group(0) @binding(3) var<uniform> geo: Geometry;
@group(0) @binding(4) var<uniform> tiles: Tiles;
@group(0) @binding(5) var<storage, read> count: array<u32>;
@group(0) @binding(6) var<storage, read> start: array<u32>;
@group(0) @binding(7) var<storage, read> order: array<u32>;
@group(0) @binding(8) var<storage, read> local_anchor: array<u32>;

// Fixed-point sums of the padded tile, component c at c * PPP, x fastest.
var<workgroup> acc: array<atomic<i32>, {acc_len}>;
// a * P + l: the grid cell of padded cell l along axis a (wrapped), times the axis stride.
var<workgroup> wrapped: array<u32, {wrap_len}>;
// Per component and subgroup: the sum of |v| over the subgroup's particles.
var<workgroup> partial: array<f32, {partial_len}>;
var<workgroup> header: array<u32, 2>;
var<workgroup> direct_flag: u32;

// Window weight (per unit length, as bits) of support index k on axis a for the
// particle at coordinate x, and the padded-tile offset (times the axis stride) of that
// support cell, the particle's anchor being at `anchor` inside the tile.
fn stencil_entry(x: f32, a: u32, k: u32, anchor: u32) -> vec2<u32> {{
    let t = centre_units(x, a);
    let j0 = first_cell(t);
    let w = window_phi(f32(j0 + i32(k)) - t, geo.win[a]) * geo.inv_h[a];
    var stride = 1u;
    if (a >= 1u) {{ stride = P; }}
    if (a == 2u) {{ stride = P * P; }}
    return vec2<u32>(bitcast<u32>(w), (anchor + k) * stride);
}}

// Support cell q (x fastest) of particle p added straight to the grid: the path of tiles
// whose scale is not a normal float.
fn direct_add(p: u32, q: u32) {{
    var w = 1.0;
    var cell = 0u;
    var stride = 1u;
    for (var a = 0u; a < 3u; a = a + 1u) {{
        let k = (q / select(select(1u, NS, a >= 1u), NS * NS, a == 2u)) % NS;
        let t = centre_units(pos[p * 3u + a], a);
        let j = first_cell(t) + i32(k);
        w = w * window_phi(f32(j) - t, geo.win[a]) * geo.inv_h[a];
        cell = cell + wrap_cell(j, geo.n[a]) * stride;
        stride = stride * geo.n[a];
    }}
    let b0 = geo.comp_offset * geo.n.w;
    for (var c = 0u; c < COMPS; c = c + 1u) {{
        grid_add(b0 + c * geo.n.w + cell, w * vals[p * TOTAL + geo.comp_offset + c]);
    }}
}}

@compute @workgroup_size({WG})
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32,
        @builtin(subgroup_invocation_id) lane: u32,
        @builtin(subgroup_size) sg_size: u32) {{
    let tile = wid.y * nwg.x + wid.x;
    if (tile >= tiles.nt.w) {{
        return;
    }}
    if (lid == 0u) {{
        header[0] = count[tile];
        header[1] = start[tile];
    }}
    let n_p = workgroupUniformLoad(&header[0]);
    if (n_p == 0u) {{
        return;
    }}
    let first = header[1];
    let tile_xyz = vec3<u32>(tile % tiles.nt.x, (tile / tiles.nt.x) % tiles.nt.y,
                             tile / (tiles.nt.x * tiles.nt.y));
    for (var i = lid; i < COMPS * PPP; i = i + WG) {{
        atomicStore(&acc[i], 0);
    }}
    if (lid < 3u * P) {{
        let a = lid / P;
        var stride = 1u;
        if (a >= 1u) {{ stride = geo.n.x; }}
        if (a == 2u) {{ stride = geo.n.x * geo.n.y; }}
        wrapped[lid] = wrap_cell(i32(tile_xyz[a] * TILE + lid % P), geo.n[a]) * stride;
    }}
",
        acc_len = comps * ppp,
        wrap_len = 3 * p,
        partial_len = comps * subgroups,
    );
    // Sum of |v| per component over the tile's particles.
    for c in 0..comps {
        let _ = writeln!(w, "    var s{c} = 0.0;");
    }
    w.push_str(
        "    for (var i = lid; i < n_p; i = i + WG) {
        let p = order[first + i];
",
    );
    for c in 0..comps {
        let _ = writeln!(
            w,
            "        s{c} = s{c} + abs(vals[p * TOTAL + geo.comp_offset + {c}u]);"
        );
    }
    w.push_str("    }\n");
    for c in 0..comps {
        let _ = writeln!(w, "    s{c} = subgroupAdd(s{c});");
    }
    w.push_str("    if (lane == 0u) {\n");
    for c in 0..comps {
        let _ = writeln!(
            w,
            "        partial[{c}u * MAX_SUBGROUPS + lid / sg_size] = s{c};"
        );
    }
    w.push_str(
        "    }
    workgroupBarrier();
    let subgroups = WG / sg_size;
",
    );
    // Every thread derives the scales (the same values); thread 0 also the direct flag.
    w.push_str("    var direct = false;\n");
    for c in 0..comps {
        let _ = write!(
            w,
            "    var bound{c} = 0.0;
    for (var g = 0u; g < subgroups; g = g + 1u) {{
        bound{c} = bound{c} + partial[{c}u * MAX_SUBGROUPS + g];
    }}
    bound{c} = PEAK * bound{c};
    var scale{c} = 0.0;
    if (bound{c} >= 1e-29 && bound{c} <= 3e38) {{
        scale{c} = 1073741824.0 / bound{c};
    }} else if (bitcast<u32>(bound{c}) != 0u) {{
        // NaN (every comparison false), infinite or too small to scale: go direct.
        direct = true;
    }}
"
        );
    }
    w.push_str(
        "    if (lid == 0u) {
        direct_flag = select(0u, 1u, direct);
    }
    if (workgroupUniformLoad(&direct_flag) == 1u) {
        for (var i = lid; i < n_p * NS * NS * NS; i = i + WG) {
            direct_add(order[first + i / (NS * NS * NS)], i % (NS * NS * NS));
        }
        return;
    }
    let k = lane % SEG;
    let base = lane - k;
    let per_round = WG / SEG;
    let rounds = (n_p + per_round - 1u) / per_round;
    for (var r = 0u; r < rounds; r = r + 1u) {
        let slot = r * per_round + lid / SEG;
        let live = slot < n_p;
        var p = 0u;
        if (live) {
            p = order[first + slot];
        }
        var e0 = vec2<u32>(0u);
        var e1 = vec2<u32>(0u);
        var e2 = vec2<u32>(0u);
        if (live && k < NS) {
            let la = local_anchor[p];
            e0 = stencil_entry(pos[p * 3u], 0u, k, la & 255u);
            e1 = stencil_entry(pos[p * 3u + 1u], 1u, k, (la >> 8u) & 255u);
            e2 = stencil_entry(pos[p * 3u + 2u], 2u, k, la >> 16u);
        }
",
    );
    for c in 0..comps {
        let _ = writeln!(
            w,
            "        var q{c} = 0.0;\n        if (live) {{ q{c} = vals[p * TOTAL + geo.comp_offset + {c}u] * scale{c}; }}"
        );
    }
    for z in 0..ns {
        let _ = writeln!(w, "        let ez{z} = subgroupShuffle(e2, base + {z}u);");
    }
    for col in 0..(ns * ns).div_ceil(seg) {
        super::interpgen::open_column(&mut w, col, seg);
        w.push_str("            if (live && wxy != 0.0) {\n");
        for z in 0..ns {
            let _ = writeln!(
                w,
                "                let w{z} = wxy * bitcast<f32>(ez{z}.x);\n                let c{z} = oxy + ez{z}.y;"
            );
            for c in 0..comps {
                let _ = writeln!(
                    w,
                    "                atomicAdd(&acc[{c}u * PPP + c{z}], i32(round(w{z} * q{c})));"
                );
            }
        }
        w.push_str("            }\n        }\n");
    }
    w.push_str(
        "    }
    workgroupBarrier();
    let cells = geo.n.w;
    let b0 = geo.comp_offset * cells;
",
    );
    for c in 0..comps {
        let _ = writeln!(
            w,
            "    let unscale{c} = select(0.0, 1.0 / scale{c}, scale{c} > 0.0);"
        );
    }
    w.push_str(
        "    for (var i = lid; i < PPP; i = i + WG) {
        let cell = wrapped[i % P] + wrapped[P + (i / P) % P] + wrapped[2u * P + i / (P * P)];
",
    );
    for c in 0..comps {
        let _ = writeln!(
            w,
            "        let a{c} = atomicLoad(&acc[{c}u * PPP + i]);\n        if (a{c} != 0) {{ grid_add(b0 + {c}u * cells + cell, f32(a{c}) * unscale{c}); }}"
        );
    }
    w.push_str("    }\n}\n");
    w
}

/// The largest weight of one support cell per axis of `window` on cells of `h` (its
/// peak, sampled over the support; every library window peaks at 0), with a margin for
/// the f32 evaluation on the GPU.
pub fn peak_weight(window: &super::window::Window, h: f64) -> f64 {
    let ns = window.support() as f64;
    let samples = 4096;
    let peak = (0..=samples)
        .map(|i| window.phi(-0.5 * ns + ns * i as f64 / samples as f64, h) / h)
        .fold(window.phi(0.0, h) / h, f64::max);
    peak * (1.0 + 1e-5)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_cover_the_grid() {
        assert_eq!(tiles_per_axis(&[128, 20, 7]), vec![16, 3, 1]);
        assert_eq!(padded(8), 15);
    }

    #[test]
    fn every_support_cell_is_added_once() {
        // Support 5 over 32 lanes: one column block of 25 columns, 5 z cells each.
        let src = spread_source(5, 2, 3, 32, 32);
        assert_eq!(src.matches("let pair = k + ").count(), 1);
        assert_eq!(src.matches("atomicAdd(&acc[1u * PPP").count(), 5);
        assert_eq!(src.matches("grid_add(b0 + 1u * cells").count(), 1);
        // Support 8 over 32 lanes: two column blocks of 32 columns.
        let src = spread_source(8, 1, 1, 32, 32);
        assert_eq!(src.matches("let pair = k + ").count(), 2);
        assert_eq!(src.matches("atomicAdd(&acc[0u * PPP").count(), 16);
    }

    #[test]
    fn workgroup_memory_fits_three_components_of_support_8() {
        assert!(workgroup_bytes(8, 3, 32) <= 48 << 10);
        assert!(workgroup_bytes(8, 2, 8) <= 32 << 10);
    }
}
