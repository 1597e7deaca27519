//! Gather, scatter, histograms and cell hashing against their references; a
//! permutation's inverse and ids relabelled through a table (a mesh following its points
//! into a new order and back).

use mesoflow::nodes::disks::mesh::{MESH_WORDS, check_torus_mesh, periodic_delaunay};
use mesoflow::value::{HostArray, ValueType};

use crate::util::{Rng, gpu, indices, random_points, run_out, u32s, validation_error};

fn permutation(rng: &mut Rng, n: u32) -> Vec<u32> {
    let mut p: Vec<u32> = (0..n).collect();
    for i in (1..n as usize).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        p.swap(i, j);
    }
    p
}

#[test]
fn gather_and_scatter_follow_an_index() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(31);
    for n in [0u32, 1, 7, 1000] {
        let values = rng.array(ValueType::Particles { n, k: 3 }, -1.0, 1.0);
        let keys = indices(&(0..n).map(|_| rng.next_u64() as u32).collect::<Vec<_>>());
        let perm = indices(&permutation(&mut rng, n));
        for v in [&values, &keys] {
            let (g, r) = run_out(
                "gather",
                "{}",
                &[("values", v.clone()), ("index", perm.clone())],
            );
            let (g, r) = (g.data.to_f64(), r.data);
            assert_eq!(g, r, "gather {n}");
            let (g, r) = run_out(
                "scatter",
                "{}",
                &[("values", v.clone()), ("index", perm.clone())],
            );
            let (g, r) = (g.data.to_f64(), r.data);
            assert_eq!(g, r, "scatter {n}");
            let (g, r) = run_out(
                "scatter",
                r#"{"permutation": true}"#,
                &[("values", v.clone()), ("index", perm.clone())],
            );
            let (g, r) = (g.data.to_f64(), r.data);
            assert_eq!(g, r, "scatter by a permutation {n}");
        }
    }
    // Out-of-range indices: gather gives zeros, scatter skips; scatter into more rows.
    let values = rng.array(ValueType::Particles { n: 4, k: 2 }, 1.0, 2.0);
    let index = indices(&[3, 9, u32::MAX, 0]);
    let (g, r) = run_out(
        "gather",
        "{}",
        &[("values", values.clone()), ("index", index.clone())],
    );
    let (g, r) = (g.data.to_f64(), r.data);
    assert_eq!(g, r);
    assert_eq!(&g[2..6], &[0.0; 4]);
    let (g, r) = run_out(
        "scatter",
        r#"{"rows": 12}"#,
        &[("values", values), ("index", index)],
    );
    let (g, r) = (g.data.to_f64(), r.data);
    assert_eq!(g, r);
    assert_eq!(g.len(), 24);
}

#[test]
fn histograms_count_keys() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(4);
    for (n, bins) in [(0u32, 1u32), (1, 1), (5000, 17), (100_000, 1000)] {
        // Keys up to twice the bins, so some fall outside; plus the extremes.
        let mut keys: Vec<u32> = (0..n)
            .map(|_| (rng.next_u64() % (2 * bins as u64)) as u32)
            .collect();
        if n > 2 {
            keys[0] = u32::MAX;
            keys[1] = 0;
        }
        let (g, r) = run_out(
            "histogram",
            &format!(r#"{{"bins": {bins}}}"#),
            &[("keys", indices(&keys))],
        );
        let (g, r) = (g.data.to_f64(), r.data);
        assert_eq!(g, r, "histogram of {n} keys in {bins} bins");
    }
}

/// Compares cell keys, forgiving only particles that sit within f32 rounding of a cell
/// face (where f32 and f64 may legitimately pick different sides).
fn check_hash(params: &str, positions: &HostArray, box_len: &[f64], cells: &[u32]) {
    let (g, r) = run_out("cell_hash", params, &[("positions", positions.clone())]);
    let (g, r) = (g.data.to_f64(), r.data);
    let pos = positions.data.to_f64();
    let d = box_len.len();
    for (p, (a, b)) in g.iter().zip(&r).enumerate() {
        if a == b {
            continue;
        }
        let near_face = (0..d).any(|ax| {
            let s = pos[p * d + ax] * cells[ax] as f64 / box_len[ax] + cells[ax] as f64 / 2.0;
            (s - s.round()).abs() < 1e-5 * s.abs().max(1.0)
        });
        assert!(
            near_face,
            "{params}: particle {p} at {:?}: GPU key {a}, reference {b}",
            &pos[p * d..p * d + d]
        );
    }
}

