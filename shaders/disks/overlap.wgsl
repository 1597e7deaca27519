// One round of the overlap correction of S1 section 2.3 (eq. 4) and Algorithm 2, along
// the edges of the torus mesh (nodes/disks/mesh.rs layout), without float atomics: each
// particle gathers over its own edges (the fan of triangles around it, in the order
// `vertex_fans` walked it from its lowest corner: shaders/disks/fans.wgsl) the
// displacement delta (sigma - r) r_hat away from every neighbour closer than sigma, clamps
// its length to sigma / 4, moves and wraps into the box. A pair at distance 0 has no
// direction and pushes nothing. Entries:
// - `correct`: one thread per particle, reading its edges' far ends from the fan table
//   (column-major: contiguous across the threads), the edges past the table's width by
//   walking the mesh from the first corner; counts each overlapping pair once (by its
//   lower id) in `count[0]` (zeroed by a fill before it): the overlaps of the positions
//   read, so a round that counts 0 moved nothing; `count[1]` the disks in any of them.
#import common/index.wgsl

// The longest fan `vertex_fans` walks: a vertex with more edges (none in a Delaunay mesh
// of disks) is corrected by its first MAX_FAN only.
const MAX_FAN: u32 = 128u;

// limit: sigma less the tolerance (nodes/disks/overlap.rs `overlap_tolerance`): closer
// pairs overlap. width: the neighbour rows of the fan table.
struct Params {
    n: u32, slots: u32, sigma: f32, delta: f32, box_len: vec2<f32>, max_step: f32, limit: f32,
    width: u32,
}

@group(0) @binding(0) var<storage, read> x: array<vec2<f32>>;
@group(0) @binding(1) var<storage, read> mesh: array<u32>;
@group(0) @binding(2) var<storage, read> fans: array<u32>;
@group(0) @binding(3) var<storage, read_write> out: array<vec2<f32>>;
@group(0) @binding(4) var<storage, read_write> count: array<atomic<u32>>;
@group(0) @binding(5) var<uniform> params: Params;

// p - q by the minimum image. The image shift goes on p before the difference: p - k L
// is exact (both are multiples of p's ulp) and so is the difference of two nearby
// values, while (p - q) - k L first rounds p - q at the box's scale (an ulp of 1.2e-4 in
// a box of 1257, enough to make the in-circle test of a quad across the periodic
// boundary disagree with itself after a flip, which then never ends).
fn image_difference(p: vec2<f32>, q: vec2<f32>) -> vec2<f32> {
    return (p - params.box_len * round((p - q) / params.box_len)) - q;
}

fn wrap(p: vec2<f32>) -> vec2<f32> {
    return p - params.box_len * floor((p + 0.5 * params.box_len) / params.box_len);
}

// The sum over v's edges so far: its displacement, the overlapping pairs it counts (by
// their lower id) and whether v is in any.
struct Sum { shift: vec2<f32>, overlaps: u32, any: u32 }

// The sum with the push on v (at xv) from its neighbour w added, when they overlap.
fn push(sum: Sum, v: u32, xv: vec2<f32>, w: u32) -> Sum {
    let r = image_difference(x[w], xv);
    let len = length(r);
    if (len < params.limit && len > 0.0) {
        return Sum(sum.shift - (params.delta * (params.sigma - len) / len) * r,
            sum.overlaps + select(0u, 1u, w > v), 1u);
    }
    return sum;
}

@compute @workgroup_size(256)
fn correct(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
           @builtin(local_invocation_index) lid: u32) {
    let v = flat_index(wid, nwg, lid, 256u);
    if (v >= params.n) {
        return;
    }
    let n = params.n;
    let xv = x[v];
    let edges = min(fans[v], MAX_FAN);
    var sum = Sum(vec2<f32>(0.0), 0u, 0u);
    for (var j = 0u; j < min(edges, params.width); j = j + 1u) {
        sum = push(sum, v, xv, fans[(2u + j) * n + v]);
    }
    if (edges > params.width) {
        // A fan wider than the table (none in a mesh of disks at the default width): the
        // rest by twins around v, past the edges read above.
        var c = fans[n + v];
        for (var j = 0u; j < edges; j = j + 1u) {
            let t = c / 3u;
            let k = c % 3u;
            if (j >= params.width) {
                sum = push(sum, v, xv, mesh[6u * t + (k + 1u) % 3u]);
            }
            let u = mesh[6u * t + 3u + (k + 2u) % 3u];
            c = 3u * (u / 3u) + (u % 3u + 2u) % 3u;
        }
    }
    var shift = sum.shift;
    let s = length(shift);
    if (s > params.max_step) {
        shift = shift * (params.max_step / s);
    }
    out[v] = wrap(xv + shift);
    if (sum.overlaps > 0u) {
        atomicAdd(&count[0], sum.overlaps);
    }
    if (sum.any != 0u) {
        atomicAdd(&count[1], 1u);
    }
}
