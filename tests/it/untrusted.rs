//! Graph files and `--set` values from other people (issue 19): every size, count and
//! nesting they can reach is bounded on the host, with the limit named in the error,
//! before anything is built; nothing panics, overflows the stack or runs without end.

use std::path::{Path, PathBuf};

use mesoflow::expr::{Scope, evaluate};

use crate::util::{load_error, registry, tmpdir, write_graph};

/// The report of loading a graph file, which must fail.
fn load_file_error(path: &Path) -> String {
    match mesoflow::graph::load(path, registry(), &Default::default()) {
        Ok(_) => panic!("{} loaded", path.display()),
        Err(e) => e.to_string(),
    }
}

/// Host planners called from expressions with hostile sizes: an error naming the
/// limit, never a panic (before: `no friendly FFT size >= 4294967295 fits in a u32`
/// from `box=[1e30,1e30,1e30]` or a radius of 5e-324).
#[test]
fn planners_refuse_hostile_sizes_naming_the_limit() {
    let scope = Scope::new(registry().functions());
    for (text, wanted) in [
        (
            "fcm_grid([1e30, 1e30, 1e30], 1, 1e-3, 'gaussian')",
            "MAX_LENGTH",
        ),
        (
            "fcm_grid([8, 8, 8], 5e-324, 1e-3, 'gaussian')",
            "MAX_LENGTH",
        ),
        ("fcm_grid([8, 8, 8], 5e-324, 1e-3, 'es')", "MAX_LENGTH"),
        (
            "fcm_grid([2000, 2000, 2000], 0.5, 1e-3, 'peskin3')",
            "MAX_GRID_CELLS",
        ),
        ("pse_grid([1e30, 1e30, 1e30], 0.5, 1e-3)", "MAX_LENGTH"),
        (
            "pse_width(1, 0.5, 1e-3, [8, 8, 8], [1e30, 1e30, 1e30])",
            "MAX_LENGTH",
        ),
        ("fcm_sort_bins([0, 0, 0])", "MAX_LENGTH"),
        ("fcm_support(0, 'es', 1, [8, 8, 8], [8, 8, 8])", "tolerance"),
    ] {
        let got = std::panic::catch_unwind(|| evaluate(text, &scope));
        match got {
            Ok(Err(e)) => assert!(e.to_string().contains(wanted), "{text}: {e}"),
            other => panic!("{text} gave {other:?}, not an error"),
        }
    }
}

/// `--set box=[1e30,1e30,1e30]` on the shipped FCM graph is a load error naming the
/// limit (before: a panic of the FFT size search).
#[test]
fn a_huge_box_is_a_load_error() {
    let e = load_error("fcm.json", &[("box", "[1e30, 1e30, 1e30]")]);
    assert!(e.contains("MAX_LENGTH"), "{e}");
}

/// `--set split=1e6` on PSE: its near-field quadrature would need 3e7 panels (before:
/// the host planner ran for minutes and allocated gigabytes); now an error at once.
#[test]
fn a_huge_split_is_a_load_error_not_a_hang() {
    let e = load_error("pse.json", &[("split", "1e6")]);
    assert!(e.contains("MAX_FAR_PANELS"), "{e}");
}

/// Expressions nested 100,000 deep in a graph file are an error naming the limit
/// (before: a stack overflow, SIGABRT).
#[test]
fn deeply_nested_expressions_are_an_error() {
    let dir = tmpdir("untrusted-nesting");
    let deep = 100_000;
    let expr = format!("= {}1{}", "(".repeat(deep), ")".repeat(deep));
    let json = crate::util::chain_graph(1).replace("1.0001", &format!("\"{expr}\""));
    let e = load_file_error(&write_graph(&dir, "deep.json", &json));
    assert!(e.contains("MAX_EXPR_NESTING"), "{e}");
}

