//! `mesoflow bench fcm`: the FCM graph's speed against its error, per kernel and
//! tolerance: the GPU time of one evaluation M F (and, with `--noise`, M F plus the
//! Fourier-space noise) for N random particles, and the error reached, measured in a
//! separate box against f64 references: the self-mobility (Hasimoto's periodic value for
//! the window's radius; for the Gaussian the exact periodic Gaussian mobility) over
//! random positions, and for the Gaussian the pair mobility against a direct Fourier sum.
//! Times are end to end (the whole evaluation, as UAMMD's figures are) beside the
//! per-launch sum; comparisons with UAMMD use the end-to-end time.
//! `--plot FILE.svg` draws error against time: the user's guide to kernel and tolerance.

use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

use mesoflow::exec::{Profile, Program, RunOptions};
use mesoflow::expr::ParamValue;
use mesoflow::gpu::{GpuContext, KernelCache};
use mesoflow::graph::{self, Graph, LoadOptions};
use mesoflow::node::Registry;
use mesoflow::nodes::fcm::{plan as fcm_plan, reference};
use mesoflow::plan::{self, PlanOptions};
use mesoflow::value::{HostArray, ValueType};

use super::{BenchError, TimedRun, end_to_end_clock, ms, time_loaded};

/// What to measure.
pub struct FcmBench {
    pub graph: PathBuf,
    pub kernels: Vec<String>,
    pub tolerances: Vec<f64>,
    /// (box side L, particles N); empty: UAMMD's benchmark sizes for each tolerance.
    pub sizes: Vec<(f64, u32)>,
    pub noise: bool,
    pub reps: u64,
    /// Side of the cubic box the errors are measured in.
    pub error_box: f64,
    /// Random positions the self-mobility error is measured at.
    pub error_samples: usize,
    pub plot: Option<PathBuf>,
    /// Other graph params for the timed runs.
    pub sets: Vec<(String, ParamValue)>,
    /// Deterministic plans (`run --deterministic`).
    pub deterministic: bool,
}

/// UAMMD's FCM benchmark (H200, Gaussian, a = 1): (tolerance, L, N, ms).
pub const UAMMD: [(f64, f64, u32, f64); 9] = [
    (1e-2, 64.0, 10_000, 0.214),
    (1e-2, 127.0, 100_000, 1.25),
    (1e-2, 264.0, 1_000_000, 13.8),
    (1e-3, 65.0, 10_000, 0.272),
    (1e-3, 129.0, 100_000, 2.15),
    (1e-3, 256.0, 1_000_000, 21.5),
    (1e-4, 65.0, 10_000, 0.372),
    (1e-4, 130.0, 100_000, 4.02),
    (1e-4, 260.0, 1_000_000, 34.5),
];

/// One measured row.
struct Row {
    kernel: String,
    tolerance: f64,
    l: f64,
    n: u32,
    grid: u32,
    support: String,
    /// One M F end to end, ms.
    e2e_ms: f64,
    /// The sum of its launches, ms.
    launches_ms: f64,
    /// M F plus the noise: (end to end, launch sum), ms.
    noise_ms: Option<(f64, f64)>,
    self_max: f64,
    self_mean: f64,
    pair: Option<f64>,
    memory: u64,
}

/// A small deterministic generator (xorshift) for positions and forces.
pub(super) struct Rng(pub(super) u64);

