//! `mesoflow bench pse`: the PSE graph's speed against its error, per split: the GPU time
//! of one M F (and, with `--noise`, M F + sqrt(2 kT) M^(1/2) W, its Lanczos iterations
//! and host round trips included) for N random particles at UAMMD's sizes, and the error
//! reached at the same split and tolerance in a box of side `error_box`: the
//! self-mobility against Hasimoto and the pair mobility (overlapping and apart) against
//! an f64 Ewald sum at another split. Shows which split is best at each size. Times are
//! end to end (UAMMD's figures compare with these) beside the per-launch sum; with the
//! noise, the Lanczos loop's host round trips inside the step make the end-to-end time a
//! host-clock figure.

use std::f64::consts::PI;
use std::path::PathBuf;

use mesoflow::exec::Program;
use mesoflow::expr::ParamValue;
use mesoflow::gpu::{GpuContext, KernelCache};
use mesoflow::node::Registry;
use mesoflow::nodes::{fcm::plan::hasimoto, pse::periodic_rpy};

use super::fcm::{Rng, load, param, plan_for, timed, velocities};
use super::{BenchError, end_to_end_clock, ms};

pub struct PseBench {
    pub graph: PathBuf,
    pub splits: Vec<f64>,
    pub tolerance: f64,
    /// (box side L, particles N); empty: UAMMD's sizes.
    pub sizes: Vec<(f64, u32)>,
    pub noise: bool,
    pub reps: u64,
    pub error_box: f64,
    /// Other graph params, for the timed runs and the error runs alike.
    pub sets: Vec<(String, ParamValue)>,
    /// Deterministic plans (`run --deterministic`).
    pub deterministic: bool,
}

/// UAMMD's PSE benchmark (H200, a = 1, tolerance 1e-3): (L, N, split, ms, with noise ms).
pub const UAMMD: [(f64, u32, f64, f64, f64); 4] = [
    (64.0, 10_000, 0.5, 0.41, 3.07),
    (128.0, 100_000, 0.5, 1.38, 5.59),
    (128.0, 100_000, 0.3, 1.71, f64::NAN),
    (128.0, 100_000, 1.0, 3.77, f64::NAN),
];

/// (worst self error, worst pair error relative to the self-mobility).
fn accuracy(
    gpu: &GpuContext,
    bench: &PseBench,
    registry: &Registry,
    split: f64,
) -> Result<(f64, f64), BenchError> {
    let l = bench.error_box;
    let mut sets = vec![
        ("box", ParamValue::Numbers(vec![l; 3])),
        ("tolerance", ParamValue::Number(bench.tolerance)),
        ("split", ParamValue::Number(split)),
    ];
    sets.extend(bench.sets.iter().map(|(k, v)| (k.as_str(), v.clone())));
    let g = load(&bench.graph, &sets, registry)?;
    let self_want = hasimoto(1.0, l) / (6.0 * PI);
    let mut cache = KernelCache::default();
    let mut rng = Rng(0x2545_F491_4F6C_DD1D);
    let mut self_err: f64 = 0.0;
    {
        let p = plan_for(gpu, &g, 1)?;
        let mut program = Program::compile(gpu, &g, &p, &mut cache)?;
        // 4 random positions, and the 8 placements where the far field's error peaks: on a
        // grid point or midway between two, per axis.
        let h = match param(&g, "grid") {
            Some(ParamValue::Numbers(cells)) => l / cells[0],
            _ => l,
        };
        let peaks = (0..8).map(|corner: usize| {
            [0, 1, 2].map(|a| -0.5 * l + (2.5 + 0.5 * ((corner >> a) & 1) as f64) * h)
        });
        let random: Vec<[f64; 3]> = (0..4)
            .map(|_| [0, 1, 2].map(|_| (rng.uniform() - 0.5) * l))
            .collect();
        for x in random.into_iter().chain(peaks) {
            for axis in 0..3 {
                let mut f = [0.0; 3];
                f[axis] = 1.0;
                let v = velocities(&mut program, &[x], &[f])?;
                self_err = self_err.max((v[0][axis] / self_want - 1.0).abs());
            }
        }
    }
    // The reference splits differently from every benchmarked split.
    let xi_ref = if (split - 0.75).abs() < 0.1 {
        0.95
    } else {
        0.75
    };
    let p = plan_for(gpu, &g, 2)?;
    let mut program = Program::compile(gpu, &g, &p, &mut cache)?;
    let mut pair_err: f64 = 0.0;
    for r in [1.2, 2.0, 3.0, 5.0] {
        let x0 = [0, 1, 2].map(|_| (rng.uniform() - 0.5) * l);
        let d = [0, 1, 2].map(|_| rng.uniform() - 0.5);
        let norm = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let x1 = [0, 1, 2].map(|c| x0[c] + r * d[c] / norm);
        let want = periodic_rpy([0, 1, 2].map(|c| x1[c] - x0[c]), l, 1.0, 1.0, xi_ref)
            .map_err(BenchError::Args)?;
        for axis in 0..3 {
            let mut f = [[0.0; 3]; 2];
            f[0][axis] = 1.0;
            let v = velocities(&mut program, &[x0, x1], &f)?;
            for (c, row) in want.iter().enumerate() {
                pair_err = pair_err.max((v[1][c] - row[axis]).abs() / self_want);
            }
        }
    }
    Ok((self_err, pair_err))
}

