//! The edge-flip predicate on the GPU against its f64 twin on degenerate quads, and rounds
//! of `edge_flip_round` against their f64 reference until no edge needs a flip: the result
//! a valid triangulation of the torus and the Delaunay triangulation of the moved points.

use mesoflow::nodes::disks::flip::FlipCode;
use mesoflow::nodes::disks::mesh::{
    MESH_WORDS, check_torus_mesh, illegal_edges, in_circle, periodic_delaunay,
};
use mesoflow::nodes::disks::{minimum_image, wrap};

use crate::util::disks::disk_positions;
use crate::util::{Rng, flat_particles, gpu, indices, run_node_and_reference, u32s};

fn codes_of(quads: &[[f64; 8]]) -> (Vec<u32>, Vec<u32>) {
    let flat: Vec<f64> = quads.iter().flatten().copied().collect();
    let (out, refs) = run_node_and_reference(
        "flip_predicate",
        "{}",
        &[("quads", flat_particles(&flat, 8))],
    );
    let want = refs[0].data.iter().map(|&v| v as u32).collect();
    (u32s(&out["codes"]), want)
}

/// The edge b -> c of (a, b, c) = ((0, 1), (-1, 0), (1, 0)) with d below it: cocircular
/// (keep), inside (illegal), outside (keep), a on the edge or past it (folded), slivers
/// (illegal: the sliver's circumcircle holds d), nearly cocircular within the tolerance
/// (keep), nearly collinear d (illegal); then random quads, GPU and f64 equal wherever the
/// determinant is not within the f32 band of the threshold.
#[test]
fn flip_predicate_matches_its_f64_twin_on_degenerate_quads() {
    if gpu().is_none() {
        return;
    }
    let (b, c) = ([-1.0, 0.0], [1.0, 0.0]);
    let quad = |a: [f64; 2], d: [f64; 2]| [a[0], a[1], b[0], b[1], c[0], c[1], d[0], d[1]];
    let cases = [
        (quad([0.0, 1.0], [0.0, -1.0]), FlipCode::Keep, "cocircular"),
        (quad([0.0, 1.0], [0.0, -0.5]), FlipCode::Illegal, "inside"),
        (quad([0.0, 1.0], [0.0, -2.0]), FlipCode::Keep, "outside"),
        (
            quad([0.0, 0.0], [0.0, -1.0]),
            FlipCode::Folded,
            "a on the edge",
        ),
        (
            quad([0.3, -0.3], [0.0, -1.0]),
            FlipCode::Folded,
            "a crossed the edge",
        ),
        (
            quad([0.0, 1.0], [0.2, 0.4]),
            FlipCode::Folded,
            "d crossed the edge",
        ),
        (quad([0.0, 1e-3], [0.0, -1.0]), FlipCode::Illegal, "sliver"),
        (
            quad([0.0, 1e-3], [0.0, -1e-3]),
            FlipCode::Illegal,
            "two slivers",
        ),
        (
            quad([0.0, 1.0], [0.0, -(1.0 - 1e-7)]),
            FlipCode::Keep,
            "within the tolerance",
        ),
        (
            quad([0.0, 1.0], [0.0, -1e-6]),
            FlipCode::Illegal,
            "d nearly on the edge",
        ),
        (
            quad([0.0, 1.0], [3.0, -0.1]),
            FlipCode::Keep,
            "non-convex quad",
        ),
    ];
    let quads: Vec<[f64; 8]> = cases.iter().map(|c| c.0).collect();
    let (got, want) = codes_of(&quads);
    for (i, (_, code, what)) in cases.iter().enumerate() {
        assert_eq!(want[i], *code as u32, "{what}: the f64 twin");
        assert_eq!(got[i], *code as u32, "{what}: the GPU");
    }
    // Random quads around the edge: both sides, crossings, near-cocircular ones.
    let mut rng = Rng::new(17);
    let mut quads = Vec::new();
    for _ in 0..4000 {
        let a = [rng.uniform(-1.5, 1.5), rng.uniform(-0.5, 1.5)];
        let d = [rng.uniform(-1.5, 1.5), rng.uniform(-1.5, 0.5)];
        quads.push(quad(a, d));
    }
    let (got, want) = codes_of(&quads);
    let mut compared = 0;
    for (i, q) in quads.iter().enumerate() {
        let rel = |j: usize| [q[2 * j] - q[6], q[2 * j + 1] - q[7]];
        let m = (0..3)
            .map(|j| rel(j)[0].powi(2) + rel(j)[1].powi(2))
            .fold(0.0, f64::max);
        let margin = (in_circle(rel(0), rel(1), rel(2), [0.0; 2]) / (m * m) - 1e-5).abs();
        if margin > 1e-5 {
            assert_eq!(got[i], want[i], "quad {i} {q:?}");
            compared += 1;
        }
    }
    assert!(compared > 3900, "{compared} quads compared");
}

fn edge_set(mesh: &[u32]) -> Vec<(u32, u32)> {
    let mut e: Vec<(u32, u32)> = mesh
        .chunks(MESH_WORDS)
        .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
        .map(|(a, b)| (a.min(b), a.max(b)))
        .collect();
    e.sort_unstable();
    e
}

