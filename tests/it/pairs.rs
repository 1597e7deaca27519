//! Pairwise sums: `neighbour_sum` through the cell list of graphs/lib/cell_list.json and
//! `all_pairs`, against O(N^2) f64 sums over every pair (minimum image) written here;
//! pairs across periodic faces, a pair exactly at the cutoff, a particle without
//! neighbours, axes of fewer than 3 cells, open axes, coincident particles.

use std::collections::BTreeMap;
use std::f64::consts::PI;

use mesoflow::nodes::pairs::rpy::{NearTable, rpy};
use mesoflow::value::{HostArray, ValueType};

use crate::util::{self, Rng, flat_particles, gpu, random_points};

/// The pair contribution f64 twin written here, independent of the node's: RPY (with
/// overlap), the tabulated near field, or Lennard-Jones.
enum Pair {
    Rpy(f64),
    Near(NearTable),
    Lj(f64, f64),
}

impl Pair {
    fn term(&self, r: [f64; 3], v: [f64; 3]) -> [f64; 3] {
        let r2: f64 = r.iter().map(|x| x * x).sum();
        let d = r2.sqrt();
        let (f, g) = match self {
            Pair::Rpy(a) => rpy(d, *a, 1.0),
            Pair::Near(t) => t.at(d),
            Pair::Lj(eps, sigma) => {
                let s6 = (sigma * sigma / r2).powi(3);
                let c = 24.0 * eps * (2.0 * s6 * s6 - s6) / r2;
                return r.map(|x| c * x);
            }
        };
        let rv = if r2 > 0.0 {
            (0..3).map(|c| r[c] * v[c]).sum::<f64>() / r2
        } else {
            0.0
        };
        [0, 1, 2].map(|c| f * v[c] + g * rv * r[c])
    }

    fn self_term(&self, v: [f64; 3]) -> [f64; 3] {
        match self {
            Pair::Rpy(a) => v.map(|x| x / (6.0 * PI * a)),
            Pair::Near(t) => v.map(|x| x * t.f[0]),
            Pair::Lj(..) => [0.0; 3],
        }
    }
}

/// O(N^2) sum; `lengths` empty for open boundaries.
fn brute_force(
    pair: &Pair,
    pos: &[f64],
    vals: &[f64],
    lengths: &[f64],
    periodic: [bool; 3],
    cutoff: f64,
) -> Vec<f64> {
    let n = pos.len() / 3;
    let cut2 = (cutoff as f32 * cutoff as f32) as f64;
    let mut out = vec![0.0; 3 * n];
    for i in 0..n {
        let vi = [vals[3 * i], vals[3 * i + 1], vals[3 * i + 2]];
        let mut acc = pair.self_term(vi);
        for j in 0..n {
            if i == j {
                continue;
            }
            let mut r = [0.0; 3];
            for a in 0..3 {
                r[a] = pos[3 * i + a] - pos[3 * j + a];
                if !lengths.is_empty() && periodic[a] {
                    r[a] -= lengths[a] * (r[a] / lengths[a]).round();
                }
            }
            if r.iter().map(|x| x * x).sum::<f64>() <= cut2 {
                let t = pair.term(r, [vals[3 * j], vals[3 * j + 1], vals[3 * j + 2]]);
                for a in 0..3 {
                    acc[a] += t[a];
                }
            }
        }
        out[3 * i..3 * i + 3].copy_from_slice(&acc);
    }
    out
}

