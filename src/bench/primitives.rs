//! `mesoflow bench sort` and `mesoflow bench scan`: the `sort` and `scan` nodes on random
//! u32 data, timed per launch with GPU timestamps ([`time_graph`]). Each result is checked
//! on the host (sortedness, a valid and stable permutation; every prefix sum), so a fast
//! wrong kernel cannot pass. benches/torch_primitives.py prints the same table for
//! PyTorch (CUB) on the same sizes.
//!
//! GB/s counts the operation's own input and output once (sort: 4 bytes of key in, 8 of
//! key and index out; scan: 4 in, 4 out). The kernels move more (sort: 76 bytes per key
//! in 4 passes on the subgroup path; scan: 12 per element); the last line gives the rate
//! of that traffic.

use std::collections::BTreeMap;

use super::{TimedRun, time_graph};
use crate::cli::CliError;
use crate::gpu::GpuContext;
use crate::nodes::scan::Variant;
use crate::value::{HostArray, HostData, ValueType};

fn runtime(e: impl std::fmt::Display) -> CliError {
    CliError::Runtime(e.to_string())
}

/// Random u32 from a fixed splitmix64 sequence.
fn random_u32(n: u32, seed: u64) -> Vec<u32> {
    let mut s = seed;
    (0..n)
        .map(|_| {
            s = s.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = s;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 32) as u32
        })
        .collect()
}

fn check_args(n: u32, reps: u64, variant: &str) -> Result<(), CliError> {
    if n == 0 || reps == 0 {
        return Err(CliError::Input("--n and --reps must be positive".into()));
    }
    if !Variant::NAMES.contains(&variant) {
        return Err(CliError::Input(format!(
            "--variant {variant}: expected one of {}",
            Variant::NAMES.join(", ")
        )));
    }
    Ok(())
}

fn u32s<'a>(run: &'a TimedRun, name: &str) -> Result<&'a [u32], CliError> {
    match run.outputs.get(name).map(|a| &a.data) {
        Some(HostData::U32(v)) => Ok(v),
        _ => Err(CliError::Runtime(format!("output `{name}` is missing"))),
    }
}

/// Prints the shared table (the same columns as benches/torch_primitives.py).
fn table(gpu: &GpuContext, what: &str, n: u32, run: &TimedRun, bytes_per_elem: f64) {
    let t = run.step_time().as_secs_f64();
    let min: f64 = run.timings.iter().map(|t| t.min.as_secs_f64()).sum();
    println!("adapter: {}", gpu.caps.summary());
    println!(
        "{:<30} {:>11} {:>9} {:>9} {:>9} {:>9}",
        "op", "n", "ms", "min ms", "G/s", "GB/s"
    );
    println!(
        "{:<30} {:>11} {:>9.4} {:>9.4} {:>9.2} {:>9.1}",
        what,
        n,
        t * 1e3,
        min * 1e3,
        n as f64 / t / 1e9,
        bytes_per_elem * n as f64 / t / 1e9
    );
}

pub fn sort(n: u32, reps: u64, variant: &str) -> Result<(), CliError> {
    check_args(n, reps, variant)?;
    let gpu = GpuContext::new().map_err(runtime)?;
    let keys = random_u32(n, 1);
    let graph = format!(
        r#"{{"mesoflow": 1, "doc": "bench: stable radix sort of n u32 keys with their permutation",
  "inputs": {{"keys": {{"type": "indices", "rows": {n}}}}},
  "nodes": [{{"id": "sort", "kind": "sort", "params": {{"variant": "{variant}"}}, "inputs": {{"keys": "inputs.keys"}}}}],
  "outputs": {{"keys": "sort.keys", "perm": "sort.perm"}}}}"#
    );
    let ty = ValueType::Indices { n };
    let inputs: BTreeMap<String, HostArray> =
        [("keys".to_string(), HostArray::u32(ty, keys.clone()))].into();
    let run = time_graph(&gpu, &graph, &inputs, reps, true)?;
    for t in &run.timings {
        print!("{}", t.breakdown());
    }

    let sorted = u32s(&run, "keys")?;
    let perm = u32s(&run, "perm")?;
    let mut seen = vec![false; n as usize];
    for i in 0..n as usize {
        let p = perm[i] as usize;
        if p >= seen.len() || std::mem::replace(&mut seen[p], true) {
            return Err(CliError::Runtime(format!(
                "sort: perm is not a permutation (perm[{i}] = {p})"
            )));
        }
        if sorted[i] != keys[p] {
            return Err(CliError::Runtime(format!(
                "sort: keys[{i}] = {} but the input key at perm[{i}] = {p} is {}",
                sorted[i], keys[p]
            )));
        }
        if i > 0 && (sorted[i - 1], perm[i - 1]) >= (sorted[i], perm[i]) {
            return Err(CliError::Runtime(format!(
                "sort: out of order or unstable at {i}: ({}, {}) then ({}, {})",
                sorted[i - 1],
                perm[i - 1],
                sorted[i],
                perm[i]
            )));
        }
    }
    table(
        &gpu,
        &format!("sort u32 keys + perm ({variant})"),
        n,
        &run,
        12.0,
    );
    // Passes of 8-bit digits on the subgroup path, of 4-bit digits on the portable one;
    // each moves 20 bytes per key but the first (16: no payload to read).
    let passes = if variant == "portable" || gpu.caps.subgroups.is_none() {
        8.0
    } else {
        4.0
    };
    let traffic = 20.0 * passes - 4.0;
    println!(
        "(checked: sorted, stable, a permutation; radix-sort traffic {traffic} B/key: {:.1} GB/s)",
        traffic * n as f64 / run.step_time().as_secs_f64() / 1e9
    );
    Ok(())
}

pub fn scan(n: u32, reps: u64, variant: &str) -> Result<(), CliError> {
    check_args(n, reps, variant)?;
    let gpu = GpuContext::new().map_err(runtime)?;
    // Full-range words, so the sums wrap (as documented) many times.
    let x = random_u32(n, 2);
    let graph = format!(
        r#"{{"mesoflow": 1, "doc": "bench: exclusive scan of n u32",
  "inputs": {{"x": {{"type": "indices", "rows": {n}}}}},
  "nodes": [{{"id": "scan", "kind": "scan", "params": {{"variant": "{variant}"}}, "inputs": {{"x": "inputs.x"}}}}],
  "outputs": {{"out": "scan.out"}}}}"#
    );
    let ty = ValueType::Indices { n };
    let inputs: BTreeMap<String, HostArray> =
        [("x".to_string(), HostArray::u32(ty, x.clone()))].into();
    let run = time_graph(&gpu, &graph, &inputs, reps, true)?;

    let out = u32s(&run, "out")?;
    let mut acc = 0u32;
    for (i, (&o, &v)) in out.iter().zip(&x).enumerate() {
        if o != acc {
            return Err(CliError::Runtime(format!(
                "scan: out[{i}] = {o}, expected {acc}"
            )));
        }
        acc = acc.wrapping_add(v);
    }
    table(
        &gpu,
        &format!("exclusive scan u32 ({variant})"),
        n,
        &run,
        8.0,
    );
    println!(
        "(checked: every element; reduce-then-scan traffic 12 B/element: {:.1} GB/s)",
        12.0 * n as f64 / run.step_time().as_secs_f64() / 1e9
    );
    Ok(())
}
