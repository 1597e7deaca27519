//! `mesoflow bench reduce`: sums of 10^8 f32 (blocked and compensated), a dot product
//! and a max, each a graph of its own timed end to end and per launch; bandwidth counts
//! bytes read. The result is checked against an f64 sum on the host, so a fast wrong
//! kernel cannot pass. `benches/torch_reduce.py` times the same calls for CUB.

use std::collections::BTreeMap;

use mesoflow::gpu::GpuContext;
use mesoflow::value::{HostArray, ValueType};

use super::{BenchError, end_to_end_clock, ms, time_graph};

/// (row label, node kind, params, bytes read per element)
const OPERATIONS: [(&str, &str, &str, f64); 4] = [
    ("sum", "sum", "{}", 4.0),
    ("sum_compensated", "sum", r#"{"compensated": true}"#, 4.0),
    ("dot", "dot", "{}", 8.0),
    ("max", "max", "{}", 4.0),
];

pub fn run(n: u32, reps: u64) -> Result<(), BenchError> {
    if n == 0 || reps == 0 {
        return Err(BenchError::Args("--n and --reps must be positive".into()));
    }
    let gpu = GpuContext::new()?;
    // Mixed magnitudes with both signs, from a fixed xorshift sequence.
    let mut s = 0x2545_F491_4F6C_DD1Du64;
    let mut next = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let x: Vec<f32> = (0..n)
        .map(|_| {
            let sign = if next() < 0.5 { -1.0 } else { 1.0 };
            (sign * 10f64.powf(6.0 * next() - 3.0)) as f32
        })
        .collect();
    let exact: f64 = x.iter().map(|&v| v as f64).sum();
    let abs: f64 = x.iter().map(|&v| (v as f64).abs()).sum();
    let ty = ValueType::Particles { n, k: 1 };
    let inputs: BTreeMap<String, HostArray> = [("x".to_string(), HostArray::f32(ty, x))]
        .into_iter()
        .collect();
    outln!("adapter: {}", gpu.caps.summary());
    outln!(
        "reductions of n = {n} f32 (mixed magnitudes 1e-3..1e3, random signs), median of {reps}; \
         e2e: the whole call, one graph per operation; launches: per-launch sum; GB/s from e2e"
    );
    outln!(
        "{:<18} {:>10} {:>12} {:>10} {:>14}",
        "node",
        "e2e ms",
        "launches ms",
        "GB/s",
        "rel. error"
    );
    for (label, kind, params, bytes) in OPERATIONS {
        let inputs_of_kind = if kind == "dot" {
            r#"{"a": "inputs.x", "b": "inputs.x"}"#
        } else {
            r#"{"x": "inputs.x"}"#
        };
        let graph = format!(
            r#"{{"mesoflow": 1,
      "inputs": {{"x": {{"type": "particles", "cols": 1}}}},
      "nodes": [{{"id": "{label}", "kind": "{kind}", "params": {params}, "inputs": {inputs_of_kind}}}],
      "outputs": {{"out": "{label}.out"}}}}"#
        );
        let run = time_graph(&gpu, &graph, &inputs, reps, true)?;
        let got = run.outputs["out"].data.to_f64()[0];
        let err = match kind {
            "sum" => format!("{:.1e}", (got - exact).abs() / abs),
            _ => "-".into(),
        };
        let e2e = run.end_to_end();
        outln!(
            "{:<18} {:>10.4} {:>12.4} {:>10.1} {:>14}",
            label,
            ms(e2e),
            ms(run.launch_sum()),
            bytes * n as f64 / e2e.as_secs_f64() / 1e9,
            err
        );
    }
    outln!(
        "(error of a sum: |sum - f64 sum| / sum |x|; sum = {exact:.6e}, sum |x| = {abs:.6e}; \
         e2e by {})",
        end_to_end_clock(&gpu)
    );
    Ok(())
}