/// A graph: cell list, values gathered into its order, neighbour_sum (through a
/// neighbour list of `list` entries per particle when given), scattered back.
fn neighbour_graph(
    lengths: [f64; 3],
    cells: [u32; 3],
    periodic: [u32; 3],
    kernel_params: &str,
    with_values: bool,
    list: Option<u32>,
) -> String {
    let lib = std::path::Path::new("lib/cell_list.json");
    let values = if with_values {
        r#"{"id": "v", "kind": "gather", "inputs": {"values": "inputs.values", "index": "cl.order"}},"#
    } else {
        ""
    };
    let values_in = if with_values {
        r#""values": "v.out","#
    } else {
        ""
    };
    let values_decl = if with_values {
        r#", "values": {"type": "particles", "rows": "n", "cols": 3}"#
    } else {
        ""
    };
    let cutoff = kernel_params
        .split(',')
        .find_map(|kv| kv.trim().strip_prefix(r#""cutoff": "#))
        .unwrap_or("0");
    let (list_node, list_in) = match list {
        Some(width) => (
            format!(
                r#"{{"id": "nl", "kind": "neighbour_list", "params": {{"box": {lengths:?}, "cells": {cells:?}, "periodic": {periodic:?}, "cutoff": {cutoff}, "max_neighbours": {width}}},
     "inputs": {{"positions": "cl.positions", "cells": "cl.cells", "cell_start": "cl.cell_start", "cell_count": "cl.cell_count"}}}},"#
            ),
            r#", "list": "nl.list", "list_count": "nl.count""#,
        ),
        None => (String::new(), ""),
    };
    format!(
        r#"{{"mesoflow": 1,
  "sizes": {{"n": {{"default": 1}}}},
  "inputs": {{"positions": {{"type": "particles", "rows": "n", "cols": 3}}{values_decl}}},
  "nodes": [
    {{"id": "cl", "graph": "{}", "params": {{"box": {lengths:?}, "cells": {cells:?}, "periodic": {periodic:?}}}, "inputs": {{"positions": "inputs.positions"}}}},
    {values}
    {list_node}
    {{"id": "sum", "kind": "neighbour_sum", "params": {{"box": {lengths:?}, "cells": {cells:?}, "periodic": {periodic:?}, {kernel_params}}},
     "inputs": {{"positions": "cl.positions", {values_in} "cells": "cl.cells", "cell_start": "cl.cell_start", "cell_count": "cl.cell_count"{list_in}}}}},
    {{"id": "back", "kind": "scatter", "inputs": {{"values": "sum.out", "index": "cl.order"}}}}
  ],
  "outputs": {{"out": "back.out"}}}}"#,
        lib.display()
    )
}

/// Runs the neighbour graph (through a neighbour list of `list` entries per particle
/// when given) and checks it against the O(N^2) sum; returns the GPU sums.
#[allow(clippy::too_many_arguments)]
fn check_neighbours(
    what: &str,
    pos: &[f64],
    vals: Option<&[f64]>,
    lengths: [f64; 3],
    cells: [u32; 3],
    periodic: [u32; 3],
    kernel_params: &str,
    pair: &Pair,
    cutoff: f64,
    list: Option<u32>,
) -> Vec<f64> {
    let gpu = gpu().expect("checked by the caller");
    // Every traversal: one thread per particle, the default, and 4-lane segments where
    // the subgroups hold 4 lanes (lavapipe's hold 8, so auto takes 8 there).
    let mut lanes = vec![1, 0];
    if gpu.caps.subgroups.is_some_and(|(min, _)| min >= 4) {
        lanes.push(4);
    }
    let mut got = Vec::new();
    for lane in lanes {
        got = check_traversal(
            &format!("{what}, lanes {lane}"),
            &gpu,
            pos,
            vals,
            lengths,
            cells,
            periodic,
            &format!(r#"{kernel_params}, "lanes": {lane}"#),
            pair,
            cutoff,
            list,
        );
    }
    got
}

/// check_neighbours for one setting of the traversal.
#[allow(clippy::too_many_arguments)]
fn check_traversal(
    what: &str,
    gpu: &mesoflow::gpu::GpuContext,
    pos: &[f64],
    vals: Option<&[f64]>,
    lengths: [f64; 3],
    cells: [u32; 3],
    periodic: [u32; 3],
    kernel_params: &str,
    pair: &Pair,
    cutoff: f64,
    list: Option<u32>,
) -> Vec<f64> {
    let dir = util::tmpdir("pairs");
    let json = neighbour_graph(
        lengths,
        cells,
        periodic,
        kernel_params,
        vals.is_some(),
        list,
    );
    let g = util::load(&util::write_graph(&dir, "g.json", &json));
    // Positions pass through f32 on the GPU: the reference takes the same f32 values.
    let pos32 = flat_particles(pos, 3);
    let pos64 = pos32.data.to_f64();
    let mut inputs = BTreeMap::from([("positions".to_string(), pos32)]);
    let zeros = vec![0.0; pos.len()];
    let vals64 = match vals {
        Some(v) => {
            let a = flat_particles(v, 3);
            let v64 = a.data.to_f64();
            inputs.insert("values".into(), a);
            v64
        }
        None => zeros,
    };
    let out = util::run_graph(gpu, &g, &inputs, None, 1, true);
    let _ = std::fs::remove_dir_all(&dir);
    let got = out["out"].data.to_f64();
    let want = brute_force(
        pair,
        &pos64,
        &vals64,
        &lengths,
        periodic.map(|p| p == 1),
        cutoff,
    );
    let scale = want.iter().fold(1e-30f64, |m, x| m.max(x.abs()));
    let err = got
        .iter()
        .zip(&want)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs() / scale));
    // f32 sums of at most a few hundred terms of one sign pattern: 1e-5 of the largest.
    assert!(err < 1e-5, "{what}: error {err:e}");
    got
}