#[test]
fn cell_hashes_wrap_periodic_boxes_in_every_order() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(8);
    // Non-cubic boxes and cells; positions inside and up to three boxes away.
    let cases: &[(&[f64], &[u32])] = &[
        (&[10.0, 6.0, 4.5], &[10, 4, 9]),
        (&[64.0, 64.0, 64.0], &[64, 64, 64]),
        (&[3.0, 7.0], &[5, 33]),
    ];
    for (box_len, cells) in cases {
        let d = box_len.len() as u32;
        let n = 5000;
        let mut v = Vec::new();
        for _ in 0..n {
            for ax in 0..d as usize {
                v.push(rng.uniform(-2.0 * box_len[ax], 2.0 * box_len[ax]) as f32);
            }
        }
        let positions = HostArray::f32(ValueType::Particles { n, k: d }, v);
        for order in ["linear", "morton"] {
            let params =
                format!(r#"{{"box": {box_len:?}, "cells": {cells:?}, "order": "{order}"}}"#);
            check_hash(&params, &positions, box_len, cells);
        }
    }
}

#[test]
fn cell_hashes_on_faces_edges_and_walls() {
    if gpu().is_none() {
        return;
    }
    // Exactly representable positions: box 8, 8 cells of size 1. -L/2 is cell 0, +L/2
    // wraps to cell 0, a cell face belongs to the cell above it.
    let pos: Vec<f32> = vec![
        -4.0, -4.0, -4.0, 4.0, 4.0, 4.0, 0.0, 0.0, 0.0, -1.0, 1.0, 3.0, 3.999, -0.0, 12.0, -12.0,
        4.5, -4.5,
    ];
    let positions = HostArray::f32(ValueType::Particles { n: 6, k: 3 }, pos);
    let params = r#"{"box": [8, 8, 8], "cells": [8, 8, 8]}"#;
    let (g, r) = run_out("cell_hash", params, &[("positions", positions.clone())]);
    let (g, r) = (g.data.to_f64(), r.data);
    assert_eq!(g, r);
    let cell = |x: u32, y: u32, z: u32| (x + 8 * (y + 8 * z)) as f64;
    assert_eq!(
        g,
        vec![
            cell(0, 0, 0),
            cell(0, 0, 0),
            cell(4, 4, 4),
            cell(3, 5, 7),
            cell(7, 4, 0),
            cell(0, 0, 7)
        ]
    );
    // Walls along z clamp to the edge cells instead of wrapping.
    let walls = r#"{"box": [8, 8, 8], "cells": [8, 8, 8], "periodic": [1, 1, 0]}"#;
    let (g, r) = run_out("cell_hash", walls, &[("positions", positions)]);
    let (g, r) = (g.data.to_f64(), r.data);
    assert_eq!(g, r);
    assert_eq!(
        g[1],
        cell(0, 0, 7),
        "+L/2 on a walled axis stays in the top cell"
    );
    assert_eq!(
        g[5],
        cell(0, 0, 0),
        "below the bottom wall clamps to the bottom cell"
    );
}

#[test]
fn cell_hash_params_are_checked() {
    let t = ValueType::Particles { n: 4, k: 3 };
    for (params, want) in [
        (
            r#"{"box": [1, 1], "cells": [2, 2, 2]}"#,
            "`box` and `cells` need 2 or 3 values each",
        ),
        (
            r#"{"box": [1, 1, 1], "cells": [2000, 2, 2], "order": "morton"}"#,
            "Morton order supports at most 1024",
        ),
        (
            r#"{"box": [1, 1, 1], "cells": [2.5, 2, 2]}"#,
            "whole numbers",
        ),
        (
            r#"{"box": [1, 1], "cells": [2, 2]}"#,
            "has 3 columns but the box has 2 axes",
        ),
    ] {
        let e = validation_error("cell_hash", params, &[("positions", t)]);
        assert!(e.contains(want), "{params}: {e}");
    }
}

#[test]
fn scatter_by_a_permutation_must_fill_its_output() {
    let e = validation_error(
        "scatter",
        r#"{"rows": 12, "permutation": true}"#,
        &[
            ("values", ValueType::Particles { n: 4, k: 2 }),
            ("index", ValueType::Indices { n: 4 }),
        ],
    );
    assert!(
        e.contains("with `permutation` the index must place every row"),
        "{e}"
    );
}

/// `invert_permutation` against its reference: out[perm[i]] = i for permutations of every
/// size (one past a workgroup's reach too); with indices that are no permutation, those
/// past the end are skipped and entries nothing points at hold u32::MAX.
#[test]
fn invert_permutation_inverts_a_sort_perm() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(61);
    for n in [0u32, 1, 7, 1000, 70_001] {
        let perm = permutation(&mut rng, n);
        let (g, r) = run_out("invert_permutation", "{}", &[("index", indices(&perm))]);
        let g = u32s(&g);
        assert_eq!(
            g.iter().map(|&v| v as f64).collect::<Vec<_>>(),
            r.data,
            "{n}"
        );
        for (i, &p) in perm.iter().enumerate() {
            assert_eq!(g[p as usize], i as u32, "{n}: perm[{i}] = {p}");
        }
    }
    let (g, r) = run_out(
        "invert_permutation",
        "{}",
        &[("index", indices(&[2, 9, u32::MAX, 0]))],
    );
    assert_eq!(
        u32s(&g).iter().map(|&v| v as f64).collect::<Vec<_>>(),
        r.data
    );
    assert_eq!(u32s(&g), vec![3, u32::MAX, 0, u32::MAX]);
}