pub fn run(bench: &PseBench) -> Result<(), BenchError> {
    if bench.reps == 0 {
        return Err(BenchError::Args("--reps must be positive".into()));
    }
    let mut gpu = GpuContext::new()?;
    // Every plan of the bench, timed and error runs alike, sees the request.
    gpu.caps.deterministic = bench.deterministic;
    let registry = mesoflow::nodes::registry();
    outln!("adapter: {}", gpu.caps.summary());
    if bench.deterministic {
        outln!("deterministic runs (--deterministic)");
    }
    outln!(
        "graph {}; a = 1, eta = 1, tolerance {:e}; time: median of one evaluation over {} runs, \
         e2e: end to end ({}; with noise, kT = 1: the Lanczos loop makes host round trips inside \
         the step, so on the host clock, round trips included), launches: sum of its launches' \
         medians (the loop timed on the host); errors in a box of side {}: self-mobility against \
         Hasimoto at 4 random positions and the 8 where the far field's error peaks (on a far \
         grid point or midway between two, per axis), pairs at 1.2a, 2a, 3a, 5a against an f64 \
         Ewald sum, relative to the self-mobility",
        bench.graph.display(),
        bench.tolerance,
        bench.reps,
        end_to_end_clock(&gpu),
        bench.error_box
    );
    outln!(
        "{:>5} {:>6} {:>8} {:>5} {:>4} {:>7} {:>7} {:>9} {:>11} {:>9} {:>11} {:>9} {:>9} {:>8} {:>10}",
        "split",
        "L",
        "N",
        "grid",
        "sup",
        "cutoff",
        "cells",
        "e2e ms",
        "launches ms",
        "noise e2e",
        "launches ms",
        "self err",
        "pair err",
        "MiB",
        "UAMMD ms"
    );
    let sizes: Vec<(f64, u32)> = if bench.sizes.is_empty() {
        vec![(64.0, 10_000), (128.0, 100_000)]
    } else {
        bench.sizes.clone()
    };
    for &split in &bench.splits {
        let (self_err, pair_err) = accuracy(&gpu, bench, &registry, split)?;
        for &(l, n) in &sizes {
            let mut sets = vec![
                ("box", ParamValue::Numbers(vec![l; 3])),
                ("tolerance", ParamValue::Number(bench.tolerance)),
                ("split", ParamValue::Number(split)),
            ];
            sets.extend(bench.sets.iter().map(|(k, v)| (k.as_str(), v.clone())));
            let g = match load(&bench.graph, &sets, &registry) {
                Ok(g) => g,
                Err(e) => {
                    outln!("{split:>5} {l:>6} {n:>8}  not run: {e}");
                    continue;
                }
            };
            let number = |name: &str| match param(&g, name) {
                Some(ParamValue::Number(x)) => x,
                Some(ParamValue::Numbers(v)) => v[0],
                _ => f64::NAN,
            };
            let run = timed(&gpu, &g, l, n, "velocities", bench.reps)?;
            let (noise_e2e, noise_launches) = if bench.noise {
                sets.push(("temperature", ParamValue::Number(1.0)));
                let g = load(&bench.graph, &sets, &registry)?;
                let noisy = timed(&gpu, &g, l, n, "fluctuating_velocities", bench.reps)?;
                (
                    format!("{:.4}", ms(noisy.end_to_end())),
                    format!("{:.4}", ms(noisy.launch_sum())),
                )
            } else {
                ("-".into(), "-".into())
            };
            let uammd = UAMMD
                .iter()
                .find(|u| u.0 == l && u.1 == n && (u.2 - split).abs() < 1e-9)
                .map(|u| {
                    if u.4.is_nan() {
                        format!("{:.2}", u.3)
                    } else {
                        format!("{:.2}/{:.2}", u.3, u.4)
                    }
                })
                .unwrap_or_else(|| "-".into());
            outln!(
                "{:>5} {:>6} {:>8} {:>5} {:>4} {:>7.3} {:>7} {:>9.4} {:>11.4} {:>9} {:>11} {:>9.2e} {:>9.2e} {:>8.0} {:>10}",
                split,
                l,
                n,
                number("grid"),
                number("support"),
                number("cutoff"),
                number("cells"),
                ms(run.end_to_end()),
                ms(run.launch_sum()),
                noise_e2e,
                noise_launches,
                self_err,
                pair_err,
                run.memory as f64 / (1u64 << 20) as f64,
                uammd
            );
        }
    }
    Ok(())
}
