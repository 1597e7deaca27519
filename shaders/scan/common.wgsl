// Declarations shared by the exclusive-scan kernels (reduce-then-scan, nodes/scan.rs).
//
// A tile is WG threads x ROWS vec4 loads = TILE elements. `reduce` writes one sum per
// tile; the host scans those sums with these same kernels (recursively while there is
// more than one tile) and `downsweep` rescans each tile from its offset. No workgroup
// waits for another (Vulkan promises no forward progress between workgroups, so there is
// no decoupled look-back). Bytes per element: 4 read by `reduce`, 4 read and 4 written
// by `downsweep`; each level of tile sums adds 12 / TILE of that.
//
// Elem is u32 as written; the host swaps this alias for f32 to scan real arrays.
alias Elem = u32;

const WG: u32 = 256u;
// vec4 loads per thread and tile; TILE = 4 * ROWS * WG is mirrored by nodes/scan.rs.
const ROWS: u32 = 4u;
const TILE: u32 = 4096u;

struct Params {
    // Elements to scan.
    len: u32,
    // 1: start each tile at offsets[tile] (the scanned tile sums); 0: at zero.
    use_offsets: u32,
}

@group(0) @binding(0) var<storage, read> src: array<vec4<Elem>>;
@group(0) @binding(1) var<storage, read> offsets: array<Elem>;
// The scanned elements (downsweep) or one sum per tile (reduce).
@group(0) @binding(2) var<storage, read_write> dst: array<vec4<Elem>>;
@group(0) @binding(3) var<uniform> params: Params;

fn tiles() -> u32 {
    return (params.len + TILE - 1u) / TILE;
}

// Whether a tile holds TILE elements: then its loads and stores skip the tail checks, so
// that all of a thread's vec4 loads can be in flight at once.
fn tile_is_full(tile: u32) -> bool {
    return params.len - tile * TILE >= TILE;
}

// The q-th group of four elements, zero past the end (buffers are padded to 16 bytes,
// so the vec4 that holds the last element is inside the binding).
fn load4(q: u32) -> vec4<Elem> {
    let i = 4u * q;
    if (i + 4u <= params.len) {
        return src[q];
    }
    var v = vec4<Elem>(Elem(0));
    if (i < params.len) {
        let w = src[q];
        for (var c = 0u; c < 3u; c++) {
            if (i + c < params.len) {
                v[c] = w[c];
            }
        }
    }
    return v;
}

// Writes the q-th group of four elements, none past the end.
fn store4(q: u32, v: vec4<Elem>) {
    let i = 4u * q;
    if (i + 4u <= params.len) {
        dst[q] = v;
        return;
    }
    for (var c = 0u; c < 3u; c++) {
        if (i + c < params.len) {
            dst[q][c] = v[c];
        }
    }
}

// Exclusive prefix inside a vec4, starting from p: sequential, as the f32 error bound
// in nodes/scan.rs assumes.
fn prefix4(p: Elem, v: vec4<Elem>) -> vec4<Elem> {
    let y = p + v.x;
    let z = y + v.y;
    return vec4<Elem>(p, y, z, z + v.z);
}

fn sum4(v: vec4<Elem>) -> Elem {
    return (v.x + v.y) + (v.z + v.w);
}

// One tile sum into the reduce output (dst holds the sums four to a vec4).
fn store_sum(tile: u32, s: Elem) {
    dst[tile / 4u][tile % 4u] = s;
}