/// 300 disks, their Delaunay mesh, then every disk moved by up to 0.15 per axis (many
/// edges turn illegal) and three pushed across an edge (their triangles invert). Rounds of flips on the GPU (one per
/// evaluation, then four), each evaluation equal to the f64 rounds word for word, until a round flips nothing: then the mesh is a valid
/// triangulation of the torus with no inverted triangle, no illegal edge in f64, and the
/// same edges as the Delaunay triangulation built afresh from the moved points.
#[test]
fn flip_rounds_restore_the_delaunay_triangulation() {
    if gpu().is_none() {
        return;
    }
    let l = [18.0, 16.0];
    let mut rng = Rng::new(23);
    let x0 = disk_positions(&mut rng, 300, l, 0.7);
    let mesh = periodic_delaunay(&x0, l).unwrap();
    let mut x: Vec<f64> = x0.iter().map(|v| v + rng.uniform(-0.15, 0.15)).collect();
    // Three vertices pushed just across the opposite edge of a triangle of theirs (10 %
    // of their distance to its midpoint past it): folded quads for the repair.
    for t in [0, 200, 400] {
        let v = &mesh[MESH_WORDS * t..MESH_WORDS * t + 3];
        let (a, b, c) = (v[0] as usize, v[1] as usize, v[2] as usize);
        for k in 0..2 {
            let near = |w: usize| x[2 * a + k] + minimum_image(x[2 * w + k] - x[2 * a + k], l[k]);
            let mid = 0.5 * (near(b) + near(c));
            x[2 * a + k] = mid + 0.1 * (mid - x[2 * a + k]);
        }
    }
    let x: Vec<f64> = x
        .iter()
        .enumerate()
        .map(|(i, v)| wrap(*v, l[i % 2]) as f32 as f64)
        .collect();
    let before = check_torus_mesh(&mesh, &x, l).unwrap();
    let illegal = illegal_edges(&mesh, &x, l, 1e-5).len();
    assert!(
        before.inverted > 0 && illegal > 20,
        "{before:?}, {illegal} illegal edges"
    );
    let start = mesh;
    // One round per evaluation, and the default four (the later ones on marked
    // triangles only).
    for params in [r#"{"box": [18, 16], "rounds": 1}"#, r#"{"box": [18, 16]}"#] {
        let mut mesh = start.clone();
        let mut counts = Vec::new();
        loop {
            let (out, refs) = run_node_and_reference(
                "edge_flip_round",
                params,
                &[
                    ("positions", flat_particles(&x, 2)),
                    ("mesh", indices(&mesh)),
                ],
            );
            let next = u32s(&out["mesh"]);
            let flips = u32s(&out["flips"])[0];
            let want: Vec<u32> = refs[0].data.iter().map(|&v| v as u32).collect();
            assert_eq!(
                next,
                want,
                "round {}: the GPU's mesh and the f64 round's",
                counts.len()
            );
            assert_eq!(
                flips as f64,
                refs[1].data[0],
                "round {}: flips",
                counts.len()
            );
            counts.push(flips);
            check_torus_mesh(&next, &x, l).unwrap();
            mesh = next;
            if flips == 0 || counts.len() == 40 {
                break;
            }
        }
        assert_eq!(counts.last(), Some(&0), "flips per round {counts:?}");
        let after = check_torus_mesh(&mesh, &x, l).unwrap();
        assert_eq!(after.inverted, 0, "{after:?}; flips per round {counts:?}");
        assert_eq!(illegal_edges(&mesh, &x, l, 1e-5), Vec::<usize>::new());
        assert_eq!(
            edge_set(&mesh),
            edge_set(&periodic_delaunay(&x, l).unwrap()),
            "flips per round {counts:?}"
        );
        eprintln!("{params}: {before:?}, {illegal} illegal edges; flips per evaluation {counts:?}");
    }
}

/// S1's pass-through check: small moves cross no edge; a disk moved through its
/// neighbour (to the mirror side of it) is counted, the GPU as the f64 count.
#[test]
fn pass_through_count_finds_a_disk_moved_through_its_neighbour() {
    if gpu().is_none() {
        return;
    }
    let l = [18.0, 16.0];
    let mut rng = Rng::new(47);
    let x0 = disk_positions(&mut rng, 200, l, 0.8);
    let mesh = periodic_delaunay(&x0, l).unwrap();
    let before: Vec<f64> = x0.iter().map(|&v| v as f32 as f64).collect();
    let small: Vec<f64> = before
        .iter()
        .enumerate()
        .map(|(i, v)| wrap(v + rng.uniform(-0.05, 0.05), l[i % 2]))
        .collect();
    // The first edge's end points b, c: b moved to c + (c - b).
    let (b, c) = (mesh[1] as usize, mesh[2] as usize);
    let mut through = before.clone();
    for a in 0..2 {
        let r = minimum_image(before[2 * c + a] - before[2 * b + a], l[a]);
        through[2 * b + a] = wrap(before[2 * c + a] + r, l[a]);
    }
    let mut counts = Vec::new();
    for after in [&small, &through] {
        let (out, refs) = run_node_and_reference(
            "pass_through_count",
            r#"{"box": [18, 16]}"#,
            &[
                ("before", flat_particles(&before, 2)),
                ("after", flat_particles(after, 2)),
                ("mesh", indices(&mesh)),
            ],
        );
        let got = u32s(&out["count"])[0];
        assert_eq!(got as f64, refs[0].data[0]);
        counts.push(got);
    }
    assert_eq!(counts[0], 0, "moves of at most 0.1 between disks 0.8 apart");
    assert!(counts[1] >= 1, "the disk moved through its neighbour");
}
