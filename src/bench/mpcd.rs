//! `mesoflow bench mpcd`: particle-steps per second of `graphs/mpcd.json` (3D SRD,
//! periodic cubic box, 10 particles per cell by default) at several particle counts:
//! the GPU time of one step end to end, and the sum of its launches (streaming and
//! binning, collision), the state drawn by the graph itself. With
//! `MESOFLOW_BENCH_DISPATCHES` the per-dispatch times show where a step goes.

use std::collections::BTreeMap;
use std::path::PathBuf;

use mesoflow::expr::ParamValue;
use mesoflow::gpu::GpuContext;

use super::fcm::{load, param};
use super::{BenchError, end_to_end_clock, ms, time_loaded};

pub struct MpcdBench {
    pub graph: PathBuf,
    /// Approximate particle counts (rounded to whole cubic boxes of cells).
    pub sizes: Vec<u64>,
    pub density: f64,
    pub reps: u64,
    /// Other graph params.
    pub sets: Vec<(String, ParamValue)>,
}

pub fn run(bench: &MpcdBench) -> Result<(), BenchError> {
    if bench.reps == 0 || bench.density <= 0.0 {
        return Err(BenchError::Args(
            "--reps and --density must be positive".into(),
        ));
    }
    let gpu = GpuContext::new()?;
    let registry = mesoflow::nodes::registry();
    outln!("adapter: {}", gpu.caps.summary());
    outln!(
        "graph {}; 3D SRD, periodic cubic box, cell 1, {} particles per cell, angle 130, dt 0.1; \
         time of one step over {} steps: e2e, the step end to end ({}), median and mean; \
         launches: sum of its launches' medians and means; the rate from e2e",
        bench.graph.display(),
        bench.density,
        bench.reps,
        end_to_end_clock(&gpu)
    );
    outln!(
        "{:>10} {:>6} {:>10} {:>5} {:>10} {:>10} {:>12} {:>12} {:>16} {:>9}",
        "N",
        "L",
        "cells",
        "sort",
        "e2e ms",
        "e2e mean",
        "launches ms",
        "launch mean",
        "particle-steps/s",
        "ns/part."
    );
    outln!(
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
        let run = time_loaded(
            &gpu,
            &g,
            &BTreeMap::new(),
            Some(vec!["positions".into(), "velocities".into()]),
            bench.reps,
            true,
        )?;
        if std::env::var_os("MESOFLOW_BENCH_DISPATCHES").is_some() {
            for t in &run.timings {
                out!("{}", t.breakdown());
            }
        }
        // With a reordering every few steps, the rate comes from the mean step (the
        // reordering amortised); otherwise from the median.
        let step = if sort_every > 0.0 {
            run.mean_end_to_end()
        } else {
            run.end_to_end()
        }
        .as_secs_f64();
        outln!(
            "{:>10} {:>6} {:>10} {:>5} {:>10.4} {:>10.4} {:>12.4} {:>12.4} {:>16.3e} {:>9.3}",
            n,
            side,
            cells,
            sort_every,
            ms(run.end_to_end()),
            ms(run.mean_end_to_end()),
            ms(run.launch_sum()),
            ms(run.mean_launch_sum()),
            n / step,
            step * 1e9 / n
        );
    }
    Ok(())
}