/// A chain of 2,000 element-wise nodes fuses into runs of at most MAX_FUSED_NODES
/// (before: one kernel of 2,000 members, minutes to compile), every node in one run.
#[test]
fn long_element_wise_chains_fuse_in_bounded_groups() {
    use mesoflow::plan::{Launch, MAX_FUSED_NODES};
    let dir = tmpdir("untrusted-fuse");
    let n = 2_000;
    let g = crate::util::load(&write_graph(
        &dir,
        "chain.json",
        &crate::util::chain_graph(n),
    ));
    let caps = mesoflow::gpu::DeviceCaps::baseline();
    let p = crate::util::plan_graph(&caps, &g, g.declared_input_types(), None, true);
    let sizes: Vec<usize> = p
        .step
        .iter()
        .map(|l| match l {
            Launch::Fused(k) => k.nodes.len(),
            _ => panic!("expected fused launches only"),
        })
        .collect();
    assert!(sizes.iter().all(|&s| s <= MAX_FUSED_NODES), "{sizes:?}");
    assert_eq!(sizes.iter().sum::<usize>(), n);
    assert_eq!(sizes.len(), n.div_ceil(MAX_FUSED_NODES), "{sizes:?}");
}

/// A chain of MAX_EXPANDED_NODES element-wise nodes in one file loads and plans on a
/// test thread's 2 MiB stack (before: the loader's cycle search recursed once per node
/// and overflowed the stack at about 10,000).
#[test]
fn the_longest_chain_a_file_may_have_loads_and_plans() {
    let dir = tmpdir("untrusted-long-chain");
    let n = mesoflow::graph::MAX_EXPANDED_NODES;
    let g = crate::util::load(&write_graph(
        &dir,
        "chain.json",
        &crate::util::chain_graph(n),
    ));
    let caps = mesoflow::gpu::DeviceCaps::baseline();
    let p = crate::util::plan_graph(&caps, &g, g.declared_input_types(), None, true);
    assert_eq!(p.step.len(), n.div_ceil(mesoflow::plan::MAX_FUSED_NODES));
}

/// A file `f{level}.json` that uses `next` once or twice in sequence (x -> a -> b -> y),
/// or is one scale node where `next` is none.
fn include_file(dir: &Path, level: usize, next: Option<&str>, twice: bool) -> PathBuf {
    let body = match next {
        None => r#"{"id": "s", "kind": "scale", "params": {"factor": 2}, "inputs": {"x": "inputs.x"}}], "outputs": {"y": "s.out"}"#.to_string(),
        Some(n) if twice => format!(
            r#"{{"id": "a", "graph": "{n}", "inputs": {{"x": "inputs.x"}}}}, {{"id": "b", "graph": "{n}", "inputs": {{"x": "a.y"}}}}], "outputs": {{"y": "b.y"}}"#
        ),
        Some(n) => format!(
            r#"{{"id": "a", "graph": "{n}", "inputs": {{"x": "inputs.x"}}}}], "outputs": {{"y": "a.y"}}"#
        ),
    };
    let json = format!(
        r#"{{"mesoflow": 1, "inputs": {{"x": {{"type": "particles", "cols": 1}}}}, "nodes": [{body}}}"#
    );
    write_graph(dir, &format!("f{level}.json"), &json)
}

/// Files f0.json to f{levels - 1}.json, each including the next (twice with `twice`).
fn include_chain(dir: &Path, levels: usize, twice: bool) {
    for level in 0..levels {
        let next = format!("f{}.json", level + 1);
        include_file(
            dir,
            level,
            (level + 1 < levels).then_some(next.as_str()),
            twice,
        );
    }
}

/// A chain of 2,000 files each including the next is an error naming the depth limit
/// (before: a stack overflow of the loader, SIGABRT, at 20,000); 30 levels still load.
#[test]
fn include_chains_are_bounded_in_depth() {
    let dir = tmpdir("untrusted-chain");
    let levels = 2_000;
    include_chain(&dir, levels, false);
    let e = load_file_error(&dir.join("f0.json"));
    assert!(e.contains("MAX_SUBGRAPH_DEPTH"), "{e}");
    mesoflow::graph::load(
        &dir.join(format!("f{}.json", levels - 30)),
        registry(),
        &Default::default(),
    )
    .unwrap_or_else(|e| panic!("30 levels: {e}"));
}