/// `relabel` against its reference, word for word: the ids in the chosen columns of each
/// row renamed through the table, ids past the table (a u32::MAX sentinel, ids one past)
/// and the other columns kept; every column layout of the params.
#[test]
fn relabel_renames_the_ids_of_the_chosen_columns() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(67);
    for (rows, stride, params) in [
        (0u32, 1u32, "{}"),
        (1000, 1, "{}"),
        (500, 6, r#"{"stride": 6, "count": 3}"#),
        (333, 4, r#"{"stride": 4, "first": 1, "count": 2}"#),
        (333, 4, r#"{"stride": 4, "first": 2}"#),
        (70_001, 1, r#"{"permutation": true}"#),
    ] {
        let n = 1 + rows / 2;
        let words: Vec<u32> = (0..rows * stride)
            .map(|_| match rng.next_u64() % 8 {
                0 => u32::MAX,
                1 => n + (rng.next_u64() % 3) as u32,
                _ => (rng.next_u64() % n as u64) as u32,
            })
            .collect();
        let table: Vec<u32> = (0..n).map(|_| rng.next_u64() as u32).collect();
        let (g, r) = run_out(
            "relabel",
            params,
            &[("x", indices(&words)), ("table", indices(&table))],
        );
        let g = u32s(&g);
        assert_eq!(
            g.iter().map(|&v| v as f64).collect::<Vec<_>>(),
            r.data,
            "{rows} rows of {stride} words, {params}"
        );
        if params == r#"{"stride": 6, "count": 3}"# {
            for (w, (&got, &was)) in g.iter().zip(&words).enumerate() {
                let want = if w % 6 < 3 && was < n {
                    table[was as usize]
                } else {
                    was
                };
                assert_eq!(got, want, "word {w}");
            }
        }
    }
}

/// A mesh follows its points into a new order: the points gathered by a permutation
/// (a sort's perm) and the mesh's vertex ids relabelled through its inverse
/// (invert_permutation) make a valid mesh of the reordered points with the same
/// triangles in the same slots, and relabelled back through the permutation it is the
/// mesh given, word for word.
#[test]
fn a_mesh_relabelled_through_a_permutation_and_back_is_the_same_mesh() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(71);
    let (n, l) = (500u32, [24.0, 24.0]);
    let x = random_points(&mut rng, n as usize, &l);
    let mesh = periodic_delaunay(&x, l).unwrap();
    let perm = permutation(&mut rng, n);
    let (inverse, _) = run_out("invert_permutation", "{}", &[("index", indices(&perm))]);
    let params = r#"{"stride": 6, "count": 3, "permutation": true}"#;
    let (inside, _) = run_out(
        "relabel",
        params,
        &[("x", indices(&mesh)), ("table", inverse)],
    );
    let inside = u32s(&inside);
    let gathered: Vec<f64> = perm
        .iter()
        .flat_map(|&p| [x[2 * p as usize], x[2 * p as usize + 1]])
        .collect();
    let stats = check_torus_mesh(&inside, &gathered, l).unwrap();
    assert_eq!(stats.inverted, 0);
    for (t, (a, b)) in inside
        .chunks(MESH_WORDS)
        .zip(mesh.chunks(MESH_WORDS))
        .enumerate()
    {
        assert_eq!(&a[3..], &b[3..], "triangle {t}: the twin slots");
        for k in 0..3 {
            assert_eq!(perm[a[k] as usize], b[k], "triangle {t}, vertex {k}");
        }
    }
    let (back, _) = run_out(
        "relabel",
        params,
        &[("x", indices(&inside)), ("table", indices(&perm))],
    );
    assert_eq!(u32s(&back), mesh);
}

/// `relabel` names what its params and input cannot do.
#[test]
fn relabel_params_are_checked() {
    let words = |n| ValueType::Indices { n };
    let e = validation_error(
        "relabel",
        r#"{"stride": 6}"#,
        &[("x", words(10)), ("table", words(4))],
    );
    assert!(
        e.contains("has 10 words, not a whole number of rows"),
        "{e}"
    );
    let e = validation_error(
        "relabel",
        r#"{"stride": 4, "first": 3, "count": 2}"#,
        &[("x", words(8)), ("table", words(4))],
    );
    assert!(
        e.contains("columns 3 to 4 do not fit a row of 4 words"),
        "{e}"
    );
    let e = validation_error(
        "relabel",
        r#"{"stride": 4, "first": 4}"#,
        &[("x", words(8)), ("table", words(4))],
    );
    assert!(e.contains("`first` 4 must be below `stride` 4"), "{e}");
}