#[test]
fn neighbour_sums_match_every_pair() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(7);
    // Non-cubic box, overlapping pairs (r < 2a) and well-separated ones.
    let lengths = [10.0, 12.0, 14.5];
    let pos = random_points(&mut rng, 400, &lengths);
    let vals: Vec<f64> = (0..pos.len()).map(|_| rng.uniform(-1.0, 1.0)).collect();
    check_neighbours(
        "rpy, 3x4x4 cells",
        &pos,
        Some(&vals),
        lengths,
        [3, 4, 4],
        [1, 1, 1],
        r#""cutoff": 3.0, "kernel": "rpy", "radius": 0.8"#,
        &Pair::Rpy(0.8),
        3.0,
        None,
    );
    // Axes of 2 and 1 cells (the distinct neighbours only) and an open axis.
    check_neighbours(
        "rpy, 2x1x3 cells, open z",
        &pos,
        Some(&vals),
        lengths,
        [2, 1, 3],
        [1, 1, 0],
        r#""cutoff": 4.8, "kernel": "rpy", "radius": 0.8"#,
        &Pair::Rpy(0.8),
        4.8,
        None,
    );
    // Forces from positions alone (WCA: cutoff 2^(1/6) sigma), spaced out so forces
    // stay moderate.
    let sparse = random_points(&mut rng, 150, &lengths);
    let wca = 2f64.powf(1.0 / 6.0) * 0.5;
    check_neighbours(
        "wca",
        &sparse,
        None,
        lengths,
        [9, 10, 12],
        [1, 1, 1],
        &format!(r#""cutoff": {wca}, "kernel": "lj", "sigma": 0.5, "epsilon": 2.0"#),
        &Pair::Lj(2.0, 0.5),
        wca,
        None,
    );
}

#[test]
fn neighbour_sums_cross_faces_stop_at_the_cutoff_and_skip_loners() {
    if gpu().is_none() {
        return;
    }
    let lengths = [8.0, 8.0, 8.0];
    let pos = vec![
        // A pair across the x faces (0.2 apart through the face).
        -3.9, 0.0, 0.0, 3.9, 0.0, 0.0, // A pair across a corner.
        -3.95, -3.95, -3.95, 3.95, 3.95, 3.95,
        // A pair exactly at the cutoff (2), and one just past it.
        0.0, 2.0, 1.0, 2.0, 2.0, 1.0, //
        0.0, -2.0, 1.0, 2.0000005, -2.0, 1.0, // Alone.
        0.0, 0.0, -2.5, // Coincident particles.
        -1.5, -1.0, 3.0, -1.5, -1.0, 3.0,
    ];
    let vals: Vec<f64> = (0..pos.len()).map(|i| 1.0 + (i % 5) as f64).collect();
    let got = check_neighbours(
        "faces",
        &pos,
        Some(&vals),
        lengths,
        [4, 4, 4],
        [1, 1, 1],
        r#""cutoff": 2.0, "kernel": "rpy", "radius": 1.0"#,
        &Pair::Rpy(1.0),
        2.0,
        None,
    );
    // The loner gets its self term only: v / (6 pi).
    for c in 0..3 {
        let want = vals[24 + c] / (6.0 * PI);
        assert!((got[24 + c] - want).abs() < 1e-6 * want, "loner {c}");
    }
    // The pair at the cutoff couples; the one just past it does not.
    let alone = |i: usize, c: usize| vals[3 * i + c] / (6.0 * PI);
    assert!((got[12] - alone(4, 0)).abs() > 1e-3);
    assert!((got[18] - alone(6, 0)).abs() < 1e-6);
}

