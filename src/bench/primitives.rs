//! `mesoflow bench sort` and `mesoflow bench scan`: the `sort` and `scan` nodes on random
//! u32 data, timed end to end and per launch ([`time_graph`]). Each result is checked
//! on the host (sortedness, a valid and stable permutation; every prefix sum), so a fast
//! wrong kernel cannot pass. `bench sort --variant all` runs every sort variant on the same
//! keys, one row each. benches/torch_primitives.py prints the same table for PyTorch (CUB)
//! on the same sizes, timed with CUDA events around each call: the "ms" and "min ms"
//! columns here are the end-to-end times it compares with, and the rates come from them.
//!
//! GB/s counts the operation's own input and output once (sort: 4 bytes of key in, 8 of
//! key and index out; scan: 4 in, 4 out). The kernels move more (sort: about 80 bytes per
//! key in 4 passes, 160 in the portable path's 8, see `sort::traffic_per_key`; scan: 12
//! per element); the "moved GB/s" column gives the rate of that traffic.

use std::collections::BTreeMap;

use mesoflow::gpu::GpuContext;
use mesoflow::nodes::scan::Variant;
use mesoflow::nodes::sort::{self, SortVariant};
use mesoflow::value::{HostArray, HostData, ValueType};

use super::{BenchError, TimedRun, end_to_end_clock, ms, time_graph};

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

fn check_args(n: u32, reps: u64) -> Result<(), BenchError> {
    if n == 0 || reps == 0 {
        return Err(BenchError::Args("--n and --reps must be positive".into()));
    }
    Ok(())
}

fn u32s<'a>(run: &'a TimedRun, name: &str) -> Result<&'a [u32], BenchError> {
    match run.outputs.get(name).map(|a| &a.data) {
        Some(HostData::U32(v)) => Ok(v),
        _ => Err(BenchError::Wrong(format!(
            "output `{name}` is missing or not u32"
        ))),
    }
}

/// The shared table (the columns of benches/torch_primitives.py, end to end, plus the
/// per-launch sum and the rate of the traffic the kernels themselves move): header, then
/// one row per call.
fn header(gpu: &GpuContext, reps: u64) {
    outln!("adapter: {}", gpu.caps.summary());
    outln!(
        "ms, min ms: the whole call end to end ({}), median and fastest of {reps}; launches ms: \
         sum of per-launch medians; rates from the end-to-end median",
        end_to_end_clock(gpu)
    );
    outln!(
        "{:<30} {:>11} {:>9} {:>9} {:>12} {:>9} {:>9} {:>11}",
        "op",
        "n",
        "ms",
        "min ms",
        "launches ms",
        "G/s",
        "GB/s",
        "moved GB/s"
    );
}

fn row(what: &str, n: u32, run: &TimedRun, bytes_per_elem: f64, moved_per_elem: f64) {
    let t = run.end_to_end().as_secs_f64();
    let min = run.steps.iter().min().copied().unwrap_or_default();
    outln!(
        "{:<30} {:>11} {:>9.4} {:>9.4} {:>12.4} {:>9.2} {:>9.1} {:>11.1}",
        what,
        n,
        t * 1e3,
        ms(min),
        ms(run.launch_sum()),
        n as f64 / t / 1e9,
        bytes_per_elem * n as f64 / t / 1e9,
        moved_per_elem * n as f64 / t / 1e9
    );
}

/// Checks a sort's outputs on the host: `perm` a permutation, `sorted` the keys it
/// picks, in ascending order and stable (equal keys in input order).
fn check_sort(keys: &[u32], run: &TimedRun, variant: &str) -> Result<(), String> {
    let fail = |msg: String| Err(format!("sort ({variant}): {msg}"));
    let (Ok(sorted), Ok(perm)) = (u32s(run, "keys"), u32s(run, "perm")) else {
        return fail("an output is missing".into());
    };
    if sorted.len() != keys.len() || perm.len() != keys.len() {
        return fail(format!(
            "{} keys and {} indices for {} keys",
            sorted.len(),
            perm.len(),
            keys.len()
        ));
    }
    let mut seen = vec![false; keys.len()];
    for i in 0..keys.len() {
        let p = perm[i] as usize;
        if p >= seen.len() || std::mem::replace(&mut seen[p], true) {
            return fail(format!("perm is not a permutation (perm[{i}] = {p})"));
        }
        if sorted[i] != keys[p] {
            return fail(format!(
                "keys[{i}] = {} but the input key at perm[{i}] = {p} is {}",
                sorted[i], keys[p]
            ));
        }
        if i > 0 && (sorted[i - 1], perm[i - 1]) >= (sorted[i], perm[i]) {
            return fail(format!(
                "out of order or unstable at {i}: ({}, {}) then ({}, {})",
                sorted[i - 1],
                perm[i - 1],
                sorted[i],
                perm[i]
            ));
        }
    }
    Ok(())
}

