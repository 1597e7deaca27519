//! The triangulation of the torus that the disk nodes keep on the GPU, built once on the
//! host, and its checks.
//!
//! **Layout** (one u32 array, `MESH_WORDS` = 6 words per triangle, 2N triangles for N
//! points): `[v0, v1, v2, s0, s1, s2]`: the vertices counter-clockwise, and for each slot
//! k the edge opposite v_k (from v_(k+1) to v_(k+2)) as the slot `3 t' + k'` that holds the
//! same edge, reversed, in the neighbouring triangle t' (its twin). Slots rather than
//! triangle ids, because on a small torus two triangles may share more than one edge.
//! An edge is handled by the slot of the pair with the smaller index (E = 3N edges).
//!
//! **Geometry by the minimum image.** The mesh stores no image shifts: every edge vector
//! is the minimum image of the difference of its end points, so particles may wrap
//! freely. This holds while every edge is shorter than half the box along each axis;
//! `periodic_delaunay` refuses points whose triangulation has a longer edge (too few
//! points for the box), and the edge vectors around each triangle must close.
//!
//! **Construction.** The points and their 8 periodic copies (3 x 3 boxes) are
//! triangulated by `delaunator` (robust predicates, f64); of each triangle of the torus
//! the copy kept is the one whose vertex of smallest id lies in the central box (exact,
//! no rounding at the faces); the triangles are put in the Morton order of their
//! centroids (`morton_cells`), whatever the points' numbering, and the twins are matched
//! by (from, to, image shift of `to` relative to `from`). Points in degenerate position (four on a circle) may be
//! triangulated differently in different copies; the trimmed result is then not a
//! triangulation of the torus, and the build says so instead of returning it.

use std::collections::HashMap;

use super::{minimum_image, wrap};

/// u32 words per triangle: 3 vertices, 3 twin slots.
pub const MESH_WORDS: usize = 6;

/// Why no triangulation of the torus came out of the points.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum MeshError {
    #[error("{0}")]
    Input(String),
    #[error(
        "an edge of the triangulation spans {length:.4} along axis {axis}, at least half the box ({half:.4}): the mesh works by the minimum image and needs more points in this box"
    )]
    LongEdge { axis: usize, length: f64, half: f64 },
    #[error(
        "the periodic copies were triangulated inconsistently ({0}): points in degenerate position (four on a circle, a lattice); perturb them slightly"
    )]
    Inconsistent(String),
}

