//! WGSL of the lane kernels (interpolation, and spreading with one grid add per cell),
//! generated for one support, dimension, component count and segment width with every
//! loop written out.
//!
//! Each particle is served by a segment of `seg` consecutive lanes of one subgroup (a
//! power of two, at least the support and at most the adapter's smallest subgroup): lane
//! k < NS of the segment evaluates the window and the wrapped cell offset of support index
//! k on every axis, the other lanes fetch them with subgroup shuffles, each lane sums its
//! (x, y) columns of the support along z into named scalars, and a shuffle butterfly
//! adds the segment. No workgroup memory and no barrier. Assumes full subgroups of
//! consecutive invocations (lane = invocation index mod subgroup size), as every driver
//! gives for workgroups that are multiples of the subgroup, so that particle slot
//! lid / seg and the lanes of its segment coincide. Why: the workgroup-table kernel of
//! spread/interpolate_subgroup.wgsl spent most of its time outside the grid loads, its
//! 64 threads per particle each running the table set-up, a workgroup barrier and a WGSL
//! loop over z (on an H200 at support 8: 0.81 ns per particle with the column sums taken
//! out, 1.06 with the z loop written out, against 1.73); this kernel interpolates in
//! 0.56 ns (see BENCHMARKS.md).

use std::fmt::Write;

const HEADER: &str = "#import spread/geometry.wgsl
#import spread/slots.wgsl
";

/// Lanes per particle for support `ns` on an adapter whose subgroups hold at least
/// `min_subgroup` lanes: the power of two covering the support's (x, y) columns, at most
/// the subgroup, at least the support (lane k holds support index k); None when the
/// support is wider than the subgroup (the per-particle kernel serves it).
pub fn segment(ns: u32, min_subgroup: u32) -> Option<u32> {
    let seg = (ns * ns).next_power_of_two().min(min_subgroup);
    (ns <= seg && min_subgroup.is_power_of_two()).then_some(seg)
}