/// A file that includes itself is a cycle error.
#[test]
fn a_file_including_itself_is_an_error() {
    let dir = tmpdir("untrusted-self");
    let e = load_file_error(&include_file(&dir, 0, Some("f0.json"), false));
    assert!(e.contains("subgraph cycle"), "{e}");
}

/// 17 small files each using the next twice expand to 2^16 copies of the last (2^22
/// with 23 files exhausted memory before): an error naming the node budget, reached
/// after loading about MAX_EXPANDED_NODES nodes, not all of them.
#[test]
fn exponential_include_fan_out_is_bounded() {
    let dir = tmpdir("untrusted-fan-out");
    let levels = 17;
    include_chain(&dir, levels, true);
    let e = load_file_error(&dir.join("f0.json"));
    assert!(e.contains("MAX_EXPANDED_NODES"), "{e}");
    assert_eq!(
        e.matches("MAX_EXPANDED_NODES").count(),
        1,
        "reported once: {e}"
    );
}

/// `neighbour_sum` with cell arrays, keys and neighbour lists a graph wired from its own
/// inputs (any values): every traversal stays within the particles and finishes (before:
/// cell_count u32::MAX walked 4e9 slots past the positions, keys past the cells indexed
/// outside cell_start). Valid cell lists are unchanged by the clamps (tests/it/pairs.rs).
#[test]
fn neighbour_sums_survive_any_cell_list() {
    use crate::util::{flat_particles, gpu, indices, named, run_node};
    let Some(gpu) = gpu() else { return };
    let n = 8;
    let pos: Vec<f64> = (0..3 * n).map(|i| (i as f64 * 0.37) % 4.0 - 2.0).collect();
    let vals: Vec<f64> = (0..3 * n).map(|i| 1.0 + i as f64 * 0.1).collect();
    let big = u32::MAX;
    let keys = [big, 0, 5, 7, 1 << 30, 3, big - 1, 2];
    let starts = [0, 0, big, 3_000_000_000, 7, 8, 0, big - 3];
    let counts = [big, 5, big, 5, big, 0, 1 << 31, 9];
    let mut lanes = vec![1, 0];
    if gpu.caps.subgroups.is_none() {
        lanes.pop();
    }
    for lane in lanes {
        for with_list in [false, true] {
            let mut inputs = vec![
                ("positions", flat_particles(&pos, 3)),
                ("values", flat_particles(&vals, 3)),
                ("cells", indices(&keys)),
                ("cell_start", indices(&starts)),
                ("cell_count", indices(&counts)),
            ];
            if with_list {
                // Four entries per particle, all past the particles; counts within them.
                inputs.push(("list", indices(&[big; 4 * 8])));
                inputs.push(("list_count", indices(&[0, 1, 2, 3, 4, 4, 2, 1])));
            }
            let params = format!(
                r#"{{"box": [4, 4, 4], "cells": [2, 2, 2], "periodic": [1, 1, 1], "kernel": "rpy", "radius": 0.5, "cutoff": 1.5, "lanes": {lane}}}"#
            );
            let out = run_node(&gpu, "neighbour_sum", &params, &named(&inputs));
            let got = out["out"].data.to_f64();
            assert_eq!(got.len(), 3 * n);
            assert!(
                got.iter().all(|x| x.is_finite()),
                "lanes {lane}, list {with_list}: {got:?}"
            );
        }
    }
}

