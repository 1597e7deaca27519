//! `mesoflow bench mpcd`: particle-steps per second of `graphs/mpcd.json` (3D SRD,
//! periodic cubic box, 10 particles per cell by default) at several particle counts:
//! the GPU time of one step (the sum of its launches' medians: streaming, binning,
//! collision), the state drawn by the graph itself. With `MESOFLOW_BENCH_DISPATCHES`
//! the per-dispatch times show where a step goes.

use std::collections::BTreeMap;
use std::path::PathBuf;

use super::fcm::{load, param};
use super::{runtime, time_loaded};
use crate::cli::CliError;
use crate::expr::ParamValue;
use crate::gpu::GpuContext;

pub struct MpcdBench {
    pub graph: PathBuf,
    /// Approximate particle counts (rounded to whole cubic boxes of cells).
    pub sizes: Vec<u64>,
    pub density: f64,
    pub reps: u64,
    /// Other graph params.
    pub sets: Vec<(String, ParamValue)>,
}

pub fn run(bench: &MpcdBench) -> Result<(), CliError> {
    if bench.reps == 0 || bench.density <= 0.0 {
        return Err(CliError::Input(
            "--reps and --density must be positive".into(),
        ));
    }
    let gpu = GpuContext::new().map_err(runtime)?;
    let registry = crate::nodes::registry();
    println!("adapter: {}", gpu.caps.summary());
    println!(
        "graph {}; 3D SRD, periodic cubic box, cell 1, {} particles per cell, angle 130, dt 0.1; time: GPU time of one step over {} steps (sum of its launches' medians and means)",
        bench.graph.display(),
        bench.density,
        bench.reps
    );
    println!(
        "{:>10} {:>6} {:>10} {:>5} {:>10} {:>10} {:>14} {:>9}",
        "N", "L", "cells", "sort", "median ms", "mean ms", "particle-steps/s", "ns/part."
    );
    println!(
        "(sort: the graph's sort_every; where it is set the rate comes from the mean step, the reordering amortised)"
    );
    for &target in &bench.sizes {
        let side = ((target as f64 / bench.density).cbrt().round()).max(2.0);
        let mut sets = vec![
            ("box", ParamValue::Numbers(vec![side; 3])),
            ("density", ParamValue::Number(bench.density)),
        ];
        sets.extend(bench.sets.iter().map(|(k, v)| (k.as_str(), v.clone())));
        let g = load(&bench.graph, &sets, &registry)?;
        let density = match param(&g, "density") {
            Some(ParamValue::Number(d)) => d,
            _ => bench.density,
        };
        let sort_every = match param(&g, "sort_every") {
            Some(ParamValue::Number(k)) => k,
            _ => 0.0,
        };
        let cells = side * side * side;
        let n = (cells * density).round();
        let (run, _) = time_loaded(
            &gpu,
            &g,
            &BTreeMap::new(),
            Some(vec!["positions".into(), "velocities".into()]),
            bench.reps,
            true,
        )?;
        if std::env::var_os("MESOFLOW_BENCH_DISPATCHES").is_some() {
            for t in &run.timings {
                print!("{}", t.breakdown());
            }
        }
        // With a reordering every few steps, the rate comes from the mean step (the
        // reordering amortised); otherwise from the median, as before.
        let median = run.step_time().as_secs_f64();
        let mean = run.mean_step_time().as_secs_f64();
        let step = if sort_every > 0.0 { mean } else { median };
        println!(
            "{:>10} {:>6} {:>10} {:>5} {:>10.4} {:>10.4} {:>14.3e} {:>9.3}",
            n,
            side,
            cells,
            sort_every,
            median * 1e3,
            mean * 1e3,
            n / step,
            step * 1e9 / n
        );
    }
    Ok(())
}