/// Declarations, the stencil set-up and the z entries shared by both kernels, up to the
/// column loop. `bindings` declares pos (0), geo (the last) and the kernel's own buffers.
fn prologue(ns: u32, dims: u32, total: u32, seg: u32, wg: u32, bindings: &str) -> String {
    let mut w = String::from(HEADER);
    let _ = write!(
        w,
        "const NS: u32 = {ns}u;
const DIMS: u32 = {dims}u;
const TOTAL: u32 = {total}u;
const SEG: u32 = {seg}u;

{bindings}
// Window weight (per unit length, as bits) and wrapped cell offset (times the axis
// stride) of support index k on axis a for the particle at coordinate x.
fn stencil_entry(x: f32, a: u32, k: u32) -> vec2<u32> {{
    let t = centre_units(x, a);
    let j0 = floor(t - 0.5 * f32(NS)) + 1.0;
    let w = window_phi(j0 + f32(k) - t, geo.win[a]) * geo.inv_h[a];
    var stride = 1u;
    if (a >= 1u) {{ stride = geo.n.x; }}
    if (a == 2u) {{ stride = geo.n.x * geo.n.y; }}
    let off = wrap_cell(i32(j0) + i32(k), geo.n[a]) * stride;
    return vec2<u32>(bitcast<u32>(w), off);
}}

@compute @workgroup_size({wg})
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32,
        @builtin(subgroup_invocation_id) lane: u32) {{
    let k = lane % SEG;
    let base = lane - k;
    let p = slot_particle((wid.y * nwg.x + wid.x) * ({wg}u / SEG) + lid / SEG);
    let live = p < geo.count;
    var e0 = vec2<u32>(0u);
    var e1 = vec2<u32>(0u);
    var e2 = vec2<u32>(0u);
    if (live && k < NS) {{
        e0 = stencil_entry(pos[p * DIMS], 0u, k);
        e1 = stencil_entry(pos[p * DIMS + 1u], 1u, k);
        if (DIMS == 3u) {{
            e2 = stencil_entry(pos[p * DIMS + 2u], 2u, k);
        }}
    }}
    let cells = geo.n.w;
    let b0 = geo.comp_offset * cells;
"
    );
    if dims == 3 {
        for z in 0..ns {
            let _ = writeln!(w, "    let ez{z} = subgroupShuffle(e2, base + {z}u);");
        }
    }
    w
}

/// Opens column block `col` (lanes k + col * seg): the (x, y) weight `wxy` (zero past
/// the support) and offset `oxy`, from the lanes' entries e0 and e1 (tilegen.rs uses
/// it too). Every lane runs every block, so the shuffles stay in uniform control flow.
pub(super) fn open_column(w: &mut String, col: u32, seg: u32) {
    let _ = write!(
        w,
        "    {{
        let pair = k + {off}u;
        let q = min(pair, NS * NS - 1u);
        let ex = subgroupShuffle(e0, base + q % NS);
        let ey = subgroupShuffle(e1, base + q / NS);
        let wxy = select(0.0, bitcast<f32>(ex.x) * bitcast<f32>(ey.x), pair < NS * NS);
        let oxy = ex.y + ey.y;
",
        off = col * seg
    );
}

/// The interpolation kernel, composed after a window file (window_phi). Bindings as
/// spread/interpolate_common.wgsl: pos, grid, quadrature, out, geo.
pub fn interpolate_source(
    ns: u32,
    dims: u32,
    comps: u32,
    total: u32,
    weights: bool,
    seg: u32,
    wg: u32,
) -> String {
    let mut w = prologue(
        ns,
        dims,
        total,
        seg,
        wg,
        "@group(0) @binding(0) var<storage, read> pos: array<f32>;
@group(0) @binding(1) var<storage, read> grid: array<f32>;
@group(0) @binding(2) var<storage, read> quadrature: array<f32>;
@group(0) @binding(3) var<storage, read_write> out: array<f32>;
@group(0) @binding(4) var<uniform> geo: Geometry;
",
    );
    for c in 0..comps {
        let _ = writeln!(w, "    var a{c} = 0.0;");
    }
    for col in 0..(ns * ns).div_ceil(seg) {
        open_column(&mut w, col, seg);
        if dims == 3 {
            for z in 0..ns {
                let dv = if weights {
                    format!(" * quadrature[oxy + ez{z}.y]")
                } else {
                    String::new()
                };
                let _ = writeln!(w, "        let w{z} = bitcast<f32>(ez{z}.x){dv};");
            }
            for c in 0..comps {
                let terms: Vec<String> = (0..ns)
                    .map(|z| format!("w{z} * grid[b0 + {c}u * cells + oxy + ez{z}.y]"))
                    .collect();
                let _ = writeln!(w, "        a{c} = fma(wxy, {}, a{c});", terms.join(" + "));
            }
        } else {
            let dv = if weights { " * quadrature[oxy]" } else { "" };
            let _ = writeln!(w, "        let wc = wxy{dv};");
            for c in 0..comps {
                let _ = writeln!(
                    w,
                    "        a{c} = fma(wc, grid[b0 + {c}u * cells + oxy], a{c});"
                );
            }
        }
        w.push_str("    }\n");
    }
    let mut o = seg / 2;
    while o > 0 {
        for c in 0..comps {
            let _ = writeln!(w, "    a{c} = a{c} + subgroupShuffleXor(a{c}, {o}u);");
        }
        o /= 2;
    }
    let dv = if weights { "" } else { " * geo.dv" };
    w.push_str("    if (live && k == 0u) {\n");
    for c in 0..comps {
        let _ = writeln!(
            w,
            "        out[p * TOTAL + geo.comp_offset + {c}u] = a{c}{dv};"
        );
    }
    w.push_str("    }\n}\n");
    w
}

/// The spreading kernel, composed after a window file and an add file (grid_add,
/// binding 2). Bindings as spread/spread.wgsl: pos, vals, grid, geo.
pub fn spread_source(ns: u32, dims: u32, comps: u32, total: u32, seg: u32, wg: u32) -> String {
    let mut w = prologue(
        ns,
        dims,
        total,
        seg,
        wg,
        "@group(0) @binding(0) var<storage, read> pos: array<f32>;
@group(0) @binding(1) var<storage, read> vals: array<f32>;
@group(0) @binding(3) var<uniform> geo: Geometry;
",
    );
    for c in 0..comps {
        let _ = writeln!(
            w,
            "    var v{c} = 0.0;\n    if (live) {{ v{c} = vals[p * TOTAL + geo.comp_offset + {c}u]; }}"
        );
    }
    for col in 0..(ns * ns).div_ceil(seg) {
        open_column(&mut w, col, seg);
        w.push_str("        if (live && wxy != 0.0) {\n");
        if dims == 3 {
            for z in 0..ns {
                let _ = writeln!(
                    w,
                    "            let w{z} = wxy * bitcast<f32>(ez{z}.x);\n            let c{z} = b0 + oxy + ez{z}.y;"
                );
                for c in 0..comps {
                    let _ = writeln!(w, "            grid_add(c{z} + {c}u * cells, w{z} * v{c});");
                }
            }
        } else {
            for c in 0..comps {
                let _ = writeln!(
                    w,
                    "            grid_add(b0 + {c}u * cells + oxy, wxy * v{c});"
                );
            }
        }
        w.push_str("        }\n    }\n");
    }
    w.push_str("}\n");
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segments_cover_the_support() {
        assert_eq!(segment(8, 32), Some(32));
        assert_eq!(segment(8, 8), Some(8));
        assert_eq!(segment(4, 32), Some(16));
        assert_eq!(segment(3, 32), Some(16));
        assert_eq!(segment(3, 4), Some(4));
        assert_eq!(segment(9, 8), None);
        assert_eq!(segment(6, 24), None);
    }

    #[test]
    fn every_column_is_written_once() {
        let src = interpolate_source(3, 3, 2, 2, false, 4, 64);
        // 9 (x, y) columns over 4 lanes: 3 column blocks, each with 3 z loads per component.
        assert_eq!(src.matches("let pair = k + ").count(), 3);
        assert_eq!(src.matches("a1 = fma(").count(), 3);
        assert_eq!(src.matches("subgroupShuffleXor(a0").count(), 2);
    }
}
