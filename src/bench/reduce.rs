//! `mesoflow bench reduce`: sums of 10^8 f32 (blocked and compensated), a dot product
//! and a max, timed per launch with GPU timestamps; bandwidth counts bytes read. The
//! result is checked against an f64 sum on the host, so a fast wrong kernel cannot pass.

use std::collections::BTreeMap;

use super::{Timing, runtime, time_graph};
use crate::cli::CliError;
use crate::gpu::GpuContext;
use crate::value::{HostArray, ValueType};

pub fn run(n: u32, reps: u64) -> Result<(), CliError> {
    let gpu = GpuContext::new().map_err(runtime)?;
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
    let graph = r#"{"mesoflow": 1,
      "inputs": {"x": {"type": "particles", "cols": 1}},
      "nodes": [
        {"id": "sum", "kind": "sum", "inputs": {"x": "inputs.x"}},
        {"id": "sum_compensated", "kind": "sum", "params": {"compensated": true}, "inputs": {"x": "inputs.x"}},
        {"id": "dot", "kind": "dot", "inputs": {"a": "inputs.x", "b": "inputs.x"}},
        {"id": "max", "kind": "max", "inputs": {"x": "inputs.x"}}
      ],
      "outputs": {"sum": "sum.out", "sum_compensated": "sum_compensated.out", "dot": "dot.out", "max": "max.out"}}"#;
    let run = time_graph(&gpu, graph, &inputs, reps, true)?;
    let bytes = |t: &Timing| if t.label == "dot" { 8.0 } else { 4.0 } * n as f64;
    println!("adapter: {}", gpu.caps.summary());
    println!(
        "reductions of n = {n} f32 (mixed magnitudes 1e-3..1e3, random signs), median of {reps}"
    );
    println!(
        "{:<18} {:>10} {:>10} {:>14}",
        "node", "ms", "GB/s", "rel. error"
    );
    for t in &run.timings {
        let got = run.outputs[&t.label].data.to_f64()[0];
        let err = match t.label.as_str() {
            "sum" | "sum_compensated" => format!("{:.1e}", (got - exact).abs() / abs),
            _ => "-".into(),
        };
        let ms = t.median.as_secs_f64() * 1e3;
        println!(
            "{:<18} {:>10.4} {:>10.1} {:>14}",
            t.label,
            ms,
            bytes(t) / t.median.as_secs_f64() / 1e9,
            err
        );
    }
    println!("(error of a sum: |sum - f64 sum| / sum |x|; sum = {exact:.6e}, sum |x| = {abs:.6e})");
    Ok(())
}