#[test]
fn neighbour_lists_give_the_same_sums_and_overflow_to_the_cells() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(13);
    let lengths = [10.0, 12.0, 14.5];
    let pos = random_points(&mut rng, 400, &lengths);
    let vals: Vec<f64> = (0..pos.len()).map(|_| rng.uniform(-1.0, 1.0)).collect();
    // About 3 neighbours per particle within 1.5: a list of 64 holds them all, a list
    // of 2 overflows for many particles (those walk the cells), 1 for most.
    for width in [64, 2, 1] {
        check_neighbours(
            &format!("list of {width}"),
            &pos,
            Some(&vals),
            lengths,
            [3, 4, 4],
            [1, 1, 0],
            r#""cutoff": 1.5, "kernel": "rpy", "radius": 0.8"#,
            &Pair::Rpy(0.8),
            1.5,
            Some(width),
        );
    }
}

#[test]
fn neighbour_list_matches_its_reference_entry_by_entry() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(17);
    let lengths = [9.0, 9.0, 9.0];
    let pos = flat_particles(&random_points(&mut rng, 300, &lengths), 3);
    // Sort by cell first (what the cell list does), then list from the node alone.
    let gpu = gpu().unwrap();
    let dir = util::tmpdir("pairs-list");
    let lib = std::path::Path::new("lib/cell_list.json");
    let json = format!(
        r#"{{"mesoflow": 1, "inputs": {{"positions": {{"type": "particles", "rows": 300, "cols": 3}}}},
          "nodes": [{{"id": "cl", "graph": "{}", "params": {{"box": [9, 9, 9], "cells": [3, 3, 3]}}, "inputs": {{"positions": "inputs.positions"}}}}],
          "outputs": {{"positions": "cl.positions", "cells": "cl.cells", "cell_start": "cl.cell_start", "cell_count": "cl.cell_count"}}}}"#,
        lib.display()
    );
    let g = util::load(&util::write_graph(&dir, "g.json", &json));
    let cl = util::run_graph(
        &gpu,
        &g,
        &BTreeMap::from([("positions".into(), pos)]),
        None,
        1,
        true,
    );
    drop(gpu);
    let _ = std::fs::remove_dir_all(&dir);
    let inputs: Vec<(&str, HostArray)> = ["positions", "cells", "cell_start", "cell_count"]
        .iter()
        .map(|&k| (k, cl[k].clone()))
        .collect();
    let (out, refs) = util::run_node_and_reference(
        "neighbour_list",
        r#"{"box": [9, 9, 9], "cells": [3, 3, 3], "cutoff": 2.5, "max_neighbours": 8}"#,
        &inputs,
    );
    assert_eq!(out["count"].data.to_f64(), refs[1].data, "counts");
    assert_eq!(out["list"].data.to_f64(), refs[0].data, "lists");
    assert!(
        refs[1].data.iter().any(|&c| c > 8.0),
        "some particle overflows the list"
    );
}

#[test]
fn near_field_table_sums_like_its_reference() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(11);
    let lengths = [16.0, 16.0, 16.0];
    let (xi, cutoff) = (0.6, 4.0);
    let pos = random_points(&mut rng, 300, &lengths);
    let vals: Vec<f64> = (0..pos.len()).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let table = NearTable::new(1.0, 1.0, xi, cutoff, 8192).unwrap();
    check_neighbours(
        "rpy_near",
        &pos,
        Some(&vals),
        lengths,
        [4, 4, 4],
        [1, 1, 1],
        &format!(r#""cutoff": {cutoff}, "kernel": "rpy_near", "split": {xi}"#),
        &Pair::Near(table),
        cutoff,
        None,
    );
}

