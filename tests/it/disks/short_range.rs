//! The short-range law r/|r|^7 (S1, cut at 2.5 sigma) through the engine's 2-D cell list:
//! neighbour_sum with the pair kernel `nonreciprocal`, with and without a Verlet list (a
//! neighbour_list reaching cutoff + skin), against the f64 all-pairs sum of S1 eq. 2 and
//! against the all-pairs node `nonreciprocal_forces`; the node against its own f64
//! reference in the plane; the 2-D neighbour list entry by entry; refusals.

use std::collections::BTreeMap;

use mesoflow::nodes::disks::forces::forces_reference;
use mesoflow::value::HostArray;

use crate::util::disks::disk_positions;
use crate::util::{self, Rng, flat_particles, gpu};

const BOX: [f64; 2] = [24.0, 20.0];

/// N disks at least 0.9 apart (f32 values) and random non-reciprocal (alpha, mu) rows.
fn system(n: usize, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let mut rng = Rng::new(seed);
    let x: Vec<f64> = disk_positions(&mut rng, n, BOX, 0.9)
        .iter()
        .map(|&v| v as f32 as f64)
        .collect();
    let q: Vec<f64> = (0..2 * n)
        .map(|_| rng.uniform(-2.0, 2.0) as f32 as f64)
        .collect();
    (x, q)
}

/// Cell list, charges gathered into its order, the optional Verlet list, the sum,
/// scattered back; and the all-pairs node beside it.
fn graph(lanes: u32, verlet: Option<(f64, u32)>) -> String {
    let (list_node, list_in) = match verlet {
        Some((skin, width)) => (
            format!(
                r#"{{"id": "nl", "kind": "neighbour_list", "params": {{"box": [24, 20], "cells": [8, 7], "periodic": [1, 1], "cutoff": {}, "max_neighbours": {width}}},
     "inputs": {{"positions": "cl.positions", "cells": "cl.cells", "cell_start": "cl.cell_start", "cell_count": "cl.cell_count"}}}},"#,
                2.5 + skin
            ),
            r#", "list": "nl.list", "list_count": "nl.count""#,
        ),
        None => (String::new(), ""),
    };
    format!(
        r#"{{"mesoflow": 1,
  "inputs": {{"positions": {{"type": "particles", "rows": 300, "cols": 2}}, "charges": {{"type": "particles", "rows": 300, "cols": 2}}}},
  "nodes": [
    {{"id": "cl", "graph": "lib/cell_list_2d.json", "params": {{"box": [24, 20], "cells": [8, 7], "periodic": [1, 1]}}, "inputs": {{"positions": "inputs.positions"}}}},
    {{"id": "q", "kind": "gather", "inputs": {{"values": "inputs.charges", "index": "cl.order"}}}},
    {list_node}
    {{"id": "sum", "kind": "neighbour_sum", "params": {{"box": [24, 20], "cells": [8, 7], "periodic": [1, 1], "cutoff": 2.5, "kernel": "nonreciprocal", "law": "short", "lanes": {lanes}}},
     "inputs": {{"positions": "cl.positions", "values": "q.out", "cells": "cl.cells", "cell_start": "cl.cell_start", "cell_count": "cl.cell_count"{list_in}}}}},
    {{"id": "back", "kind": "scatter", "params": {{"permutation": true}}, "inputs": {{"values": "sum.out", "index": "cl.order"}}}},
    {{"id": "ap", "kind": "nonreciprocal_forces", "params": {{"law": "short", "cutoff": 2.5, "box": [24, 20]}}, "inputs": {{"positions": "inputs.positions", "charges": "inputs.charges"}}}}
  ],
  "outputs": {{"cells": "back.out", "all_pairs": "ap.forces"}}}}"#
    )
}

fn max_rel(got: &[f64], want: &[f64]) -> f64 {
    let scale = want.iter().fold(1e-30f64, |m, x| m.max(x.abs()));
    got.iter()
        .zip(want)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs() / scale))
}