impl Rng {
    pub(super) fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

pub(super) fn load(
    path: &Path,
    sets: &[(&str, ParamValue)],
    registry: &Registry,
) -> Result<Graph, BenchError> {
    let overrides = sets
        .iter()
        .map(|(k, v)| (k.to_string(), v.clone()))
        .collect();
    Ok(graph::load(
        path,
        registry,
        &LoadOptions {
            overrides,
            steps: 1,
            seed: 1,
        },
    )?)
}

pub(super) fn param(g: &Graph, name: &str) -> Option<ParamValue> {
    g.param(name).cloned()
}

/// Rows of 3-vectors as an f32 particle array (N x 3).
pub(super) fn particles(rows: &[[f64; 3]]) -> HostArray {
    HostArray::f32(
        ValueType::Particles {
            n: rows.len() as u32,
            k: 3,
        },
        rows.iter().flatten().map(|&x| x as f32).collect(),
    )
}

/// The inputs of a mobility graph: positions and forces, N x 3 each.
pub(super) fn mobility_inputs(x: &[[f64; 3]], f: &[[f64; 3]]) -> BTreeMap<String, HostArray> {
    [
        ("positions".to_string(), particles(x)),
        ("forces".to_string(), particles(f)),
    ]
    .into_iter()
    .collect()
}

/// Velocities of `x` under forces `f`, one evaluation of a compiled graph.
pub(super) fn velocities(
    program: &mut Program,
    x: &[[f64; 3]],
    f: &[[f64; 3]],
) -> Result<Vec<[f64; 3]>, BenchError> {
    program.upload(&mobility_inputs(x, f))?;
    program.run(&RunOptions {
        steps: 1,
        profile: Profile::Off,
        progress: false,
    })?;
    let out = program.read_outputs()?;
    let v = out
        .iter()
        .find(|(k, _)| k == "velocities")
        .map(|(_, v)| v.data.to_f64())
        .ok_or_else(|| BenchError::Wrong("the graph has no `velocities` output".into()))?;
    Ok(v.chunks(3).map(|c| [c[0], c[1], c[2]]).collect())
}

/// (max, mean) relative self-mobility error over random positions, and for the Gaussian
/// the largest pair-mobility error (at 2a and 4a) relative to the self-mobility.
fn accuracy(
    gpu: &GpuContext,
    bench: &FcmBench,
    registry: &Registry,
    kernel: &str,
    tolerance: f64,
) -> Result<(f64, f64, Option<f64>), BenchError> {
    let l = bench.error_box;
    let g = load(
        &bench.graph,
        &[
            ("box", ParamValue::Numbers(vec![l; 3])),
            ("tolerance", ParamValue::Number(tolerance)),
            ("kernel", ParamValue::Text(kernel.into())),
        ],
        registry,
    )?;
    let a = match param(&g, "effective_radius") {
        Some(ParamValue::Number(a)) => a,
        _ => 1.0,
    };
    let eta = match param(&g, "viscosity") {
        Some(ParamValue::Number(e)) => e,
        _ => 1.0,
    };
    let gaussian = kernel == "gaussian";
    let sigma = a / PI.sqrt();
    let self_want = if gaussian {
        reference::periodic_gaussian_mobility([0.0; 3], [l; 3], eta, sigma)[0][0]
    } else {
        fcm_plan::hasimoto(a, l) / (6.0 * PI * eta * a)
    };
    let mut cache = KernelCache::default();
    let mut rng = Rng(0x2545_F491_4F6C_DD1D);
    let mut errors = Vec::new();
    let mut peak_errors = Vec::new();
    {
        let p = plan_for(gpu, &g, 1)?;
        let mut program = Program::compile(gpu, &g, &p, &mut cache)?;
        let mut self_error = |x: [f64; 3], into: &mut Vec<f64>| -> Result<(), BenchError> {
            for axis in 0..3 {
                let mut f = [0.0; 3];
                f[axis] = 1.0;
                let v = velocities(&mut program, &[x], &[f])?;
                into.push((v[0][axis] / self_want - 1.0).abs());
            }
            Ok(())
        };
        for _ in 0..bench.error_samples {
            let x = [0, 1, 2].map(|_| (rng.uniform() - 0.5) * l);
            self_error(x, &mut errors)?;
        }
        // Where the discretisation's error peaks: on a grid point or midway between two,
        // per axis (a cell corner midway on all three).
        if let Some(ParamValue::Numbers(cells)) = param(&g, "grid") {
            let h = l / cells[0];
            for corner in 0..8 {
                let x = [0, 1, 2].map(|a| -0.5 * l + (2.5 + 0.5 * ((corner >> a) & 1) as f64) * h);
                self_error(x, &mut peak_errors)?;
            }
        }
    }
    let self_max = errors
        .iter()
        .chain(&peak_errors)
        .cloned()
        .fold(0.0, f64::max);
    let self_mean = errors.iter().sum::<f64>() / errors.len().max(1) as f64;
    let pair = if gaussian {
        let p = plan_for(gpu, &g, 2)?;
        let mut program = Program::compile(gpu, &g, &p, &mut cache)?;
        let mut worst: f64 = 0.0;
        for r in [2.0 * a, 4.0 * a] {
            for _ in 0..2 {
                let x0 = [0, 1, 2].map(|_| (rng.uniform() - 0.5) * l);
                let d = [0, 1, 2].map(|_| rng.uniform() - 0.5);
                let norm = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                let x1 = [0, 1, 2].map(|c| x0[c] + r * d[c] / norm);
                let want = reference::periodic_gaussian_mobility(
                    [0, 1, 2].map(|c| x1[c] - x0[c]),
                    [l; 3],
                    eta,
                    sigma,
                );
                for axis in 0..3 {
                    let mut f = [[0.0; 3]; 2];
                    f[0][axis] = 1.0;
                    let v = velocities(&mut program, &[x0, x1], &f)?;
                    for (c, row) in want.iter().enumerate() {
                        worst = worst.max((v[1][c] - row[axis]).abs() / self_want);
                    }
                }
            }
        }
        Some(worst)
    } else {
        None
    };
    Ok((self_max, self_mean, pair))
}

pub(super) fn plan_for(gpu: &GpuContext, g: &Graph, n: u32) -> Result<plan::Plan, BenchError> {
    let p3 = ValueType::Particles { n, k: 3 };
    let opts = PlanOptions {
        outputs: Some(vec!["velocities".into()]),
        inputs: [("positions".to_string(), p3), ("forces".to_string(), p3)]
            .into_iter()
            .collect(),
        fuse: true,
        in_place: true,
    };
    Ok(plan::plan(g, &opts, &gpu.caps)?)
}

/// One evaluation of `output` for N random particles in a cube of side L, timed.
pub(super) fn timed(
    gpu: &GpuContext,
    g: &Graph,
    l: f64,
    n: u32,
    output: &str,
    reps: u64,
) -> Result<TimedRun, BenchError> {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15 ^ n as u64);
    let x: Vec<[f64; 3]> = (0..n)
        .map(|_| [0, 1, 2].map(|_| (rng.uniform() - 0.5) * l))
        .collect();
    let f: Vec<[f64; 3]> = (0..n)
        .map(|_| [0, 1, 2].map(|_| rng.uniform() - 0.5))
        .collect();
    let inputs = mobility_inputs(&x, &f);
    let run = time_loaded(gpu, g, &inputs, Some(vec![output.into()]), reps, true)?;
    if std::env::var_os("MESOFLOW_BENCH_DISPATCHES").is_some() {
        for t in &run.timings {
            out!("{}", t.breakdown());
        }
    }
    Ok(run)
}