/// Hostile cell arrays and lists mean what the port docs of `neighbour_sum` say: a key past
/// the cells is the last cell, a cell's slots are cut to the particles (first = min(start,
/// N), count = min(count, N - first)), a list entry past the particles is the last
/// particle. So they give exactly the sums of those clamped arrays, written out on the
/// host. The Lennard-Jones kernel reads positions only, and particles sit within its
/// cutoff of the origin: a slot or entry read past the particles (zeros under lavapipe's
/// robust access, a phantom particle at the origin) or a key taken modulo the cells changes
/// the sums, so without the clamps of shaders/pairs/*.wgsl this fails (the test above only
/// checks that the sums stay finite, which zeros from out-of-range reads also give).
#[test]
fn hostile_cell_lists_sum_like_their_clamped_equivalents() {
    use crate::util::{flat_particles, gpu, indices, named, run_node};
    let Some(gpu) = gpu() else { return };
    let n = 8u32;
    // Pairs 0.9 apart (inside the WCA cutoff 1.12), and every particle within 1.12 of the
    // origin, none on it.
    let pos: Vec<f64> = (0..n)
        .flat_map(|i| {
            let a = i as f64 * 0.785;
            [
                0.6 * a.cos(),
                0.6 * a.sin(),
                if i % 2 == 0 { 0.3 } else { -0.3 },
            ]
        })
        .collect();
    let vals = vec![1.0; 3 * n as usize];
    // 4 x 4 x 4 cells of width 2: a cell's 27 neighbours are not all cells, so a key taken
    // modulo the grid (1 << 30: cell 0, z = 2^26; 100: z = 6) visits other cells than the
    // last one (63).
    let ncells = 64u32;
    let keys = [u32::MAX, 0, 5, 63, 1 << 30, 3, 100, 2];
    // Slots past the particles and across their end.
    let starts: Vec<u32> = (0..ncells)
        .map(|c| [0, 6, 10, 3_000_000_000, 7, 8, 0, 2][c as usize % 8])
        .collect();
    let counts: Vec<u32> = (0..ncells)
        .map(|c| [3, 5, 3, 5, 4, 0, 2, 9][c as usize % 8])
        .collect();
    let clamped_keys: Vec<u32> = keys.iter().map(|&k| k.min(ncells - 1)).collect();
    let clamped_starts: Vec<u32> = starts.iter().map(|&s| s.min(n)).collect();
    let clamped_counts: Vec<u32> = counts
        .iter()
        .zip(&clamped_starts)
        .map(|(&c, &s)| c.min(n - s))
        .collect();
    // Four entries per particle (list[k n + i]), never i itself (no pair at r = 0), some
    // past the particles (not for the last particle, which they mean).
    let list: Vec<u32> = (0..4 * n)
        .map(|e| {
            let (k, i) = (e / n, e % n);
            if (k + i) % 2 == 0 && i != n - 1 {
                100 + e
            } else {
                (i + 1 + k) % n
            }
        })
        .collect();
    let clamped_list: Vec<u32> = list.iter().map(|&j| j.min(n - 1)).collect();
    let list_count = [0, 1, 2, 3, 4, 4, 2, 1];
    let mut lanes = vec![1, 0];
    if gpu.caps.subgroups.is_none() {
        lanes.pop();
    }
    for lane in lanes {
        for with_list in [false, true] {
            let sums = |keys: &[u32], starts: &[u32], counts: &[u32], list: &[u32]| {
                let mut inputs = vec![
                    ("positions", flat_particles(&pos, 3)),
                    ("values", flat_particles(&vals, 3)),
                    ("cells", indices(keys)),
                    ("cell_start", indices(starts)),
                    ("cell_count", indices(counts)),
                ];
                if with_list {
                    inputs.push(("list", indices(list)));
                    inputs.push(("list_count", indices(&list_count)));
                }
                let params = format!(
                    r#"{{"box": [8, 8, 8], "cells": [4, 4, 4], "periodic": [1, 1, 1], "kernel": "lj", "sigma": 0.8, "cutoff": 1.5, "lanes": {lane}}}"#
                );
                run_node(&gpu, "neighbour_sum", &params, &named(&inputs))["out"]
                    .data
                    .to_f64()
            };
            let hostile = sums(&keys, &starts, &counts, &list);
            let clamped = sums(
                &clamped_keys,
                &clamped_starts,
                &clamped_counts,
                &clamped_list,
            );
            assert!(
                clamped.iter().any(|x| *x != 0.0),
                "lanes {lane}, list {with_list}: the clamped arrays find no pairs"
            );
            assert_eq!(hostile, clamped, "lanes {lane}, list {with_list}");
        }
    }
}

