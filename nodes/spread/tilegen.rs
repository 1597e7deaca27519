//! Tiled spreading: one workgroup per tile of the grid, summing over the particles that
//! can reach it and writing each of its cells once (no float atomics, any input order).
//! The set-up (a counting sort of the particles by the tile of their anchor cell) is in
//! shaders/spread/tiles.wgsl; this writes the spreading kernel for one support,
//! dimension and component count, with the per-thread loops over z cells and components
//! written out so the accumulators are named scalars in registers (see boxgen.rs for
//! why).
//!
//! Thread (x, y) of the 256 owns the column (x, y) of its tile (TZ cells along z in 3D,
//! one cell in 2D). The tile's candidates are the particles filed under the tiles whose
//! anchors can reach it: along each axis the anchors from NS - 1 cells before the tile
//! to its last cell. They are staged 64 at a time in workgroup memory as per-axis window
//! weights at the tile's own cells (zero where the support misses them), so each thread's
//! inner loop is two loads and a test per candidate, and TZ fused multiply-adds per
//! component where the candidate's support covers its column.

use std::fmt::Write;

/// Cells per tile per axis: x, y, z (3D; 2D tiles are TX x TY).
pub const TX: u32 = 16;
pub const TY: u32 = 16;
pub const TZ: u32 = 8;
/// Candidates staged per batch.
const BATCH: u32 = 64;

const COMP: [&str; 4] = ["x", "y", "z", "w"];

/// Tiles per axis for a grid of `cells`.
pub fn tiles_per_axis(cells: &[u32]) -> Vec<u32> {
    cells
        .iter()
        .zip([TX, TY, TZ])
        .map(|(&n, t)| n.div_ceil(t))
        .collect()
}

/// The spreading kernel, composed after a window file (window_phi).
pub fn spread_source(ns: u32, dims: u32, comps: u32, total: u32) -> String {
    let tz = if dims == 3 { TZ } else { 1 };
    let entries = TX + TY + if dims == 3 { TZ } else { 0 };
    let mut w = String::new();
    let _ = write!(
        w,
        "#import spread/geometry.wgsl

const NS: u32 = {ns}u;
const DIMS: u32 = {dims}u;
const TOTAL: u32 = {total}u;
const TX: u32 = {TX}u;
const TY: u32 = {TY}u;
const TZ: u32 = {tz}u;
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
@group(0) @binding(7) var<storage, read> stencil: array<vec4<f32>>;

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

// Window weight at tile cell o + l along axis a of the particle with stencil s (zero
// where its support misses the cell).
fn staged_weight(s: vec4<f32>, a: u32, o: u32, l: u32) -> f32 {{
    let n = geo.n[a];
    var stride = 1u;
    if (a >= 1u) {{ stride = geo.n.x; }}
    if (a == 2u) {{ stride = geo.n.x * geo.n.y; }}
    let j0 = (bitcast<u32>(s.w) / stride) % n;
    var k = o + l + n - j0;
    if (k >= n) {{ k = k - n; }}
    if (k >= NS) {{
        return 0.0;
    }}
    return window_phi(s[a] + f32(k), geo.win[a]) * geo.inv_h[a];
}}

@compute @workgroup_size(256)
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
            for (var e = lid; e < m * E; e = e + 256u) {
                let j = e / E;
                let q = e % E;
                let p = order[first + b0 + j];
                let s = stencil[p];
                var w = 0.0;
                if (q < TX) {
                    if (q < len.x) { w = staged_weight(s, 0u, o.x, q); }
                } else if (q < TX + TY) {
                    if (q - TX < len.y) { w = staged_weight(s, 1u, o.y, q - TX); }
                } else if (q - TX - TY < len.z) {
                    w = staged_weight(s, 2u, o.z, q - TX - TY);
                }
                cw[e] = w;
            }
            if (lid < m) {
                let p = order[first + b0 + lid];
                var v = vec4<f32>(0.0);
",
    );
    for c in 0..comps {
        let _ = writeln!(
            w,
            "                v.{} = vals[p * TOTAL + geo.comp_offset + {c}u];",
            COMP[c as usize]
        );
    }
    w.push_str(
        "                cv[lid] = v;
            }
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
        assert_eq!(tiles_per_axis(&[128, 128, 128]), vec![8, 8, 16]);
        assert_eq!(tiles_per_axis(&[20, 33, 9]), vec![2, 3, 2]);
        assert_eq!(tiles_per_axis(&[48, 16]), vec![3, 1]);
    }

    #[test]
    fn every_tile_cell_and_component_is_written() {
        let src = spread_source(7, 3, 3, 3);
        assert_eq!(src.matches("out[(geo.comp_offset").count(), (TZ * 3) as usize);
        let src = spread_source(4, 2, 2, 2);
        assert_eq!(src.matches("out[(geo.comp_offset").count(), 2);
    }
}