fn support_text(g: &Graph, kernel: &str) -> String {
    match (kernel, param(g, "support")) {
        ("peskin3", _) => "3".into(),
        ("peskin4", _) => "4".into(),
        ("peskin6", _) => "6".into(),
        (_, Some(ParamValue::Number(s))) if s > 0.0 => format!("{s}"),
        _ => "?".into(),
    }
}

pub fn run(bench: &FcmBench) -> Result<(), BenchError> {
    if bench.reps == 0 || bench.error_samples == 0 {
        return Err(BenchError::Args(
            "--reps and --error-samples must be positive".into(),
        ));
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
        "graph {}; a = 1, eta = 1; time: median of one evaluation over {} runs, e2e: end to end ({}), \
         ns/part and the ratio to UAMMD from it; launches: sum of its launches' medians; errors \
         measured in a box of side {} (self max: over {} random positions and the 8 placements \
         where the error peaks, on a grid point or midway between two per axis, a cell corner \
         among them; self mean: over the random ones) and 4 pairs at 2a and 4a (pair, Gaussian \
         only, relative to the self-mobility)",
        bench.graph.display(),
        bench.reps,
        end_to_end_clock(&gpu),
        bench.error_box,
        bench.error_samples
    );
    outln!(
        "{:<8} {:>6} {:>6} {:>8} {:>5} {:>4} {:>9} {:>11} {:>8} {:>9} {:>11} {:>9} {:>9} {:>9} {:>8} {:>9} {:>7}",
        "kernel",
        "tol",
        "L",
        "N",
        "grid",
        "sup",
        "e2e ms",
        "launches ms",
        "ns/part",
        "noise e2e",
        "launches ms",
        "self max",
        "self mean",
        "pair max",
        "MiB",
        "UAMMD ms",
        "/UAMMD"
    );
    let mut rows: Vec<Row> = Vec::new();
    for kernel in &bench.kernels {
        for &tol in &bench.tolerances {
            let (self_max, self_mean, pair) = accuracy(&gpu, bench, &registry, kernel, tol)?;
            let sizes: Vec<(f64, u32)> = if bench.sizes.is_empty() {
                UAMMD
                    .iter()
                    .filter(|u| (u.0 / tol - 1.0).abs() < 1e-9)
                    .map(|u| (u.1, u.2))
                    .collect()
            } else {
                bench.sizes.clone()
            };
            for (l, n) in sizes {
                let mut sets = vec![
                    ("box", ParamValue::Numbers(vec![l; 3])),
                    ("tolerance", ParamValue::Number(tol)),
                    ("kernel", ParamValue::Text(kernel.clone())),
                ];
                sets.extend(bench.sets.iter().map(|(k, v)| (k.as_str(), v.clone())));
                let g = load(&bench.graph, &sets, &registry)?;
                let grid = match param(&g, "grid") {
                    Some(ParamValue::Numbers(v)) => v[0] as u32,
                    _ => 0,
                };
                let run = timed(&gpu, &g, l, n, "velocities", bench.reps)?;
                let noise_ms = if bench.noise {
                    sets.push(("temperature", ParamValue::Number(1.0)));
                    let g = load(&bench.graph, &sets, &registry)?;
                    let noisy = timed(&gpu, &g, l, n, "fluctuating_velocities", bench.reps)?;
                    Some((ms(noisy.end_to_end()), ms(noisy.launch_sum())))
                } else {
                    None
                };
                let e2e_ms = ms(run.end_to_end());
                let (uammd, ratio) = UAMMD
                    .iter()
                    .find(|u| {
                        kernel == "gaussian"
                            && (u.0 / tol - 1.0).abs() < 1e-9
                            && u.1 == l
                            && u.2 == n
                    })
                    .map(|u| (format!("{:.3}", u.3), format!("{:.2}", e2e_ms / u.3)))
                    .unwrap_or_else(|| ("-".into(), "-".into()));
                let row = Row {
                    kernel: kernel.clone(),
                    tolerance: tol,
                    l,
                    n,
                    grid,
                    support: support_text(&g, kernel),
                    e2e_ms,
                    launches_ms: ms(run.launch_sum()),
                    noise_ms,
                    self_max,
                    self_mean,
                    pair,
                    memory: run.memory,
                };
                let (noise_e2e, noise_launches) = match row.noise_ms {
                    Some((e2e, launches)) => (format!("{e2e:.4}"), format!("{launches:.4}")),
                    None => ("-".into(), "-".into()),
                };
                outln!(
                    "{:<8} {:>6.0e} {:>6} {:>8} {:>5} {:>4} {:>9.4} {:>11.4} {:>8.2} {:>9} {:>11} {:>9.2e} {:>9.2e} {:>9} {:>8.0} {:>9} {:>7}",
                    row.kernel,
                    row.tolerance,
                    row.l,
                    row.n,
                    row.grid,
                    row.support,
                    row.e2e_ms,
                    row.launches_ms,
                    row.e2e_ms * 1e6 / row.n as f64,
                    noise_e2e,
                    noise_launches,
                    row.self_max,
                    row.self_mean,
                    row.pair
                        .map(|p| format!("{p:.2e}"))
                        .unwrap_or_else(|| "-".into()),
                    row.memory as f64 / (1u64 << 20) as f64,
                    uammd,
                    ratio
                );
                rows.push(row);
            }
        }
    }
    if let Some(path) = &bench.plot {
        plot(path, &rows).map_err(|message| BenchError::Plot {
            path: path.clone(),
            message,
        })?;
        outln!("plot: {}", path.display());
    }
    Ok(())
}