fn all_pairs(params: &str, pos: &[f64], vals: Option<&[f64]>) -> Vec<f64> {
    let mut inputs = vec![("positions", flat_particles(pos, 3))];
    if let Some(v) = vals {
        inputs.push(("values", flat_particles(v, 3)));
    }
    let (out, _) = util::run_node_and_reference("all_pairs", params, &inputs);
    out["out"].data.to_f64()
}

#[test]
fn all_pairs_match_every_pair() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(3);
    // Sizes around the tile of 128: one particle, a partial tile, several tiles.
    for n in [1usize, 129, 300] {
        let pos = random_points(&mut rng, n, &[12.0, 6.0, 9.0]);
        let vals: Vec<f64> = (0..3 * n).map(|_| rng.uniform(-1.0, 1.0)).collect();
        let pos64 = flat_particles(&pos, 3).data.to_f64();
        let vals64 = flat_particles(&vals, 3).data.to_f64();
        let want = brute_force(&Pair::Rpy(0.7), &pos64, &vals64, &[], [false; 3], f64::MAX);
        let scale = want.iter().fold(1e-30f64, |m, x| m.max(x.abs()));
        // One run of j tiles (what small N gets), and the sums cut into runs added after.
        for params in [
            r#"{"kernel": "rpy", "radius": 0.7}"#,
            r#"{"kernel": "rpy", "radius": 0.7, "slices": 3}"#,
        ] {
            let got = all_pairs(params, &pos, Some(&vals));
            let err = got
                .iter()
                .zip(&want)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs() / scale));
            assert!(err < 2e-5, "all_pairs {params} n = {n}: {err:e}");
        }
        let got = all_pairs(
            r#"{"kernel": "lj", "sigma": 0.4, "cutoff": 1.0, "slices": 2}"#,
            &pos,
            None,
        );
        let want = brute_force(
            &Pair::Lj(1.0, 0.4),
            &pos64,
            &vec![0.0; 3 * n],
            &[],
            [false; 3],
            1.0,
        );
        let scale = want.iter().fold(1e-30f64, |m, x| m.max(x.abs()));
        let err = got
            .iter()
            .zip(&want)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs() / scale));
        assert!(err < 2e-5, "all_pairs lj n = {n}: {err:e}");
    }
}