/// `variant` is a value of the node's `variant` param, or `all`: every value in turn on
/// the same keys, one table row each; then a variant the device cannot run is skipped,
/// and one whose result is wrong is reported after the table (and fails the command)
/// without hiding the others' times.
pub fn sort(n: u32, reps: u64, variant: &str) -> Result<(), BenchError> {
    check_args(n, reps)?;
    let all = variant == "all";
    let variants: Vec<&str> = if all {
        SortVariant::NAMES.to_vec()
    } else if SortVariant::NAMES.contains(&variant) {
        vec![variant]
    } else {
        return Err(BenchError::Args(format!(
            "--variant {variant}: expected all or one of {}",
            SortVariant::NAMES.join(", ")
        )));
    };
    let gpu = GpuContext::new()?;
    let keys = random_u32(n, 1);
    let ty = ValueType::Indices { n };
    let inputs: BTreeMap<String, HostArray> =
        [("keys".to_string(), HostArray::u32(ty, keys.clone()))].into();
    let mut rows = Vec::new();
    let mut notes = Vec::new();
    let mut wrong = Vec::new();
    for v in variants {
        let parsed = SortVariant::from_name(v)
            .ok_or_else(|| BenchError::Args(format!("--variant {v}: no such sort variant")))?;
        let traffic = match sort::traffic_per_key(parsed, &gpu.caps, 32, n as u64) {
            Ok(t) => t,
            Err(e) if all => {
                notes.push(format!("{v} skipped: {e}"));
                continue;
            }
            Err(e) => return Err(BenchError::Args(e.to_string())),
        };
        let graph = format!(
            r#"{{"mesoflow": 1, "doc": "bench: stable radix sort of n u32 keys with their permutation",
  "inputs": {{"keys": {{"type": "indices", "rows": {n}}}}},
  "nodes": [{{"id": "sort", "kind": "sort", "params": {{"variant": "{v}"}}, "inputs": {{"keys": "inputs.keys"}}}}],
  "outputs": {{"keys": "sort.keys", "perm": "sort.perm"}}}}"#
        );
        let run = time_graph(&gpu, &graph, &inputs, reps, true)?;
        if run.timings.iter().any(|t| !t.dispatches.is_empty()) {
            outln!("{v}:");
        }
        for t in &run.timings {
            out!("{}", t.breakdown());
        }
        match check_sort(&keys, &run, v) {
            Ok(()) => {
                notes.push(format!("{v} {traffic:.1} B/key"));
                rows.push((v, run, traffic));
            }
            Err(e) => wrong.push(e),
        }
    }
    header(&gpu, reps);
    for (v, run, traffic) in &rows {
        row(
            &format!("sort u32 keys + perm ({v})"),
            n,
            run,
            12.0,
            *traffic,
        );
    }
    outln!(
        "(checked: sorted, stable, a permutation; GB/s: 12 B/key, key in, key and index \
         out; moved: what the passes move, {})",
        notes.join(", ")
    );
    if wrong.is_empty() {
        Ok(())
    } else {
        Err(BenchError::Wrong(wrong.join("\n")))
    }
}

pub fn scan(n: u32, reps: u64, variant: &str) -> Result<(), BenchError> {
    check_args(n, reps)?;
    if !Variant::NAMES.contains(&variant) {
        return Err(BenchError::Args(format!(
            "--variant {variant}: expected one of {}",
            Variant::NAMES.join(", ")
        )));
    }
    let gpu = GpuContext::new()?;
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
            return Err(BenchError::Wrong(format!(
                "scan: out[{i}] = {o}, expected {acc}"
            )));
        }
        acc = acc.wrapping_add(v);
    }
    header(&gpu, reps);
    row(
        &format!("exclusive scan u32 ({variant})"),
        n,
        &run,
        8.0,
        12.0,
    );
    outln!("(checked: every element; moved: reduce-then-scan traffic, 12 B/element)");
    Ok(())
}