/// Error (worst self-mobility) against the end-to-end time, one series per kernel and
/// particle count, UAMMD's Gaussian figures as crosses at their reported errors.
fn plot(path: &Path, rows: &[Row]) -> Result<(), String> {
    use plotters::prelude::*;
    let err = |e: &dyn std::fmt::Display| e.to_string();
    // Written next to the target and renamed: never a half-written plot.
    let tmp = path.with_extension("svg.tmp");
    {
        let root = SVGBackend::new(&tmp, (900, 600)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let times: Vec<f64> = rows
            .iter()
            .map(|r| r.e2e_ms)
            .chain(UAMMD.iter().map(|u| u.3))
            .collect();
        let errors: Vec<f64> = rows.iter().map(|r| r.self_max.max(1e-9)).collect();
        let (tmin, tmax) = times
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(a, b), &t| (a.min(t), b.max(t)));
        let (emin, emax) = errors
            .iter()
            .chain([2e-3, 8e-4, 4e-5].iter())
            .fold((f64::INFINITY, 0.0f64), |(a, b), &e| (a.min(e), b.max(e)));
        let mut chart = ChartBuilder::on(&root)
            .caption(
                "FCM: self-mobility error against GPU time per M F",
                ("sans-serif", 20),
            )
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(
                (tmin / 1.5..tmax * 1.5).log_scale(),
                (emin / 2.0..emax * 2.0).log_scale(),
            )
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc("GPU time per evaluation, end to end (ms)")
            .y_desc("worst relative self-mobility error")
            .draw()
            .map_err(|e| err(&e))?;
        let palette = [RED, BLUE, GREEN, MAGENTA, CYAN, BLACK];
        let mut series: Vec<(String, u32)> = Vec::new();
        for r in rows {
            if !series.iter().any(|(k, n)| *k == r.kernel && *n == r.n) {
                series.push((r.kernel.clone(), r.n));
            }
        }
        let kernels: Vec<&String> = {
            let mut k: Vec<&String> = rows.iter().map(|r| &r.kernel).collect();
            k.dedup();
            k
        };
        for (kernel, n) in &series {
            let color =
                palette[kernels.iter().position(|k| *k == kernel).unwrap_or(0) % palette.len()];
            let mut pts: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| &r.kernel == kernel && r.n == *n)
                .map(|r| (r.e2e_ms, r.self_max.max(1e-9)))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            chart
                .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))
                .map_err(|e| err(&e))?
                .label(format!("{kernel}, N = {n}"))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
            chart
                .draw_series(pts.iter().map(|&p| Circle::new(p, 4, color.filled())))
                .map_err(|e| err(&e))?;
        }
        let uammd_err = |tol: f64| {
            if tol > 5e-3 {
                2e-3
            } else if tol > 5e-4 {
                8e-4
            } else {
                4e-5
            }
        };
        chart
            .draw_series(
                UAMMD
                    .iter()
                    .map(|u| Cross::new((u.3, uammd_err(u.0)), 6, BLACK.stroke_width(2))),
            )
            .map_err(|e| err(&e))?
            .label("UAMMD FCM (H200, its reported errors)")
            .legend(|(x, y)| Cross::new((x + 10, y), 5, BLACK));
        chart
            .configure_series_labels()
            .border_style(BLACK)
            .background_style(WHITE.mix(0.9))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(|e| err(&e))?;
        root.present().map_err(|e| err(&e))?;
    }
    std::fs::rename(&tmp, path).map_err(|e| err(&e))
}
