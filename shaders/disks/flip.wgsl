// Rounds of parallel Lawson edge flips on the torus mesh (nodes/disks/mesh.rs layout: per
// triangle 3 vertices counter-clockwise and 3 twin slots), in place on the output,
// conflicts resolved on the GPU by claims (nodes/disks/flip.rs explains why they suffice
// and why the later rounds need only the marked triangles):
// - before them, disks/flip_prepare.wgsl copies the mesh to the output, every claim to
//   0xFFFFFFFF, every mark and the count to 0. Nothing is reset between rounds: a claim
//   carries its round's tag in its top bits (later rounds smaller tags, so they win
//   over earlier rounds' claims, which the flip pass ignores), and a mark is the number
//   of its round plus 1, in two arrays taken in turn (read: the round before's number);
// - `claim` (first round; one thread per triangle, for its three slots): every edge (its
//   smaller slot s) whose quad needs a flip (disks/predicate.wgsl) claims the four
//   triangles its flip writes (its two and the owners of the two outer edges whose twins
//   move) by atomicMin(claim, tag | s), and marks its two triangles for the next round (an edge
//   left out as degenerate marks them too);
// - `claim_marked` (later rounds): the same for the three edges of each triangle the
//   round before marked, each by its smaller slot;
// - `flip` (one thread per triangle): the edge holding the claim of its own triangle
//   flips if it holds its other three claims too, and counts itself (count[0]; in the
//   last round count[1] too: 0 there means the mesh is final). A thread reads the
//   words of a triangle only once it holds that triangle's claim, and a winner writes
//   only triangles it holds: the flips of a round touch disjoint words, in place.
// The lowest candidate always wins its claims, so a round with a candidate flips at least
// one edge, and the winners are those of a fixed rule: the same result every run.
#import common/index.wgsl
#import disks/predicate.wgsl

// round: this round's number (from 0); tag: the rounds left after it.
struct Params { slots: u32, tolerance: f32, box_len: vec2<f32>, round: u32, tag: u32 }

// The low bits of a claim: the slot (the node refuses meshes of 2^27 slots or more).
const SLOT_BITS: u32 = 27u;
const SLOT_MASK: u32 = 0x7FFFFFFu;

@group(0) @binding(0) var<storage, read> x: array<vec2<f32>>;
@group(0) @binding(1) var<storage, read_write> out: array<u32>;
@group(0) @binding(2) var<storage, read_write> claims: array<atomic<u32>>;
@group(0) @binding(3) var<storage, read_write> count: array<atomic<u32>>;
@group(0) @binding(4) var<uniform> params: Params;
// The triangles the round before marked (read by `claim_marked`) and those this round
// marks.
@group(0) @binding(5) var<storage, read> marked: array<u32>;
// (marks hold round + 1 where this round marks.)
@group(0) @binding(6) var<storage, read_write> marks: array<atomic<u32>>;

// p - q by the minimum image. The image shift goes on p before the difference: p - k L
// is exact (both are multiples of p's ulp) and so is the difference of two nearby
// values, while (p - q) - k L first rounds p - q at the box's scale (an ulp of 1.2e-4 in
// a box of 1257, enough to make the in-circle test of a quad across the periodic
// boundary disagree with itself after a flip, which then never ends).
fn image_difference(p: vec2<f32>, q: vec2<f32>) -> vec2<f32> {
    return (p - params.box_len * round((p - q) / params.box_len)) - q;
}

fn vert(t: u32, k: u32) -> u32 {
    return out[6u * t + k % 3u];
}

fn twin(t: u32, k: u32) -> u32 {
    return out[6u * t + 3u + k % 3u];
}

fn mark(t: u32, u: u32) {
    atomicStore(&marks[t], params.round + 1u);
    atomicStore(&marks[u], params.round + 1u);
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
    // Two triangles sharing more than this edge (a torus of very few points): no flip,
    // but the next round looks again (a flip nearby may change that).
    if (a == d || xb == u || xc == u || yc == t || yb == t || t == u) {
        mark(t, u);
        return;
    }
    let xd = x[d];
    let code = flip_code(image_difference(pa, xd), image_difference(pb, xd),
        image_difference(pc, xd), params.tolerance);
    if (code != FLIP_KEEP) {
        let c = (params.tag << SLOT_BITS) | s;
        atomicMin(&claims[t], c);
        atomicMin(&claims[u], c);
        atomicMin(&claims[xb], c);
        atomicMin(&claims[yc], c);
        mark(t, u);
    }
}

// The edge of slot s, from its triangle's side.
fn claim_slot(s: u32, us: u32) {
    let t = s / 3u;
    let k = s % 3u;
    claim_edge(t, s, us, vert(t, k), x[vert(t, k)], x[vert(t, k + 1u)], x[vert(t, k + 2u)],
        twin(t, k + 1u) / 3u, twin(t, k + 2u) / 3u);
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
    let v = vec3<u32>(out[6u * t], out[6u * t + 1u], out[6u * t + 2u]);
    let w = vec3<u32>(out[6u * t + 3u], out[6u * t + 4u], out[6u * t + 5u]);
    let p0 = x[v.x];
    let p1 = x[v.y];
    let p2 = x[v.z];
    claim_edge(t, 3u * t, w.x, v.x, p0, p1, p2, w.y / 3u, w.z / 3u);
    claim_edge(t, 3u * t + 1u, w.y, v.y, p1, p2, p0, w.z / 3u, w.x / 3u);
    claim_edge(t, 3u * t + 2u, w.z, v.z, p2, p0, p1, w.x / 3u, w.y / 3u);
}

@compute @workgroup_size(256)
fn claim_marked(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
                @builtin(local_invocation_index) lid: u32) {
    let t = flat_index(wid, nwg, lid, 256u);
    if (t >= params.slots / 3u || marked[t] != params.round) {
        return;
    }
    // Each edge by its smaller slot, whichever triangle holds it (both may be marked:
    // the claims and marks are the same again).
    for (var k = 0u; k < 3u; k = k + 1u) {
        let s = 3u * t + k;
        let us = twin(t, k);
        if (us > s) {
            claim_slot(s, us);
        } else if (us < s) {
            claim_slot(us, twin(us / 3u, us));
        }
    }
}

@compute @workgroup_size(256)
fn flip(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    // One thread per triangle t: a winner s holds the claim of its own triangle s / 3, so
    // the edge whose slot holds claims[t] and lies in t is the one candidate of t that
    // may have won; only a candidate claims, so no predicate is evaluated again. Each
    // triangle's words are read only after its claim is seen held (no winner writes it).
    let tri = flat_index(wid, nwg, lid, 256u);
    if (tri >= params.slots / 3u) {
        return;
    }
    let c = atomicLoad(&claims[tri]);
    let s = c & SLOT_MASK;
    if (c >> SLOT_BITS != params.tag || s / 3u != tri) {
        return;
    }
    let us = twin(tri, s);
    if (us >= params.slots || atomicLoad(&claims[us / 3u]) != c) {
        return;
    }
    let xb = twin(tri, s + 1u) / 3u;
    let yc = twin(us / 3u, us + 1u) / 3u;
    if (atomicLoad(&claims[xb]) != c || atomicLoad(&claims[yc]) != c) {
        return;
    }
    // t = (a, b, c) from slot k, u = (d, c, b) from slot m; after: t = (a, b, d),
    // u = (d, c, a), the new edge a -> d between them. Every word is read before any is
    // written.
    let t = tri;
    let u = us / 3u;
    let k = s % 3u;
    let m = us % 3u;
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
    if (params.tag == 0u) {
        atomicAdd(&count[1], 1u);
    }
}
