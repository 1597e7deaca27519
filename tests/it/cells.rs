//! Gather, scatter, histograms and cell hashing against their references.

use mesoflow::value::{HostArray, ValueType};

use crate::util::{Rng, gpu, run_node_and_reference, single_node_graph, tmpdir, write_graph};

/// Runs a node and returns (GPU output, f64 reference) for output `out`.
fn run_node(kind: &str, params: &str, inputs: &[(&str, HostArray)]) -> (Vec<f64>, Vec<f64>) {
    let (out, mut refs) = run_node_and_reference(kind, params, inputs);
    (out["out"].data.to_f64(), refs.remove(0).data)
}

fn idx(v: Vec<u32>) -> HostArray {
    HostArray::u32(ValueType::Indices { n: v.len() as u32 }, v)
}

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
        let keys = idx((0..n).map(|_| rng.next_u64() as u32).collect());
        let perm = idx(permutation(&mut rng, n));
        for v in [&values, &keys] {
            let (g, r) = run_node(
                "gather",
                "{}",
                &[("values", v.clone()), ("index", perm.clone())],
            );
            assert_eq!(g, r, "gather {n}");
            let (g, r) = run_node(
                "scatter",
                "{}",
                &[("values", v.clone()), ("index", perm.clone())],
            );
            assert_eq!(g, r, "scatter {n}");
            let (g, r) = run_node(
                "scatter",
                r#"{"permutation": true}"#,
                &[("values", v.clone()), ("index", perm.clone())],
            );
            assert_eq!(g, r, "scatter by a permutation {n}");
        }
    }
    // Out-of-range indices: gather gives zeros, scatter skips; scatter into more rows.
    let values = rng.array(ValueType::Particles { n: 4, k: 2 }, 1.0, 2.0);
    let index = idx(vec![3, 9, u32::MAX, 0]);
    let (g, r) = run_node(
        "gather",
        "{}",
        &[("values", values.clone()), ("index", index.clone())],
    );
    assert_eq!(g, r);
    assert_eq!(&g[2..6], &[0.0; 4]);
    let (g, r) = run_node(
        "scatter",
        r#"{"rows": 12}"#,
        &[("values", values), ("index", index)],
    );
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
        let (g, r) = run_node(
            "histogram",
            &format!(r#"{{"bins": {bins}}}"#),
            &[("keys", idx(keys))],
        );
        assert_eq!(g, r, "histogram of {n} keys in {bins} bins");
    }
}

/// Compares cell keys, forgiving only particles that sit within f32 rounding of a cell
/// face (where f32 and f64 may legitimately pick different sides).
fn check_hash(params: &str, positions: &HostArray, box_len: &[f64], cells: &[u32]) {
    let (g, r) = run_node("cell_hash", params, &[("positions", positions.clone())]);
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
    let (g, r) = run_node("cell_hash", params, &[("positions", positions.clone())]);
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
    let (g, r) = run_node("cell_hash", walls, &[("positions", positions)]);
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
    let dir = tmpdir("hash-params");
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
        let path = write_graph(
            &dir,
            "g.json",
            &single_node_graph("cell_hash", params, &[("positions", t)]),
        );
        let e = mesoflow::plan::validate_file(crate::util::registry(), &path)
            .unwrap_err()
            .to_string();
        assert!(e.contains(want), "{params}: {e}");
    }
}

#[test]
fn scatter_by_a_permutation_must_fill_its_output() {
    let dir = tmpdir("scatter-params");
    let path = write_graph(
        &dir,
        "g.json",
        &single_node_graph(
            "scatter",
            r#"{"rows": 12, "permutation": true}"#,
            &[
                ("values", ValueType::Particles { n: 4, k: 2 }),
                ("index", ValueType::Indices { n: 4 }),
            ],
        ),
    );
    let e = mesoflow::plan::validate_file(crate::util::registry(), &path)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("with `permutation` the index must place every row"),
        "{e}"
    );
}