/// 2-D cross product of b - a and c - a (twice the signed area of a, b, c).
pub fn orient(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

/// The in-circle determinant of d against the counter-clockwise triangle (a, b, c):
/// positive when d lies strictly inside its circumcircle, zero on it. Computed relative
/// to d, in f64.
pub fn in_circle(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> f64 {
    let r = |p: [f64; 2]| {
        let (x, y) = (p[0] - d[0], p[1] - d[1]);
        [x, y, x * x + y * y]
    };
    let (a, b, c) = (r(a), r(b), r(c));
    a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
        + a[2] * (b[0] * c[1] - b[1] * c[0])
}

/// The periodic Delaunay triangulation of `x` (N x 2, flat) in the box `l` (both lengths
/// positive), in the layout above. Points outside the box are wrapped first.
pub fn periodic_delaunay(x: &[f64], l: [f64; 2]) -> Result<Vec<u32>, MeshError> {
    if !(l[0] > 0.0 && l[1] > 0.0 && l.iter().all(|v| v.is_finite())) {
        return Err(MeshError::Input(format!(
            "the box {l:?} must have two positive finite lengths (a torus)"
        )));
    }
    let n = x.len() / 2;
    if n < 3 || !x.len().is_multiple_of(2) {
        return Err(MeshError::Input(format!(
            "need at least 3 points (N x 2 values), got {} values",
            x.len()
        )));
    }
    if n as u64 * 3 * 2 >= u32::MAX as u64 {
        return Err(MeshError::Input(format!(
            "{n} points: the slots overflow u32"
        )));
    }
    if let Some(i) = x.iter().position(|v| !v.is_finite()) {
        return Err(MeshError::Input(format!(
            "point {} is not finite ({})",
            i / 2,
            x[i]
        )));
    }
    let p: Vec<[f64; 2]> = x
        .chunks(2)
        .map(|c| [wrap(c[0], l[0]), wrap(c[1], l[1])])
        .collect();
    // Copy c of the 3 x 3 boxes is shifted by SHIFTS[c] box lengths; copy 0 is the box.
    const SHIFTS: [[i32; 2]; 9] = [
        [0, 0],
        [-1, -1],
        [0, -1],
        [1, -1],
        [-1, 0],
        [1, 0],
        [-1, 1],
        [0, 1],
        [1, 1],
    ];
    let points: Vec<delaunator::Point> = SHIFTS
        .iter()
        .flat_map(|s| {
            p.iter().map(move |q| delaunator::Point {
                x: q[0] + s[0] as f64 * l[0],
                y: q[1] + s[1] as f64 * l[1],
            })
        })
        .collect();
    let dt = delaunator::triangulate(&points);
    let at = |i: usize| [points[i].x, points[i].y];
    let id = |i: usize| (i % n) as u32;
    let shift = |i: usize| SHIFTS[i / n];
    let mut tris: Vec<[usize; 3]> = Vec::with_capacity(2 * n);
    for t in dt.triangles.chunks_exact(3) {
        let mut v = [t[0], t[1], t[2]];
        let lowest = *v.iter().min_by_key(|&&i| id(i)).expect("three");
        if lowest >= n {
            continue;
        }
        if orient(at(v[0]), at(v[1]), at(v[2])) < 0.0 {
            v.swap(1, 2);
        }
        tris.push(v);
    }
    if tris.len() != 2 * n {
        return Err(MeshError::Inconsistent(format!(
            "{} triangles kept for {n} points, not 2N",
            tris.len()
        )));
    }
    // Edge lengths along each axis: the minimum image must be the edge.
    for t in &tris {
        for k in 0..3 {
            let (a, b) = (at(t[k]), at(t[(k + 1) % 3]));
            for axis in 0..2 {
                let length = (b[axis] - a[axis]).abs();
                if length >= 0.5 * l[axis] {
                    return Err(MeshError::LongEdge {
                        axis,
                        length,
                        half: 0.5 * l[axis],
                    });
                }
            }
        }
    }
    // Triangles in space order: delaunator's order spirals out from its seed, so
    // neighbours in the mesh would be far apart in memory; sorted by the Morton cell of
    // their centroids (about a point a cell), the kernels that walk triangles read nearby
    // words. Before the twins, which are then matched in this order.
    let cells = morton_cells(n);
    tris.sort_by_cached_key(|t| {
        let c = [0, 1].map(|a| {
            let centroid = (at(t[0])[a] + at(t[1])[a] + at(t[2])[a]) / 3.0;
            let u = (wrap(centroid, l[a]) / l[a] + 0.5) * cells as f64;
            (u.floor() as i64).clamp(0, cells as i64 - 1) as u32
        });
        super::super::cells::morton(&c)
    });
    // Twins: slot k of triangle t is the edge v_(k+1) -> v_(k+2).
    type EdgeKey = (u32, u32, [i32; 2]);
    let key = |from: usize, to: usize| -> EdgeKey {
        let (sf, st) = (shift(from), shift(to));
        (id(from), id(to), [st[0] - sf[0], st[1] - sf[1]])
    };
    let mut slots: HashMap<EdgeKey, u32> = HashMap::with_capacity(6 * n);
    for (ti, t) in tris.iter().enumerate() {
        for k in 0..3 {
            let s = (3 * ti + k) as u32;
            if slots
                .insert(key(t[(k + 1) % 3], t[(k + 2) % 3]), s)
                .is_some()
            {
                return Err(MeshError::Inconsistent(format!(
                    "the edge of slot {s} appears twice"
                )));
            }
        }
    }
    let mut mesh = Vec::with_capacity(MESH_WORDS * tris.len());
    for (ti, t) in tris.iter().enumerate() {
        mesh.extend(t.iter().map(|&v| id(v)));
        for k in 0..3 {
            let Some(&twin) = slots.get(&key(t[(k + 2) % 3], t[(k + 1) % 3])) else {
                return Err(MeshError::Inconsistent(format!(
                    "the edge of slot {} has no twin",
                    3 * ti + k
                )));
            };
            mesh.push(twin);
        }
    }
    Ok(mesh)
}

/// Cells per axis of the Morton order `periodic_delaunay` puts the triangles of `n`
/// points in: the power of two nearest below sqrt(n) (about a point a cell, two
/// triangles), at most 2^16.
pub fn morton_cells(n: usize) -> u32 {
    let mut c = 1u32;
    while c < 1 << 16 && (2 * c as u64) * (2 * c as u64) <= n as u64 {
        c *= 2;
    }
    c
}

/// What `check_torus_mesh` counted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshStats {
    pub vertices: usize,
    pub edges: usize,
    pub triangles: usize,
    /// Triangles whose minimum-image orientation is not positive.
    pub inverted: usize,
}

/// The edge vectors of triangle `t` by the minimum image: v1 - v0, v2 - v0, and the
/// mismatch |(v2 - v1) - ((v2 - v0) - (v1 - v0))| (0 when the images close).
fn triangle_vectors(mesh: &[u32], x: &[f64], l: [f64; 2], t: usize) -> ([f64; 2], [f64; 2], f64) {
    let v = &mesh[MESH_WORDS * t..MESH_WORDS * t + 3];
    let d = |a: u32, b: u32| -> [f64; 2] {
        std::array::from_fn(|k| minimum_image(x[2 * b as usize + k] - x[2 * a as usize + k], l[k]))
    };
    let (e1, e2, e12) = (d(v[0], v[1]), d(v[0], v[2]), d(v[1], v[2]));
    let gap = (e12[0] - (e2[0] - e1[0])).hypot(e12[1] - (e2[1] - e1[1]));
    (e1, e2, gap)
}

/// Checks that `mesh` is a triangulation of the torus over the N points `x` (flat N x 2)
/// in the box `l`: 2N triangles, vertex ids in range, twins that are slots of the same
/// edge reversed and point back (so E = 3N), each vertex's corners one cycle whose angles
/// sum to 2 pi, and minimum-image edge vectors that close around every triangle. Inverted
/// (not positively oriented) triangles are counted, not refused: a step may leave some
/// for the repair to flip. Errors name the first triangle or vertex that breaks a rule.
pub fn check_torus_mesh(mesh: &[u32], x: &[f64], l: [f64; 2]) -> Result<MeshStats, String> {
    let n = x.len() / 2;
    if !mesh.len().is_multiple_of(MESH_WORDS) {
        return Err(format!(
            "{} words: not {MESH_WORDS} per triangle",
            mesh.len()
        ));
    }
    let tris = mesh.len() / MESH_WORDS;
    if tris != 2 * n {
        return Err(format!(
            "{tris} triangles for {n} points: a torus has F = 2N"
        ));
    }
    let vert = |s: usize| mesh[MESH_WORDS * (s / 3) + s % 3];
    let twin = |s: usize| mesh[MESH_WORDS * (s / 3) + 3 + s % 3] as usize;
    let from = |s: usize| vert(3 * (s / 3) + (s % 3 + 1) % 3);
    let to = |s: usize| vert(3 * (s / 3) + (s % 3 + 2) % 3);
    for s in 0..3 * tris {
        if vert(s) as usize >= n {
            return Err(format!("triangle {}: vertex {} >= N = {n}", s / 3, vert(s)));
        }
        let u = twin(s);
        if u >= 3 * tris || u / 3 == s / 3 {
            return Err(format!(
                "slot {s}: twin {u} is out of range or in the same triangle"
            ));
        }
        if twin(u) != s {
            return Err(format!("slot {s}: its twin {u} points to {}", twin(u)));
        }
        if from(u) != to(s) || to(u) != from(s) {
            return Err(format!(
                "slot {s} is the edge {} -> {} but its twin {u} is {} -> {}",
                from(s),
                to(s),
                from(u),
                to(u)
            ));
        }
    }
    let mut inverted = 0;
    for t in 0..tris {
        let v = &mesh[MESH_WORDS * t..MESH_WORDS * t + 3];
        if v[0] == v[1] || v[1] == v[2] || v[0] == v[2] {
            return Err(format!("triangle {t} repeats a vertex: {v:?}"));
        }
        let (e1, e2, gap) = triangle_vectors(mesh, x, l, t);
        if gap > 1e-9 * (l[0] + l[1]) {
            return Err(format!(
                "triangle {t} {v:?}: its minimum-image edges do not close (gap {gap:e}): an edge spans half the box"
            ));
        }
        if orient([0.0; 2], e1, e2) <= 0.0 {
            inverted += 1;
        }
    }
    // Corners around each vertex: corner (t, k) is followed by the corner of the same
    // vertex across the edge v_k -> v_(k+1) (slot k + 2).
    let mut seen = vec![false; 3 * tris];
    let mut cycles = vec![0u32; n];
    let mut angle = vec![0.0f64; n];
    for c0 in 0..3 * tris {
        if seen[c0] {
            continue;
        }
        let v = vert(c0) as usize;
        cycles[v] += 1;
        let mut c = c0;
        loop {
            seen[c] = true;
            let (t, k) = (c / 3, c % 3);
            let p = |j: usize| {
                let w = vert(3 * t + (k + j) % 3) as usize;
                [0, 1].map(|a| minimum_image(x[2 * w + a] - x[2 * v + a], l[a]))
            };
            let (a, b) = (p(1), p(2));
            angle[v] += (a[0] * b[1] - a[1] * b[0]).atan2(a[0] * b[0] + a[1] * b[1]);
            let u = twin(3 * t + (k + 2) % 3);
            c = 3 * (u / 3) + (u % 3 + 2) % 3;
            if vert(c) as usize != v {
                return Err(format!(
                    "the corners around vertex {v} lead to vertex {}",
                    vert(c)
                ));
            }
            if c == c0 {
                break;
            }
            if seen[c] {
                return Err(format!("the corners around vertex {v} do not close"));
            }
        }
    }
    if let Some(v) = cycles.iter().position(|&c| c != 1) {
        return Err(format!(
            "vertex {v} has {} fans of triangles, not one",
            cycles[v]
        ));
    }
    if inverted == 0
        && let Some(v) = angle
            .iter()
            .position(|a| (a - 2.0 * std::f64::consts::PI).abs() > 1e-6)
    {
        return Err(format!(
            "the angles around vertex {v} sum to {}, not 2 pi: the mesh folds over itself",
            angle[v]
        ));
    }
    Ok(MeshStats {
        vertices: n,
        edges: 3 * tris / 2,
        triangles: tris,
        inverted,
    })
}

/// The edges (by their smaller slot) whose opposite vertex across the edge lies inside the
/// circumcircle of the triangle, by more than `tolerance` times the in-circle
/// determinant's scale (the largest squared distance from d to a, b, c, squared: the
/// determinant is of degree 4 in lengths): the edges that break the Delaunay condition,
/// in f64.
pub fn illegal_edges(mesh: &[u32], x: &[f64], l: [f64; 2], tolerance: f64) -> Vec<usize> {
    let mut out = Vec::new();
    for s in 0..mesh.len() / MESH_WORDS * 3 {
        let u = mesh[MESH_WORDS * (s / 3) + 3 + s % 3] as usize;
        if u < s {
            continue;
        }
        let (a, b, c, d) = quad(mesh, x, l, s, u);
        let m = [a, b, c]
            .iter()
            .map(|p| p[0] * p[0] + p[1] * p[1])
            .fold(0.0f64, f64::max);
        let scale = m * m;
        if in_circle(a, b, c, d) > tolerance * scale {
            out.push(s);
        }
    }
    out
}

/// The quadrilateral of slot s (triangle (a, b, c), a opposite the edge b -> c) and its
/// twin u (d opposite), relative to d by the minimum image: (a, b, c, d = 0).
pub fn quad(
    mesh: &[u32],
    x: &[f64],
    l: [f64; 2],
    s: usize,
    u: usize,
) -> ([f64; 2], [f64; 2], [f64; 2], [f64; 2]) {
    let vert = |t: usize, k: usize| mesh[MESH_WORDS * t + k % 3] as usize;
    let (t, k) = (s / 3, s % 3);
    let d = vert(u / 3, u % 3);
    let rel = |w: usize| [0, 1].map(|a| minimum_image(x[2 * w + a] - x[2 * d + a], l[a]));
    (
        rel(vert(t, k)),
        rel(vert(t, k + 1)),
        rel(vert(t, k + 2)),
        [0.0, 0.0],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lcg_points(n: usize, l: [f64; 2], seed: u64) -> Vec<f64> {
        let mut s = seed;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        (0..2 * n).map(|i| (next() - 0.5) * l[i % 2]).collect()
    }

    /// Random points: a valid torus triangulation (E = 3N, F = 2N, no inverted
    /// triangle), Delaunay in f64 (no edge whose opposite vertex is inside the
    /// circumcircle), and each edge's twin the same pair of points.
    #[test]
    fn random_points_give_a_delaunay_triangulation_of_the_torus() {
        for (n, l, seed) in [
            (200, [14.0, 11.0], 1),
            (37, [6.0, 6.0], 2),
            (1000, [30.0, 40.0], 3),
        ] {
            let x = lcg_points(n, l, seed);
            let mesh = periodic_delaunay(&x, l).unwrap();
            let stats = check_torus_mesh(&mesh, &x, l).unwrap();
            assert_eq!(
                stats,
                MeshStats {
                    vertices: n,
                    edges: 3 * n,
                    triangles: 2 * n,
                    inverted: 0
                }
            );
            assert_eq!(illegal_edges(&mesh, &x, l, 1e-12), Vec::<usize>::new());
            // Euler's relation on the torus: V - E + F = 0.
            assert_eq!(stats.vertices + stats.triangles, stats.edges);
        }
    }

    /// The same points shifted by whole boxes (wrapped back) give the same edges.
    #[test]
    fn the_triangulation_does_not_depend_on_the_images_given() {
        let l = [10.0, 10.0];
        let x = lcg_points(120, l, 4);
        let shifted: Vec<f64> = x
            .iter()
            .enumerate()
            .map(|(i, v)| v + if i % 3 == 0 { 10.0 } else { -20.0 })
            .collect();
        let edges = |m: &[u32]| {
            let mut e: Vec<(u32, u32)> = m
                .chunks(MESH_WORDS)
                .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
                .map(|(a, b)| (a.min(b), a.max(b)))
                .collect();
            e.sort_unstable();
            e
        };
        assert_eq!(
            edges(&periodic_delaunay(&x, l).unwrap()),
            edges(&periodic_delaunay(&shifted, l).unwrap())
        );
    }

    /// The triangles come in the Morton order of their centroids (delaunator's spiral
    /// undone): the keys never decrease, and consecutive triangles lie close together
    /// (a few point spacings on average, against about L/3 for a random order), with
    /// the twins matched in that order (a valid torus mesh).
    #[test]
    fn triangles_are_in_the_morton_order_of_their_centroids() {
        let (n, l) = (4000, [60.0, 60.0]);
        let x = lcg_points(n, l, 6);
        let mesh = periodic_delaunay(&x, l).unwrap();
        check_torus_mesh(&mesh, &x, l).unwrap();
        let cells = morton_cells(n);
        assert_eq!(cells, 32);
        let centroid = |t: &[u32]| {
            [0, 1].map(|a| {
                let p = x[2 * t[0] as usize + a];
                let d1 = minimum_image(x[2 * t[1] as usize + a] - p, l[a]);
                let d2 = minimum_image(x[2 * t[2] as usize + a] - p, l[a]);
                wrap(p + (d1 + d2) / 3.0, l[a])
            })
        };
        let key = |c: [f64; 2]| {
            let i = [0, 1].map(|a| {
                (((c[a] / l[a] + 0.5) * cells as f64).floor() as i64).clamp(0, cells as i64 - 1)
                    as u32
            });
            crate::nodes::cells::morton(&i)
        };
        let centroids: Vec<[f64; 2]> = mesh.chunks(MESH_WORDS).map(centroid).collect();
        let keys: Vec<u64> = centroids.iter().map(|&c| key(c)).collect();
        assert!(keys.windows(2).all(|w| w[0] <= w[1]), "keys out of order");
        let gap = centroids
            .windows(2)
            .map(|w| {
                let d = [0, 1].map(|a| minimum_image(w[1][a] - w[0][a], l[a]));
                d[0].hypot(d[1])
            })
            .sum::<f64>()
            / (centroids.len() - 1) as f64;
        let spacing = (l[0] * l[1] / n as f64).sqrt();
        assert!(gap < 3.0 * spacing, "mean gap {gap} for spacing {spacing}");
    }

    /// Too few points for the box: an edge would span half of it.
    #[test]
    fn sparse_points_are_refused_by_the_minimum_image_rule() {
        let x = [0.0, 0.0, 1.0, 0.2, 0.3, 1.1, -0.4, 0.5];
        let e = periodic_delaunay(&x, [40.0, 40.0]).unwrap_err();
        assert!(matches!(e, MeshError::LongEdge { .. }), "{e}");
        assert!(periodic_delaunay(&x, [0.0, 4.0]).is_err());
    }

    /// The checker refuses broken meshes: a twin that does not point back, a vertex
    /// swapped (which inverts or disconnects), a wrong triangle count.
    #[test]
    fn the_checker_refuses_broken_meshes() {
        let l = [9.0, 9.0];
        let x = lcg_points(60, l, 5);
        let mesh = periodic_delaunay(&x, l).unwrap();
        let mut bad = mesh.clone();
        bad[3] = mesh[9];
        assert!(check_torus_mesh(&bad, &x, l).unwrap_err().contains("twin"));
        let mut bad = mesh.clone();
        bad.swap(0, 1);
        assert!(check_torus_mesh(&bad, &x, l).is_err());
        assert!(check_torus_mesh(&mesh[..mesh.len() - MESH_WORDS], &x, l).is_err());
        // Moving a point across an edge inverts a triangle, and the count says so.
        let t = &mesh[..3];
        let (a, b) = (t[1] as usize, t[2] as usize);
        let mut moved = x.clone();
        let v = t[0] as usize;
        for k in 0..2 {
            // Reflect v through the midpoint of the opposite edge (by the minimum image).
            let mid = x[2 * a + k] + 0.5 * minimum_image(x[2 * b + k] - x[2 * a + k], l[k]);
            moved[2 * v + k] = wrap(2.0 * mid - x[2 * v + k], l[k]);
        }
        let stats = check_torus_mesh(&mesh, &moved, l).unwrap();
        assert!(stats.inverted >= 1, "{stats:?}");
    }

    /// The in-circle determinant: inside, on and outside the unit circle through
    /// (1, 0), (0, 1), (-1, 0).
    #[test]
    fn in_circle_signs() {
        let (a, b, c) = ([1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]);
        assert!(in_circle(a, b, c, [0.0, -0.5]) > 0.0);
        assert_eq!(in_circle(a, b, c, [0.0, -1.0]), 0.0);
        assert!(in_circle(a, b, c, [0.0, -1.5]) < 0.0);
    }
}
