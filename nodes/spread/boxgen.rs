//! WGSL of the box kernel (spreading particles sorted in space, see
//! shaders/spread/box.wgsl), generated for one support, dimension and component count
//! with every per-thread loop over z cells and components written out: the accumulators
//! are then named scalars in registers. Written as loops, naga emits arrays indexed by a
//! loop counter, which the driver kept in local memory (that first version measured
//! 7.5 ns per particle at support 8 on an H200, against 1.4 ns for the per-particle
//! kernel); see BENCHMARKS.md.

use std::fmt::Write;

/// Box cells per axis (shaders/spread/box.wgsl `BMAX`).
pub const BMAX: u32 = 16;

const HEADER: &str = "#import common/index.wgsl
#import spread/geometry.wgsl
#import spread/first_cell.wgsl
#import spread/box.wgsl
";

const COMP: [&str; 4] = ["x", "y", "z", "w"];

/// The spreading kernel: composed after a window file and an add file (grid_add).
pub fn spread_source(ns: u32, dims: u32, comps: u32, total: u32) -> String {
    let zmax = if dims == 3 { BMAX } else { 1 };
    let mut w = String::from(HEADER);
    let _ = write!(
        w,
        "const NS: u32 = {ns}u;
const DIMS: u32 = {dims}u;
const COMPS: u32 = {comps}u;
const TOTAL: u32 = {total}u;

@group(0) @binding(0) var<storage, read> pos: array<f32>;
@group(0) @binding(1) var<storage, read> vals: array<f32>;
@group(0) @binding(3) var<uniform> geo: Geometry;

var<workgroup> value: array<vec4<f32>, 64>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {{
    let p0 = (wid.y * nwg.x + wid.x) * geo.run;
    let count = min(geo.run, select(0u, geo.count - p0, p0 < geo.count));
    if (lid < P) {{
        var v = vec4<f32>(0.0);
        if (lid < count) {{
"
    );
    for c in 0..comps {
        let _ = writeln!(
            w,
            "            v.{} = vals[(p0 + lid) * TOTAL + geo.comp_offset + {c}u];",
            COMP[c as usize]
        );
    }
    w.push_str(
        "        }
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
            let v = value[s];
            for (var iz = 0u; iz < nz; iz = iz + 1u) {
                let w = wxy * direct_weight(s, 2u, iz);
                let cell = direct_cell(s, ix, iy, iz);
",
    );
    for c in 0..comps {
        let _ = writeln!(
            w,
            "                grid_add((geo.comp_offset + {c}u) * cells + cell, w * v.{});",
            COMP[c as usize]
        );
    }
    w.push_str(
        "            }
        }
        return;
    }
    let x = lid % b.n.x;
    let y = lid / b.n.x;
    // Only the box's columns sum (whole warps past them skip the loop), over as many z
    // cells as the box has: runs of dense sorted particles give boxes of about 11 cells
    // a side, so the z sums go to SHORT_Z registers when they fit.
    if (y >= b.n.y) {
        return;
    }
",
    );
    if zmax > SHORT_Z {
        let _ = writeln!(w, "    if (b.n.z <= {SHORT_Z}u) {{");
        column_sums(&mut w, SHORT_Z, comps);
        w.push_str("        return;\n    }\n");
    }
    column_sums(&mut w, zmax, comps);
    w.push_str("}\n");
    w
}

/// Box cells along z summed in registers when the box has no more (the short version of
/// the column sums).
const SHORT_Z: u32 = 12;

/// The column (x, y)'s sums over the run's particles in `nz` z registers per component,
/// and its flush to the grid.
fn column_sums(w: &mut String, nz: u32, comps: u32) {
    for z in 0..nz {
        for c in 0..comps {
            let _ = writeln!(w, "    var a{z}_{c} = 0.0;");
        }
    }
    w.push_str(
        "    for (var s = 0u; s < count; s = s + 1u) {
        let a = box_w[(s * 3u) * BMAX + x] * box_w[(s * 3u + 1u) * BMAX + y];
        if (a != 0.0) {
            let v = a * value[s];
            let wz = (s * 3u + 2u) * BMAX;
",
    );
    for z in 0..nz {
        let _ = writeln!(w, "            let w{z} = box_w[wz + {z}u];");
        for c in 0..comps {
            let _ = writeln!(
                w,
                "            a{z}_{c} = fma(w{z}, v.{}, a{z}_{c});",
                COMP[c as usize]
            );
        }
    }
    w.push_str(
        "        }
    }
    let xy = box_wrap[x] + box_wrap[BMAX + y];
",
    );
    for z in 0..nz {
        let _ = writeln!(
            w,
            "    if ({z}u < b.n.z) {{\n        let cell = xy + box_wrap[2u * BMAX + {z}u];"
        );
        for c in 0..comps {
            let _ = writeln!(
                w,
                "        if (a{z}_{c} != 0.0) {{ grid_add((geo.comp_offset + {c}u) * cells + cell, a{z}_{c}); }}"
            );
        }
        w.push_str("    }\n");
    }
}
