// The edge-flip predicate of the disk triangulation (nodes/disks/flip.rs has its f64
// twin). For the edge b -> c of the counter-clockwise triangle (a, b, c), with d the
// vertex across it (triangle (d, c, b)):
// - FOLDED (2): a lies in the closed triangle (b, c, d), or d in (c, b, a): the quad has
//   folded over the edge (a vertex crossed it), S1 eq. 8 (the same-sign barycentric
//   test, both orientations);
// - ILLEGAL (1): both triangles and both flipped triangles positively oriented and d
//   strictly inside the circumcircle of (a, b, c): the in-circle determinant (relative to
//   d) above `tolerance` times m^2, m the largest squared distance from d to a, b, c.
//   The determinant's f32 round-off is about 1e-6 m^2; quads closer to cocircular than
//   the tolerance keep their edge (quasi-Delaunay);
// - KEEP (0) otherwise.
// Either way flipping the edge to a -> d repairs the quad.

const FLIP_KEEP: u32 = 0u;
const FLIP_ILLEGAL: u32 = 1u;
const FLIP_FOLDED: u32 = 2u;

fn cross2(p: vec2<f32>, q: vec2<f32>) -> f32 {
    return p.x * q.y - p.y * q.x;
}

// S1 eq. 8: v3 in the closed triangle (v1, v2, v4).
fn in_closed_triangle(v1: vec2<f32>, v2: vec2<f32>, v3: vec2<f32>, v4: vec2<f32>) -> bool {
    let e0 = v2 - v1;
    let e1 = v3 - v1;
    let e2 = v4 - v1;
    let d2 = cross2(e2, e0);
    let s2 = cross2(e1, e0);
    let t2 = cross2(e2, e1);
    if (d2 < 0.0) {
        return s2 <= 0.0 && t2 <= 0.0 && s2 + t2 >= d2;
    }
    return s2 >= 0.0 && t2 >= 0.0 && s2 + t2 <= d2;
}

// a, b, c relative to d (d at the origin).
fn flip_code(a: vec2<f32>, b: vec2<f32>, c: vec2<f32>, tolerance: f32) -> u32 {
    let d = vec2<f32>(0.0);
    if (in_closed_triangle(b, c, a, d) || in_closed_triangle(c, b, d, a)) {
        return FLIP_FOLDED;
    }
    let positive = cross2(b - a, c - a) > 0.0 && cross2(c, b) > 0.0
        && cross2(b - a, -a) > 0.0 && cross2(c, a) > 0.0;
    let la = dot(a, a);
    let lb = dot(b, b);
    let lc = dot(c, c);
    let det = a.x * (b.y * lc - lb * c.y) - a.y * (b.x * lc - lb * c.x) + la * (b.x * c.y - b.y * c.x);
    let m = max(la, max(lb, lc));
    if (positive && det > tolerance * m * m) {
        return FLIP_ILLEGAL;
    }
    return FLIP_KEEP;
}