/// A plan whose buffers exceed what the adapter allows (planned for other limits, as
/// `validate` plans) fails in `Program::compile` with the limit named, before any
/// buffer is created (before: wgpu's `create_buffer` validation panicked).
#[test]
fn buffers_past_the_adapter_limits_fail_before_allocating() {
    use std::collections::BTreeMap;

    use mesoflow::exec::Program;
    use mesoflow::gpu::{DeviceCaps, KernelCache};
    use mesoflow::value::ValueType;

    let Some(gpu) = crate::util::gpu() else {
        return;
    };
    let limit = gpu.caps.max_buffer.min(gpu.caps.max_binding);
    // One 4-byte word past the limit, in rows of k columns that fit a u32 count.
    let words = limit / 4 + 1;
    let k = (words / u32::MAX as u64 + 1) as u32;
    let n = words.div_ceil(k as u64) as u32;
    let dir = tmpdir("untrusted-memory");
    let g = crate::util::load(&write_graph(
        &dir,
        "chain.json",
        &crate::util::chain_graph(1),
    ));
    let unlimited = DeviceCaps {
        max_binding: u64::MAX,
        max_buffer: u64::MAX,
        ..gpu.caps.clone()
    };
    let inputs = BTreeMap::from([("x".to_string(), ValueType::Particles { n, k })]);
    let p = crate::util::plan_graph(&unlimited, &g, inputs, None, true);
    match Program::compile(&gpu, &g, &p, &mut KernelCache::default()) {
        Ok(_) => panic!(
            "a buffer of {} bytes was allocated",
            4 * n as u64 * k as u64
        ),
        Err(e) => {
            let e = e.to_string();
            assert!(
                e.contains("input `x`") && e.contains("nothing was allocated"),
                "{e}"
            );
        }
    }
}

/// A graph of one subgraph node using `path`.
fn including(dir: &Path, name: &str, path: &str) -> PathBuf {
    let json = format!(
        r#"{{"mesoflow": 1, "inputs": {{"x": {{"type": "particles", "cols": 1}}}}, "nodes": [{{"id": "a", "graph": "{path}", "inputs": {{"x": "inputs.x"}}}}], "outputs": {{"y": "a.y"}}}}"#
    );
    write_graph(dir, name, &json)
}

/// Subgraph paths stay inside the graph's folder and the library (before: an absolute
/// path or `..` reached any file, and a FIFO blocked the loader for ever).
#[test]
fn subgraph_paths_stay_inside_the_graph_folder_and_the_library() {
    let dir = tmpdir("untrusted-paths");
    let inner = dir.join("inner");
    std::fs::create_dir_all(&inner).unwrap();
    include_file(&dir, 9, None, false);
    let absolute = dir.join("f9.json");
    // Absolute, even to a good graph file.
    let e = load_file_error(&including(
        &inner,
        "abs.json",
        &absolute.display().to_string(),
    ));
    assert!(e.contains("is absolute"), "{e}");
    // `..` out of the top-level graph's folder.
    let e = load_file_error(&including(&inner, "up.json", "../f9.json"));
    assert!(e.contains("outside the folders"), "{e}");
    // A symbolic link inside the folder to a device.
    std::os::unix::fs::symlink("/dev/zero", inner.join("zero.json")).unwrap();
    let e = load_file_error(&including(&inner, "zero_user.json", "zero.json"));
    assert!(e.contains("outside the folders"), "{e}");
    // A FIFO inside the folder.
    let fifo = inner.join("fifo.json");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    if made.is_ok_and(|s| s.success()) {
        let e = load_file_error(&including(&inner, "fifo_user.json", "fifo.json"));
        assert!(e.contains("not a regular file"), "{e}");
    }
    // Inside the folder, and from the library (the shipped graphs/), still load.
    include_file(&inner, 8, None, false);
    crate::util::load(&including(&inner, "ok.json", "f8.json"));
    let json = r#"{"mesoflow": 1, "inputs": {"positions": {"type": "particles", "cols": 3}}, "nodes": [{"id": "cl", "graph": "lib/cell_list.json", "params": {"box": [8, 8, 8], "cells": [2, 2, 2]}, "inputs": {"positions": "inputs.positions"}}], "outputs": {"order": "cl.order"}}"#;
    crate::util::load(&write_graph(&inner, "lib_user.json", json));
}
