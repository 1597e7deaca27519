//! Tiled spreading: one workgroup per tile of the grid, summing over the particles that
//! can reach it and writing each of its cells once (no float atomics, any input order).
//! The set-up (a counting sort of the particles by the tile of their anchor cell) is in
//! shaders/spread/tiles.wgsl; this writes the spreading kernel for one support,
//! dimension and component count, with the per-thread loops over z cells and components
//! written out so the accumulators are named scalars in registers (see boxgen.rs for
//! why).
//!
//! Thread (x, y) owns the column (x, y) of its tile (TZ cells along z in 3D, one cell in
//! 2D). The tile's candidates are the particles filed under the tiles whose
//! anchors can reach it: along each axis the anchors from NS - 1 cells before the tile
//! to its last cell. They are staged 32 at a time in workgroup memory as per-axis window
//! weights (computed once per particle by the set-up) at the tile's own cells (zero where the support misses them), so each thread's
//! inner loop is two loads and a test per candidate, and TZ fused multiply-adds per
//! component where the candidate's support covers its column.

use std::fmt::Write;

/// Cells per tile per axis (x, y, z): 8 x 8 x 8 in 3D (a thread per (x, y) column, 64
/// threads), 16 x 16 in 2D (a thread per cell). The first version's 16 x 16 x 8 tiles in
/// 3D took 5.4 ns per particle at support 8 on an H200: each candidate cost all 256
/// threads a test, for the 12% of columns its support covers.
pub fn tile_size(dims: u32) -> [u32; 3] {
    if dims == 3 { [8, 8, 8] } else { [16, 16, 1] }
}

/// Candidates staged per batch.
const BATCH: u32 = 32;

const COMP: [&str; 4] = ["x", "y", "z", "w"];

/// Tiles per axis for a grid of `cells`.
pub fn tiles_per_axis(cells: &[u32]) -> Vec<u32> {
    cells
        .iter()
        .zip(tile_size(cells.len() as u32))
        .map(|(&n, t)| n.div_ceil(t))
        .collect()
}

/// Threads per workgroup of the spreading kernel: one per (x, y) column of a tile.
pub fn workgroup(dims: u32) -> u32 {
    let [tx, ty, _] = tile_size(dims);
    tx * ty
}