/// Every traversal (one thread a particle, subgroup lanes, a Verlet list with a skin, a
/// list too short for some particles) gives the f64 sum of S1 eq. 2 within f32 round-off.
#[test]
fn short_range_forces_through_the_cell_list_match_all_pairs() {
    let Some(gpu) = gpu() else { return };
    let (x, q) = system(300, 7);
    let want = forces_reference(&x, &q, true, 2.5, BOX);
    let inputs = BTreeMap::from([
        ("positions".to_string(), flat_particles(&x, 2)),
        ("charges".to_string(), flat_particles(&q, 2)),
    ]);
    let dir = util::tmpdir("disks-short");
    for lanes in [1, 0] {
        for verlet in [None, Some((0.3, 64)), Some((0.3, 6))] {
            let what = format!("lanes {lanes}, verlet {verlet:?}");
            let g = util::load(&util::write_graph(&dir, "g.json", &graph(lanes, verlet)));
            let out = util::run_graph(&gpu, &g, &inputs, None, 1, true);
            let cells = out["cells"].data.to_f64();
            let all = out["all_pairs"].data.to_f64();
            // r^-7 forces, a few dozen terms per disk: a few f32 ulps of the largest.
            let err = max_rel(&cells, &want);
            assert!(err < 2e-5, "{what}: cell list vs f64 sum, {err:e}");
            let err = max_rel(&cells, &all);
            assert!(err < 2e-5, "{what}: cell list vs all pairs, {err:e}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The sorted arrays of the 2-D cell list, for the nodes alone.
fn sorted(x: &[f64], q: &[f64]) -> BTreeMap<String, HostArray> {
    let gpu = gpu().expect("checked by the caller");
    let dir = util::tmpdir("disks-cells");
    let json = r#"{"mesoflow": 1, "inputs": {"positions": {"type": "particles", "rows": 300, "cols": 2}, "charges": {"type": "particles", "rows": 300, "cols": 2}},
      "nodes": [{"id": "cl", "graph": "lib/cell_list_2d.json", "params": {"box": [24, 20], "cells": [8, 7], "periodic": [1, 1]}, "inputs": {"positions": "inputs.positions"}},
                {"id": "q", "kind": "gather", "inputs": {"values": "inputs.charges", "index": "cl.order"}}],
      "outputs": {"positions": "cl.positions", "values": "q.out", "cells": "cl.cells", "cell_start": "cl.cell_start", "cell_count": "cl.cell_count"}}"#;
    let g = util::load(&util::write_graph(&dir, "g.json", json));
    let inputs = BTreeMap::from([
        ("positions".to_string(), flat_particles(x, 2)),
        ("charges".to_string(), flat_particles(q, 2)),
    ]);
    let out = util::run_graph(&gpu, &g, &inputs, None, 1, true);
    let _ = std::fs::remove_dir_all(&dir);
    out
}

/// neighbour_sum (kernel nonreciprocal) and neighbour_list on 2-D positions against their
/// own f64 references: the sums within f32 round-off, the list entry by entry.
#[test]
fn planar_neighbour_nodes_match_their_references() {
    if gpu().is_none() {
        return;
    }
    let (x, q) = system(300, 9);
    let cl = sorted(&x, &q);
    let pick = |names: &[&'static str]| -> Vec<(&'static str, HostArray)> {
        names.iter().map(|&k| (k, cl[k].clone())).collect()
    };
    for law in ["short", "long"] {
        let params = format!(
            r#"{{"box": [24, 20], "cells": [8, 7], "periodic": [1, 1], "cutoff": 2.5, "kernel": "nonreciprocal", "law": "{law}", "lanes": 1}}"#
        );
        let (out, refs) = util::run_node_and_reference(
            "neighbour_sum",
            &params,
            &pick(&["positions", "values", "cells", "cell_start", "cell_count"]),
        );
        let err = max_rel(&out["out"].data.to_f64(), &refs[0].data);
        assert!(err < 2e-5, "law {law}: {err:e}");
    }
    let (out, refs) = util::run_node_and_reference(
        "neighbour_list",
        r#"{"box": [24, 20], "cells": [8, 7], "periodic": [1, 1], "cutoff": 2.8, "max_neighbours": 16}"#,
        &pick(&["positions", "cells", "cell_start", "cell_count"]),
    );
    assert_eq!(out["count"].data.to_f64(), refs[1].data, "counts");
    assert_eq!(out["list"].data.to_f64(), refs[0].data, "lists");
    assert!(refs[1].data.iter().any(|&c| c > 16.0), "a list overflows");
}

/// Mismatched axes and kernels are refused with the reason.
#[test]
fn planar_pair_setups_are_refused_with_reasons() {
    let try_build = |kind: &str, params: &str| {
        let k = util::registry().get(kind).unwrap();
        let raw: BTreeMap<String, serde_json::Value> = serde_json::from_str(params).unwrap();
        let raw = raw
            .into_iter()
            .map(|(n, v)| (n, mesoflow::expr::ParamValue::from_json(&v).unwrap()))
            .collect();
        let p = mesoflow::node::check_params(k.params(), &raw).unwrap();
        k.build(&p).err().unwrap_or_default()
    };
    // The default `periodic` has 3 entries: a plane must say its 2.
    let e = try_build(
        "neighbour_sum",
        r#"{"box": [24, 20], "cells": [8, 7], "cutoff": 2.5, "kernel": "nonreciprocal"}"#,
    );
    assert!(e.contains("one entry per axis, 2 (a plane) or 3"), "{e}");
    let e = try_build("all_pairs", r#"{"kernel": "nonreciprocal"}"#);
    assert!(e.contains("use nonreciprocal_forces"), "{e}");
    // 3-D positions for the plane's kernel: refused when typed.
    let e = util::validation_error(
        "neighbour_sum",
        r#"{"box": [24, 20, 20], "cells": [8, 7, 7], "cutoff": 2.5, "kernel": "nonreciprocal"}"#,
        &[
            (
                "positions",
                mesoflow::value::ValueType::Particles { n: 10, k: 3 },
            ),
            (
                "values",
                mesoflow::value::ValueType::Particles { n: 10, k: 2 },
            ),
            ("cells", mesoflow::value::ValueType::Indices { n: 10 }),
            ("cell_start", mesoflow::value::ValueType::Indices { n: 392 }),
            ("cell_count", mesoflow::value::ValueType::Indices { n: 392 }),
        ],
    );
    assert!(
        e.contains("kernel nonreciprocal takes positions of 2 (N x 2)"),
        "{e}"
    );
}
