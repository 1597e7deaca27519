// One parallel round of Lawson edge flips on the torus mesh (nodes/disks/mesh.rs layout:
// per triangle 3 vertices counter-clockwise and 3 twin slots), conflicts resolved on the
// GPU by claims (nodes/disks/flip.rs explains why they suffice):
// - before them, disks/flip_prepare.wgsl copies the mesh to the output, every claim to
//   0xFFFFFFFF, the count to 0;
// - `claim` (one thread per triangle, for its three slots): every edge (its smaller slot
//   s) whose quad needs a flip (disks/predicate.wgsl) claims the four triangles its flip
//   writes (its two and the owners of the two outer edges whose twins move) by
//   atomicMin(claim, s);
// - `flip` (one thread per triangle): the edge holding the claim of its own triangle
//   flips if it holds its other three claims too, reading the input mesh and writing the
//   output, and counts itself.
// The lowest candidate always wins its claims, so a round with a candidate flips at least
// one edge, and the winners are those of a fixed rule: the same result every run.
#import common/index.wgsl
#import disks/predicate.wgsl

struct Params { slots: u32, tolerance: f32, box_len: vec2<f32> }

@group(0) @binding(0) var<storage, read> x: array<vec2<f32>>;
@group(0) @binding(1) var<storage, read> mesh: array<u32>;
@group(0) @binding(2) var<storage, read_write> out: array<u32>;
@group(0) @binding(3) var<storage, read_write> claims: array<atomic<u32>>;
@group(0) @binding(4) var<storage, read_write> count: array<atomic<u32>>;
@group(0) @binding(5) var<uniform> params: Params;

fn minimum_image(r: vec2<f32>) -> vec2<f32> {
    return r - params.box_len * round(r / params.box_len);
}

fn vert(t: u32, k: u32) -> u32 {
    return mesh[6u * t + k % 3u];
}

fn twin(t: u32, k: u32) -> u32 {
    return mesh[6u * t + 3u + k % 3u];
}

// Slot s = 3 t + k of triangle t = (a, b, c) from k (positions pa, pb, pc), its twin us
// and the owners xb, xc of the twins of its outer edges c -> a and a -> b: if the edge is
// a candidate, it claims the triangles (t, u) and the owners of the outer edges c -> a
// (of t) and b -> d (of u), whose twins its flip rewrites.
fn claim_edge(t: u32, s: u32, us: u32, a: u32, pa: vec2<f32>, pb: vec2<f32>, pc: vec2<f32>,
              xb: u32, xc: u32) {
    // Each edge once, by its smaller slot.
    if (us <= s || us >= params.slots) {
        return;
    }
    let u = us / 3u;
    let m = us % 3u;
    let d = vert(u, m);
    let yc = twin(u, m + 1u) / 3u;
    let yb = twin(u, m + 2u) / 3u;
    // Two triangles sharing more than this edge (a torus of very few points): no flip.
    if (a == d || xb == u || xc == u || yc == t || yb == t || t == u) {
        return;
    }
    let xd = x[d];
    let code = flip_code(minimum_image(pa - xd), minimum_image(pb - xd),
        minimum_image(pc - xd), params.tolerance);
    if (code != FLIP_KEEP) {
        atomicMin(&claims[t], s);
        atomicMin(&claims[u], s);
        atomicMin(&claims[xb], s);
        atomicMin(&claims[yc], s);
    }
}

@compute @workgroup_size(256)
fn claim(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_index) lid: u32) {
    // One thread per triangle: its words and vertices' positions read once for its three
    // edges.
    let t = flat_index(wid, nwg, lid, 256u);
    if (t >= params.slots / 3u) {
        return;
    }
    let v = vec3<u32>(mesh[6u * t], mesh[6u * t + 1u], mesh[6u * t + 2u]);
    let w = vec3<u32>(mesh[6u * t + 3u], mesh[6u * t + 4u], mesh[6u * t + 5u]);
    let p0 = x[v.x];
    let p1 = x[v.y];
    let p2 = x[v.z];
    claim_edge(t, 3u * t, w.x, v.x, p0, p1, p2, w.y / 3u, w.z / 3u);
    claim_edge(t, 3u * t + 1u, w.y, v.y, p1, p2, p0, w.z / 3u, w.x / 3u);
    claim_edge(t, 3u * t + 2u, w.z, v.z, p2, p0, p1, w.x / 3u, w.y / 3u);
}

@compute @workgroup_size(256)
fn flip(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    // One thread per triangle t: a winner s holds the claim of its own triangle s / 3, so
    // the edge whose slot holds claims[t] and lies in t is the one candidate of t that
    // may have won; only a candidate claims, so no predicate is evaluated again.
    let tri = flat_index(wid, nwg, lid, 256u);
    if (tri >= params.slots / 3u) {
        return;
    }
    let s = atomicLoad(&claims[tri]);
    if (s / 3u != tri) {
        return;
    }
    let us = twin(tri, s);
    let xb = twin(tri, s + 1u) / 3u;
    let yc = twin(us / 3u, us + 1u) / 3u;
    if (atomicLoad(&claims[us / 3u]) != s || atomicLoad(&claims[xb]) != s
        || atomicLoad(&claims[yc]) != s) {
        return;
    }
    // t = (a, b, c) from slot k, u = (d, c, b) from slot m; after: t = (a, b, d),
    // u = (d, c, a), the new edge a -> d between them.
    let t = tri;
    let u = us / 3u;
    let k = s % 3u;
    let m = twin(t, k) % 3u;
    let a = vert(t, k);
    let d = vert(u, m);
    let x_b = twin(t, k + 1u);
    let x_c = twin(t, k + 2u);
    let y_c = twin(u, m + 1u);
    let y_b = twin(u, m + 2u);
    let k1 = (k + 1u) % 3u;
    let k2 = (k + 2u) % 3u;
    let m1 = (m + 1u) % 3u;
    let m2 = (m + 2u) % 3u;
    out[6u * t + k2] = d;
    out[6u * t + 3u + k] = y_c;
    out[6u * t + 3u + k1] = 3u * u + m1;
    out[6u * t + 3u + k2] = x_c;
    out[6u * u + m2] = a;
    out[6u * u + 3u + m] = x_b;
    out[6u * u + 3u + m1] = 3u * t + k1;
    out[6u * u + 3u + m2] = y_b;
    out[6u * (y_c / 3u) + 3u + y_c % 3u] = 3u * t + k;
    out[6u * (x_b / 3u) + 3u + x_b % 3u] = 3u * u + m;
    atomicAdd(&count[0], 1u);
}
