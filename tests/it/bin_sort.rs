//! `bin_sort` against its CPU reference (a stable counting sort) on the GPU. The GPU's
//! order inside a bin comes from atomics, so `keys`, `count` and `start` are compared
//! exactly, and `perm` must be a permutation that reorders the keys into `keys`; sorted
//! ascending inside each bin, it must equal the reference's (stable) permutation.

use std::collections::BTreeMap;

use mesoflow::gpu::GpuContext;
use mesoflow::value::{HostArray, ValueType};

use crate::util::{
    self, Rng, compile_error, gpu, indices, random_keys, reference, run_node, u32s, with_caps,
};

/// Checks the GPU outputs of bin_sort against the reference, forgiving only the order
/// inside a bin (and inside the overflow bin of keys >= bins).
fn compare(what: &str, keys: &[u32], bins: u32, got: &BTreeMap<String, HostArray>) {
    let params = format!(r#"{{"bins": {bins}}}"#);
    let want = reference("bin_sort", &params, &[Some(&indices(keys))]);
    let want: Vec<Vec<u32>> = want
        .iter()
        .map(|r| r.data.iter().map(|&x| x as u32).collect())
        .collect();
    let [want_perm, want_keys, want_count, want_start] = want.as_slice() else {
        panic!("bin_sort has four outputs");
    };
    for (port, w) in [("count", want_count), ("start", want_start)] {
        let g = u32s(&got[port]);
        assert_eq!(g.len(), bins as usize, "{what}: {port} length");
        if let Some(i) = (0..g.len()).find(|&i| g[i] != w[i]) {
            panic!("{what}: {port}[{i}] is {}, expected {}", g[i], w[i]);
        }
    }
    let n = keys.len();
    let (perm, sorted) = (u32s(&got["perm"]), u32s(&got["keys"]));
    assert_eq!((perm.len(), sorted.len()), (n, n), "{what}: lengths");
    // Keys inside the bins are their bin: equal to the reference slot by slot. Past them
    // (the overflow bin) any order.
    let total = want_count.iter().map(|&c| c as usize).sum::<usize>();
    if let Some(s) = (0..total).find(|&s| sorted[s] != want_keys[s]) {
        panic!(
            "{what}: keys[{s}] is {}, expected {}",
            sorted[s], want_keys[s]
        );
    }
    let mut tail = sorted[total..].to_vec();
    tail.sort_unstable();
    let mut want_tail = want_keys[total..].to_vec();
    want_tail.sort_unstable();
    assert_eq!(tail, want_tail, "{what}: the keys past the last bin");
    assert!(tail.iter().all(|&k| k >= bins), "{what}: overflow keys");
    // perm reorders the input into `keys`, and is a permutation.
    let mut seen = vec![false; n];
    for (s, &p) in perm.iter().enumerate() {
        assert!(
            (p as usize) < n && !seen[p as usize],
            "{what}: perm[{s}] = {p} is out of range or repeated"
        );
        seen[p as usize] = true;
        assert_eq!(keys[p as usize], sorted[s], "{what}: keys[perm[{s}]]");
    }
    // Inside each bin (and the overflow bin), sorted ascending: the stable reference.
    let mut canonical = perm.to_vec();
    let mut segments: Vec<(usize, usize)> = (0..bins as usize)
        .map(|b| {
            let s = want_start[b] as usize;
            (s, s + want_count[b] as usize)
        })
        .collect();
    segments.push((total, n));
    for (a, b) in segments {
        canonical[a..b].sort_unstable();
    }
    if let Some(s) = (0..n).find(|&s| canonical[s] != want_perm[s]) {
        panic!(
            "{what}: canonical perm[{s}] is {}, expected {}",
            canonical[s], want_perm[s]
        );
    }
}

fn check_on(gpu: &GpuContext, keys: &[u32], bins: u32, variant: &str) {
    let params = format!(r#"{{"bins": {bins}, "variant": "{variant}"}}"#);
    let inputs = [("keys".to_string(), indices(keys))].into();
    let got = run_node(gpu, "bin_sort", &params, &inputs);
    let what = format!(
        "bin_sort ({variant}) of {} keys into {bins} bins",
        keys.len()
    );
    compare(&what, keys, bins, &got);
}

/// The variants this device runs: `auto` and `portable`, and `subgroup` where it fits.
fn variants(gpu: &GpuContext) -> Vec<&'static str> {
    let mut v = vec!["auto", "portable"];
    if gpu
        .caps
        .subgroups
        .is_some_and(|s| mesoflow::nodes::scan::subgroup_scan_fits(s).is_ok())
    {
        v.push("subgroup");
    }
    v
}

#[test]
fn random_keys_in_few_and_many_bins() {
    let Some(gpu) = gpu() else { return };
    let cases: &[(usize, u32)] = &[
        (0, 1),
        (0, 100),
        (1, 1),
        (1, 7),
        (2, 1),
        (100, 1),
        (1000, 17),
        (5000, 1000),
        (3000, 4095),
        (3000, 4096),
        (3000, 4097),
        (20_000, 512),
        (50_000, 32_768),
    ];
    for variant in variants(&gpu) {
        for (i, &(n, bins)) in cases.iter().enumerate() {
            check_on(&gpu, &random_keys(n, bins as u64, i as u64), bins, variant);
        }
    }
}

#[test]
fn keys_past_the_last_bin_sort_after_every_bin() {
    let Some(gpu) = gpu() else { return };
    for variant in variants(&gpu) {
        // Half of the keys past the bins, and the extremes.
        let mut keys = random_keys(4000, 200, 1);
        keys[0] = u32::MAX;
        keys[1] = 100;
        keys[2] = 0;
        check_on(&gpu, &keys, 100, variant);
        // Every key past the bins; a single key past them; one bin.
        check_on(&gpu, &[5, 9, 5, u32::MAX], 3, variant);
        check_on(&gpu, &[3], 1, variant);
        check_on(&gpu, &random_keys(1000, 3, 2), 1, variant);
    }
}

#[test]
fn many_keys_in_one_bin() {
    let Some(gpu) = gpu() else { return };
    for variant in variants(&gpu) {
        check_on(&gpu, &vec![7; 20_000], 16, variant);
        check_on(&gpu, &vec![0; 5000], 1, variant);
        // Long runs in a few bins, bins left empty between them.
        let few: Vec<u32> = random_keys(30_000, 5, 3).iter().map(|k| 100 * k).collect();
        check_on(&gpu, &few, 401, variant);
    }
}

#[test]
fn more_bins_than_one_workgroup_scans_take_the_general_scan() {
    let Some(mut gpu) = gpu() else { return };
    // 40000 and 100000 bins: past the one-workgroup scan on any device (25 tiles of the
    // general scan for the latter); keys past the bins too.
    for variant in variants(&gpu) {
        check_on(&gpu, &random_keys(3000, 41_000, 4), 40_000, variant);
        check_on(&gpu, &random_keys(20_000, 100_000, 5), 100_000, variant);
        check_on(&gpu, &[], 40_000, variant);
    }
    // Workgroups of 256 threads: the one-workgroup scan ends at 8192 bins.
    let threads_256 = |c: &mut mesoflow::gpu::DeviceCaps| c.max_invocations = 256;
    with_caps(&mut gpu, threads_256, |gpu| {
        for variant in variants(gpu) {
            check_on(gpu, &random_keys(5000, 8192, 6), 8192, variant);
            check_on(gpu, &random_keys(5000, 8200, 7), 8193, variant);
            check_on(gpu, &random_keys(100, 3, 8), 1, variant);
        }
    });
}

#[test]
fn sorts_fold_their_dispatches_past_the_workgroup_cap() {
    let Some(mut gpu) = gpu() else { return };
    // 2000 keys on 3 workgroups per dimension: grids of 8 groups fold over (x, y).
    let keys = random_keys(2000, 300, 9);
    with_caps(
        &mut gpu,
        |c| c.max_workgroups_per_dim = 3,
        |gpu| {
            check_on(gpu, &keys, 250, "auto");
            check_on(gpu, &keys, 10_000, "auto");
        },
    );
}

#[test]
fn auto_runs_without_subgroups_and_subgroup_fails_clearly() {
    let Some(mut gpu) = gpu() else { return };
    let keys = random_keys(3000, 600, 10);
    with_caps(
        &mut gpu,
        |c| c.subgroups = None,
        |gpu| {
            check_on(gpu, &keys, 500, "auto");
            check_on(gpu, &keys, 40_000, "auto");
            let inputs = [("keys".to_string(), indices(&keys))].into();
            let err = compile_error(
                gpu,
                "bin_sort",
                r#"{"bins": 500, "variant": "subgroup"}"#,
                &inputs,
            );
            assert!(
                err.contains("bin_sort variant `subgroup` cannot run")
                    && err.contains("no subgroup operations"),
                "{err}"
            );
        },
    );
}

/// A bad test must fail: a GPU result with two slots swapped across bins, a wrong
/// count, or a repeated index is caught by `compare`.
#[test]
fn the_comparison_catches_wrong_results() {
    let Some(gpu) = gpu() else { return };
    let keys = random_keys(500, 20, 11);
    let params = r#"{"bins": 20}"#;
    let inputs = [("keys".to_string(), indices(&keys))].into();
    let good = run_node(&gpu, "bin_sort", params, &inputs);
    drop(gpu);
    compare("good", &keys, 20, &good);
    let edit = |port: &str, f: &dyn Fn(&mut Vec<u32>)| {
        let mut bad = good.clone();
        let mut v = u32s(&bad[port]);
        f(&mut v);
        let ty = bad[port].ty;
        bad.insert(port.into(), HostArray::u32(ty, v));
        std::panic::catch_unwind(|| compare("bad", &keys, 20, &bad)).is_err()
    };
    assert!(edit("perm", &|p| p.swap(0, 499)), "perm across bins");
    assert!(edit("perm", &|p| p[1] = p[0]), "repeated index");
    assert!(edit("keys", &|k| k.swap(0, 499)), "keys out of order");
    assert!(edit("count", &|c| c[3] += 1), "count");
    assert!(edit("start", &|s| s[19] -= 1), "start");
}

#[test]
fn bad_bins_get_clear_errors() {
    let t = ValueType::Indices { n: 4 };
    for (params, want) in [
        (r#"{"bins": 0}"#, "bins"),
        (r#"{"bins": 2.5}"#, "not an integer"),
        (r#"{"bins": 4294967295}"#, "outside [1, 4294967294]"),
        (r#"{}"#, "missing required param"),
        (
            r#"{"bins": 4, "variant": "fast"}"#,
            "not one of auto, subgroup, portable",
        ),
    ] {
        let e = util::validation_error("bin_sort", params, &[("keys", t)]);
        assert!(e.contains(want), "{params}: {e}");
        if params.contains("bins") && !params.contains("variant") {
            assert!(
                e.contains("bins"),
                "{params}: the error names the param: {e}"
            );
        }
    }
}

/// The cell list of graphs/lib/cell_list.json: hash, bin_sort (fill, count, scan,
/// place), gather, and the clock tick (13 dispatches with sort + histogram + scan); its
/// outputs are a bin_sort of the GPU's cell hashes (from a second cell_hash node, which
/// computes the same f32 keys).
#[test]
fn the_cell_list_takes_seven_dispatches() {
    let Some(gpu) = gpu() else { return };
    let mut rng = Rng::new(12);
    let n = 3000u32;
    let pos: Vec<f32> = (0..3 * n).map(|_| rng.uniform(-8.0, 8.0) as f32).collect();
    let positions = HostArray::f32(ValueType::Particles { n, k: 3 }, pos);
    let dir = util::tmpdir("bin-sort-cell-list");
    let graph = |with_hash: bool| {
        let (node, output) = if with_hash {
            (
                r#", {"id": "hash", "kind": "cell_hash", "params": {"box": [16, 16, 16], "cells": [5, 6, 7]}, "inputs": {"positions": "inputs.positions"}}"#,
                r#", "hash": "hash.out""#,
            )
        } else {
            ("", "")
        };
        let json = format!(
            r#"{{"mesoflow": 1, "inputs": {{"positions": {{"type": "particles", "rows": {n}, "cols": 3}}}},
              "nodes": [{{"id": "cl", "graph": "{}", "params": {{"box": [16, 16, 16], "cells": [5, 6, 7]}}, "inputs": {{"positions": "inputs.positions"}}}}{node}],
              "outputs": {{"positions": "cl.positions", "cells": "cl.cells", "cell_start": "cl.cell_start", "cell_count": "cl.cell_count", "order": "cl.order"{output}}}}}"#,
            std::path::Path::new("lib/cell_list.json").display()
        );
        util::load(&util::write_graph(
            &dir,
            &format!("g{with_hash}.json"),
            &json,
        ))
    };
    let inputs: BTreeMap<String, HostArray> = [("positions".to_string(), positions)].into();
    let g = graph(false);
    let p = util::plan_graph(&gpu.caps, &g, util::types_of(&inputs), None, true);
    let mut cache = mesoflow::gpu::KernelCache::default();
    let program = mesoflow::exec::Program::compile(&gpu, &g, &p, &mut cache).unwrap();
    assert_eq!(program.dispatches_per_step(), 7);
    drop(program);
    let out = util::run_graph(&gpu, &graph(true), &inputs, None, 1, true);
    drop(gpu);
    let _ = std::fs::remove_dir_all(&dir);
    let keys = u32s(&out["hash"]);
    let renamed: BTreeMap<String, HostArray> = [
        ("perm", "order"),
        ("keys", "cells"),
        ("count", "cell_count"),
        ("start", "cell_start"),
    ]
    .into_iter()
    .map(|(port, name)| (port.to_string(), out[name].clone()))
    .collect();
    compare("cell list", &keys, 210, &renamed);
    // The positions follow the order.
    let (x, sorted, order) = (
        inputs["positions"].data.to_f64(),
        out["positions"].data.to_f64(),
        u32s(&out["order"]),
    );
    for (s, &i) in order.iter().enumerate() {
        let i = i as usize;
        assert_eq!(&sorted[3 * s..3 * s + 3], &x[3 * i..3 * i + 3], "row {s}");
    }
}