/// The spreading kernel, composed after a window file (window_phi).
pub fn spread_source(ns: u32, dims: u32, comps: u32, total: u32) -> String {
    let [tx, ty, tz] = tile_size(dims);
    let wg = tx * ty;
    let entries = tx + ty + if dims == 3 { tz } else { 0 };
    let mut w = String::new();
    let _ = write!(
        w,
        "#import spread/geometry.wgsl

const NS: u32 = {ns}u;
const DIMS: u32 = {dims}u;
const TOTAL: u32 = {total}u;
const TX: u32 = {tx}u;
const TY: u32 = {ty}u;
const TZ: u32 = {tz}u;
const WG: u32 = {wg}u;
const E: u32 = {entries}u;   // staged weights per candidate: TX, then TY, then TZ
const B: u32 = {BATCH}u;

struct Tiles {{
    nt: vec4<u32>,
    size: vec4<u32>,
}}

@group(0) @binding(0) var<storage, read> vals: array<f32>;
@group(0) @binding(1) var<storage, read_write> out: array<f32>;
@group(0) @binding(2) var<uniform> geo: Geometry;
@group(0) @binding(3) var<uniform> tiles: Tiles;
@group(0) @binding(4) var<storage, read> count: array<u32>;
@group(0) @binding(5) var<storage, read> start: array<u32>;
@group(0) @binding(6) var<storage, read> order: array<u32>;
@group(0) @binding(7) var<storage, read> anchors: array<vec4<u32>>;
@group(0) @binding(8) var<storage, read> weights: array<f32>;

var<workgroup> cw: array<f32, {cw}>;
var<workgroup> cv: array<vec4<f32>, B>;

// The tiles whose anchors reach tile cells [o, o + len) along axis a: (first, how many).
fn anchor_tiles(o: u32, len: u32, a: u32) -> vec2<u32> {{
    let n = geo.n[a];
    let nt = tiles.nt[a];
    if (len + NS - 1u >= n) {{
        return vec2<u32>(0u, nt);
    }}
    let first = ((o + n - (NS - 1u)) % n) / tiles.size[a];
    return vec2<u32>(first, (o / tiles.size[a] + nt - first) % nt + 1u);
}}

// Window weight at tile cell o + l along axis a of particle p with anchor cell j0 (zero
// where its support misses the cell).
fn staged_weight(p: u32, j0: u32, a: u32, o: u32, l: u32) -> f32 {{
    let n = geo.n[a];
    var k = o + l + n - j0;
    if (k >= n) {{ k = k - n; }}
    if (k >= NS) {{
        return 0.0;
    }}
    return weights[(p * 3u + a) * NS + k];
}}

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {{
    let tile = wid.y * nwg.x + wid.x;
    if (tile >= tiles.nt.w) {{
        return;
    }}
    let nt = tiles.nt;
    let o = vec3<u32>((tile % nt.x) * TX, ((tile / nt.x) % nt.y) * TY, (tile / (nt.x * nt.y)) * TZ);
    let len = vec3<u32>(min(TX, geo.n.x - o.x), min(TY, geo.n.y - o.y), min(TZ, geo.n.z - o.z));
    let x = lid % TX;
    let y = lid / TX;
    let ax = anchor_tiles(o.x, len.x, 0u);
    let ay = anchor_tiles(o.y, len.y, 1u);
    var az = vec2<u32>(0u, 1u);
    if (DIMS == 3u) {{
        az = anchor_tiles(o.z, len.z, 2u);
    }}
",
        cw = BATCH * entries
    );
    for z in 0..tz {
        for c in 0..comps {
            let _ = writeln!(w, "    var a{z}_{c} = 0.0;");
        }
    }
    w.push_str(
        "    for (var iz = 0u; iz < az.y; iz = iz + 1u) {
    for (var iy = 0u; iy < ay.y; iy = iy + 1u) {
    for (var ix = 0u; ix < ax.y; ix = ix + 1u) {
        let at = (ax.x + ix) % nt.x + nt.x * ((ay.x + iy) % nt.y + nt.y * ((az.x + iz) % nt.z));
        let first = start[at];
        let n_at = count[at];
        for (var b0 = 0u; b0 < n_at; b0 = b0 + B) {
            let m = min(B, n_at - b0);
            workgroupBarrier();
            // WG / B threads per candidate, each staging its share of the entries with
            // independent loads (one chain of order -> anchor -> weights per batch).
            let jc = lid / (WG / B);
            let h = lid % (WG / B);
            if (jc < m) {
                let p = order[first + b0 + jc];
                let j0 = anchors[p];
                let row = jc * E;
",
    );
    let share = wg / BATCH;
    let axes: Vec<(u32, u32)> = (0..entries)
        .map(|q| {
            if q < tx {
                (0, q)
            } else if q < tx + ty {
                (1, q - tx)
            } else {
                (2, q - tx - ty)
            }
        })
        .collect();
    let names = ["x", "y", "z"];
    for r in 0..share {
        let _ = writeln!(w, "                if (h == {r}u) {{");
        for q in (r..entries).step_by(share as usize) {
            let (a, l) = axes[q as usize];
            let an = names[a as usize];
            let _ = writeln!(
                w,
                "                    cw[row + {q}u] = select(0.0, staged_weight(p, j0.{an}, {a}u, o.{an}, {l}u), {l}u < len.{an});"
            );
        }
        if r == 0 {
            w.push_str("                    var v = vec4<f32>(0.0);\n");
            for c in 0..comps {
                let _ = writeln!(
                    w,
                    "                    v.{} = vals[p * TOTAL + geo.comp_offset + {c}u];",
                    COMP[c as usize]
                );
            }
            w.push_str("                    cv[jc] = v;\n");
        }
        w.push_str("                }\n");
    }
    w.push_str(
        "            }
            workgroupBarrier();
            for (var j = 0u; j < m; j = j + 1u) {
                let wxy = cw[j * E + x] * cw[j * E + TX + y];
                if (wxy != 0.0) {
                    let v = wxy * cv[j];
",
    );
    for z in 0..tz {
        let wz = if dims == 3 {
            format!("cw[j * E + TX + TY + {z}u]")
        } else {
            "1.0".into()
        };
        let _ = writeln!(w, "                    let w{z} = {wz};");
        for c in 0..comps {
            let _ = writeln!(
                w,
                "                    a{z}_{c} = fma(w{z}, v.{}, a{z}_{c});",
                COMP[c as usize]
            );
        }
    }
    w.push_str(
        "                }
            }
        }
    }
    }
    }
    if (x < len.x && y < len.y) {
        let cells = geo.n.w;
        let column = (o.y + y) * geo.n.x + o.x + x;
",
    );
    for z in 0..tz {
        let _ = writeln!(
            w,
            "        if ({z}u < len.z) {{\n            let cell = (o.z + {z}u) * geo.n.x * geo.n.y + column;"
        );
        for c in 0..comps {
            let _ = writeln!(
                w,
                "            out[(geo.comp_offset + {c}u) * cells + cell] = a{z}_{c};"
            );
        }
        w.push_str("        }\n");
    }
    w.push_str("    }\n}\n");
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_cover_the_grid() {
        assert_eq!(tiles_per_axis(&[128, 128, 128]), vec![16, 16, 16]);
        assert_eq!(tiles_per_axis(&[20, 33, 9]), vec![3, 5, 2]);
        assert_eq!(tiles_per_axis(&[48, 16]), vec![3, 1]);
    }

    #[test]
    fn every_tile_cell_and_component_is_written() {
        let src = spread_source(7, 3, 3, 3);
        assert_eq!(src.matches("out[(geo.comp_offset").count(), 8 * 3);
        let src = spread_source(4, 2, 2, 2);
        assert_eq!(src.matches("out[(geo.comp_offset").count(), 2);
    }
}