#[test]
fn bad_pair_setups_are_refused_with_reasons() {
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
    let e = try_build(
        "neighbour_sum",
        r#"{"box": [8, 8, 8], "cells": [4, 4, 4], "cutoff": 3}"#,
    );
    assert!(e.contains("less than the cutoff 3"), "{e}");
    let e = try_build(
        "neighbour_sum",
        r#"{"box": [8, 8, 8], "cells": [1, 1, 1], "cutoff": 5}"#,
    );
    assert!(e.contains("exceeds half the periodic box"), "{e}");
    let e = try_build(
        "neighbour_sum",
        r#"{"box": [8, 8, 8], "cells": [2, 2, 2], "cutoff": 3, "kernel": "rpy_near"}"#,
    );
    assert!(e.contains("needs `split`"), "{e}");
    let e = try_build("all_pairs", r#"{"kernel": "rpy_near", "split": 1}"#);
    assert!(e.contains("use it in neighbour_sum"), "{e}");
    let e = try_build(
        "neighbour_sum",
        r#"{"box": [8, 8, 8], "cells": [2, 2, 2], "cutoff": 3, "lanes": 3}"#,
    );
    assert!(
        e.contains("`lanes` must be 0 (auto), 1 or a power of two up to 32, got 3"),
        "{e}"
    );
}

#[test]
fn lanes_wider_than_the_subgroups_are_a_compile_error_naming_the_node() {
    let Some(gpu) = gpu() else { return };
    let Some((min, _)) = gpu.caps.subgroups else {
        return;
    };
    if min >= 32 {
        return;
    }
    let dir = util::tmpdir("pairs-lanes");
    let json = neighbour_graph(
        [8.0, 8.0, 8.0],
        [2, 2, 2],
        [1, 1, 1],
        r#""cutoff": 1.0, "kernel": "lj", "sigma": 0.5, "epsilon": 1.0, "lanes": 32"#,
        false,
        None,
    );
    let g = util::load(&util::write_graph(&dir, "g.json", &json));
    let e = util::graph_compile_error(
        &gpu,
        &g,
        [("positions".to_string(), ValueType::Particles { n: 4, k: 3 })].into(),
    );
    let _ = std::fs::remove_dir_all(&dir);
    assert!(
        e.contains("sum") && e.contains("lanes = 32 needs subgroups of at least 32 lanes"),
        "{e}"
    );
}

/// The Lennard-Jones potential output (`outputs`: potential, both): per particle half of
/// each pair's energy 4 eps ((s/r)^12 - (s/r)^6), shifted to 0 at the cutoff, so the
/// particles' potentials add up to the total energy; `both` is (energy, force).
#[test]
fn lennard_jones_energies_add_up_to_the_total() {
    if gpu().is_none() {
        return;
    }
    let gpu = gpu().expect("checked");
    let lengths = [6.0, 6.0, 6.0];
    let (eps, sigma, cutoff): (f64, f64, f64) = (1.5, 0.6, 1.4);
    let mut rng = Rng::new(97);
    let pos = random_points(&mut rng, 60, &lengths);
    let pos32 = flat_particles(&pos, 3);
    let p = pos32.data.to_f64();
    let n = p.len() / 3;
    // f64 energies and forces of every pair within the cutoff (minimum image).
    let shift = 4.0 * eps * ((sigma / cutoff).powi(12) - (sigma / cutoff).powi(6));
    let mut energy = vec![0.0; n];
    let mut force = vec![[0.0; 3]; n];
    for i in 0..n {
        for j in 0..n {
            if i == j {
                continue;
            }
            let r: Vec<f64> = (0..3)
                .map(|a| {
                    let d = p[3 * i + a] - p[3 * j + a];
                    d - lengths[a] * (d / lengths[a]).round()
                })
                .collect();
            let r2: f64 = r.iter().map(|x| x * x).sum();
            if r2 > cutoff * cutoff {
                continue;
            }
            let s6 = (sigma * sigma / r2).powi(3);
            energy[i] += 0.5 * (4.0 * eps * (s6 * s6 - s6) - shift);
            for a in 0..3 {
                force[i][a] += 24.0 * eps * (2.0 * s6 * s6 - s6) / r2 * r[a];
            }
        }
    }
    for (outputs, cols) in [("potential", 1usize), ("both", 4)] {
        let dir = util::tmpdir("lj_energy");
        let json = neighbour_graph(
            lengths,
            [4, 4, 4],
            [1, 1, 1],
            &format!(
                r#""cutoff": {cutoff}, "kernel": "lj", "sigma": {sigma}, "epsilon": {eps}, "outputs": "{outputs}""#
            ),
            false,
            None,
        );
        let g = util::load(&util::write_graph(&dir, "g.json", &json));
        let inputs = BTreeMap::from([("positions".to_string(), pos32.clone())]);
        let out = util::run_graph(&gpu, &g, &inputs, None, 1, true);
        let _ = std::fs::remove_dir_all(&dir);
        let got = out["out"].data.to_f64();
        assert_eq!(got.len(), cols * n, "{outputs}");
        let scale_u = energy.iter().fold(1e-30f64, |m, x| m.max(x.abs()));
        let scale_f = force.iter().flatten().fold(1e-30f64, |m, x| m.max(x.abs()));
        for i in 0..n {
            let u = got[cols * i];
            assert!(
                (u - energy[i]).abs() <= 1e-5 * scale_u,
                "{outputs}: energy {i}: {u} vs {}",
                energy[i]
            );
            if cols == 4 {
                for a in 0..3 {
                    let f = got[cols * i + 1 + a];
                    assert!(
                        (f - force[i][a]).abs() <= 1e-5 * scale_f,
                        "force {i}.{a}: {f} vs {}",
                        force[i][a]
                    );
                }
            }
        }
        let total: f64 = got.iter().step_by(cols).sum();
        let want: f64 = energy.iter().sum();
        assert!(
            (total - want).abs() <= 1e-5 * scale_u * n as f64,
            "total {total} vs {want}"
        );
    }
}
