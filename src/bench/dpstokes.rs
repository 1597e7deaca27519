//! `mesoflow bench dpstokes`: the doubly periodic Stokes mobility (graphs/dpstokes.json)
//! per wall mode and size: one M F end to end, its grid and memory, the error it reaches,
//! and fcm.json's M F on a periodic grid of (at least) the same number of points with the
//! same window family and tolerance, timed in the same run. N particles, a = 1, heights
//! uniform in [1.5 a, 10 a] (zmin = 0, zmax = 11.5: a slit's top wall 1.5 a above the
//! highest), box side 128 sqrt(N / 10^5). The error: one particle at 2 a and 6 a in a box of side 128,
//! its parallel and perpendicular self-mobility against Rotne-Prager-Blake (bottom wall),
//! against the doubly periodic sum of its window (no wall; `open_self`, f64), none for
//! the slit (no closed form), as the largest relative difference. With
//! MESOFLOW_BENCH_DISPATCHES the per-dispatch times, and the two boundary-value solves'
//! rate: the words they must read and write once (f and y, the per-k tables) over their
//! time, in GB/s (the chain's). `slab` (`--slab auto,fused,lanes,staged,chain`): a row per way of
//! solving between the Chebyshev transforms (lib/dpstokes_mobility.json's param), the
//! fcm.json time shared.

use std::f64::consts::PI;
use std::path::PathBuf;

use mesoflow::exec::Program;
use mesoflow::expr::ParamValue;
use mesoflow::gpu::{GpuContext, KernelCache};
use mesoflow::graph::Graph;
use mesoflow::node::Registry;
use mesoflow::nodes::spread::window::Window;
use mesoflow::nodes::stokes_slab::open_self_mobility;

use super::fcm::{Rng, load, mobility_inputs, param, plan_for, velocities};
use super::{BenchError, end_to_end_clock, ms, open_gpu, time_loaded};

pub struct DpStokesBench {
    pub graph: PathBuf,
    pub fcm_graph: PathBuf,
    pub walls: Vec<String>,
    pub sizes: Vec<u32>,
    pub tolerance: f64,
    pub kernel: String,
    /// lib/dpstokes_mobility.json's `slab` per row: auto, fused, lanes, staged, chain.
    pub slab: Vec<String>,
    /// dpstokes.json's spread_kernel (auto, workgroup, lanes).
    pub spread_kernel: String,
    pub reps: u64,
}

const ZMAX: f64 = 11.5;

fn numbers(g: &Graph, name: &str) -> Vec<f64> {
    match param(g, name) {
        Some(ParamValue::Numbers(v)) => v,
        Some(ParamValue::Number(x)) => vec![x],
        _ => Vec::new(),
    }
}

/// The open mode's reference for graph `g` in a box of side l: the doubly periodic sum
/// of its force window's Green function (`stokes_slab::open_self_mobility`, f64).
fn open_self(g: &Graph, l: f64) -> (f64, f64) {
    let width = numbers(g, "width")[0];
    let support = numbers(g, "support")[0] as u32;
    let (window, kmax) = match param(g, "kernel") {
        Some(ParamValue::Text(k)) if k == "gaussian" => (
            Window::Gaussian {
                sigma: width,
                support,
            },
            37f64.sqrt() / width,
        ),
        _ => {
            let beta = numbers(g, "beta")[0];
            (
                Window::es_with_half_width(beta, support, width),
                3.0 * beta / width,
            )
        }
    };
    open_self_mobility(|k| window.transform(k, 1.0), kmax, l, l)
}

/// The largest relative self-mobility error at 2 a and 6 a (None for the slit).
fn accuracy(
    gpu: &GpuContext,
    bench: &DpStokesBench,
    registry: &Registry,
    walls: &str,
) -> Result<Option<f64>, BenchError> {
    if walls == "slit" {
        return Ok(None);
    }
    let l = 128.0;
    let g = load(&bench.graph, &sets(walls, l, bench), registry)?;
    let plan = plan_for(gpu, &g, 1)?;
    let mut program = Program::compile(gpu, &g, &plan, &mut KernelCache::default())?;
    let t0 = 1.0 / (6.0 * PI);
    let open = (walls == "none").then(|| open_self(&g, l));
    let mut worst: f64 = 0.0;
    for h in [2.0, 6.0] {
        let p = [[0.3, -0.2, h]];
        let par = velocities(&mut program, &p, &[[1.0, 0.0, 0.0]])?[0][0];
        let perp = velocities(&mut program, &p, &[[0.0, 0.0, 1.0]])?[0][2];
        let want = match open {
            Some((xx, zz)) => (xx, zz),
            None => {
                let s = 1.0 / h;
                (
                    t0 * (1.0 - 9.0 / 16.0 * s + s.powi(3) / 8.0 - s.powi(5) / 16.0),
                    t0 * (1.0 - 9.0 / 8.0 * s + s.powi(3) / 2.0 - s.powi(5) / 8.0),
                )
            }
        };
        worst = worst
            .max((par - want.0).abs() / want.0)
            .max((perp - want.1).abs() / want.1);
    }
    Ok(Some(worst))
}

fn sets(walls: &str, l: f64, bench: &DpStokesBench) -> Vec<(&'static str, ParamValue)> {
    sets_with(walls, l, bench, "auto")
}

fn sets_with(
    walls: &str,
    l: f64,
    bench: &DpStokesBench,
    slab: &str,
) -> Vec<(&'static str, ParamValue)> {
    vec![
        ("slab", ParamValue::Text(slab.to_string())),
        ("kernel", ParamValue::Text(bench.kernel.clone())),
        (
            "spread_kernel",
            ParamValue::Text(bench.spread_kernel.clone()),
        ),
        ("box", ParamValue::Numbers(vec![l, l])),
        ("zmin", ParamValue::Number(0.0)),
        ("zmax", ParamValue::Number(ZMAX)),
        ("walls", ParamValue::Text(walls.to_string())),
        ("tolerance", ParamValue::Number(bench.tolerance)),
    ]
}

pub fn run(bench: &DpStokesBench) -> Result<(), BenchError> {
    let gpu = open_gpu(bench.reps)?;
    let registry = mesoflow::nodes::registry();
    outln!(
        "dpstokes.json M F at tolerance {}, {} windows, spread_kernel {}: a = 1, eta = 1, heights uniform in [1.5, 10], zmin 0, zmax {ZMAX}, box side 128 sqrt(N / 10^5); time: median over {} runs end to end ({}); fcm.json (the same window family and tolerance) on a periodic grid of at least the same points, same N; error: the largest relative self-mobility error at h = 2 a and 6 a (L = 128; bottom: against Rotne-Prager-Blake, none: against the doubly periodic f64 sum, slit: -)",
        bench.tolerance,
        bench.kernel,
        bench.spread_kernel,
        bench.reps,
        end_to_end_clock(&gpu)
    );
    outln!(
        "{:>7} {:>6} {:>8} {:>7} {:>16} {:>10} {:>10} {:>16} {:>10} {:>6} {:>9}",
        "walls",
        "slab",
        "N",
        "L",
        "grid",
        "memory MB",
        "e2e ms",
        "fcm grid",
        "fcm ms",
        "ratio",
        "error"
    );
    for walls in &bench.walls {
        let error = accuracy(&gpu, bench, &registry, walls)?;
        for &n in &bench.sizes {
            let l = 128.0 * (n as f64 / 1e5).sqrt();
            let g = load(&bench.graph, &sets(walls, l, bench), &registry)?;
            let grid = numbers(&g, "grid");
            let points = numbers(&g, "points").first().copied().unwrap_or(0.0);
            let mut rng = Rng(0x9E37_79B9_7F4A_7C15 ^ n as u64);
            let x: Vec<[f64; 3]> = (0..n)
                .map(|_| {
                    let p = [0, 1].map(|_| (rng.uniform() - 0.5) * l);
                    [p[0], p[1], 1.5 + 8.5 * rng.uniform()]
                })
                .collect();
            let f: Vec<[f64; 3]> = (0..n)
                .map(|_| [0, 1, 2].map(|_| rng.uniform() - 0.5))
                .collect();
            let inputs = mobility_inputs(&x, &f);
            // fcm.json on a periodic grid of at least as many points: the DP grid's x, y
            // and the FFT-friendly size above its Chebyshev points along z; the same
            // window family (FCM's ES at the tolerance ties its radius to this grid, so
            // it runs on any; its Gaussian needs a grid as fine as its own rule's).
            let nz = mesoflow::nodes::fft::next_friendly(points as u32) as f64;
            let hx = l / grid[0];
            let fcm = load(
                &bench.fcm_graph,
                &[
                    ("box", ParamValue::Numbers(vec![l, l, nz * hx])),
                    ("grid", ParamValue::Numbers(vec![grid[0], grid[1], nz])),
                    ("tolerance", ParamValue::Number(bench.tolerance)),
                    ("kernel", ParamValue::Text(bench.kernel.clone())),
                ],
                &registry,
            )?;
            let fcm_x: Vec<[f64; 3]> = x
                .iter()
                .map(|p| [p[0], p[1], p[2] - 0.5 * nz * hx])
                .collect();
            let fcm_inputs = mobility_inputs(&fcm_x, &f);
            let fcm_run = time_loaded(
                &gpu,
                &fcm,
                &fcm_inputs,
                Some(vec!["velocities".into()]),
                bench.reps,
                true,
            )?;
            for slab in &bench.slab {
                let g = load(&bench.graph, &sets_with(walls, l, bench, slab), &registry)?;
                let run = time_loaded(
                    &gpu,
                    &g,
                    &inputs,
                    Some(vec!["velocities".into()]),
                    bench.reps,
                    true,
                )?;
                let (t, tf) = (run.end_to_end(), fcm_run.end_to_end());
                outln!(
                    "{:>7} {:>6} {:>8} {:>7.1} {:>16} {:>10.1} {:>10.4} {:>16} {:>10.4} {:>6.2} {:>9}",
                    walls,
                    slab,
                    n,
                    l,
                    format!("{}x{}x{}", grid[0], grid[1], points),
                    run.memory as f64 / 1e6,
                    ms(t),
                    format!("{}x{}x{}", grid[0], grid[1], nz),
                    ms(tf),
                    t.as_secs_f64() / tf.as_secs_f64(),
                    error.map_or("-".to_string(), |e| format!("{e:.2e}"))
                );
                if std::env::var_os("MESOFLOW_BENCH_DISPATCHES").is_some() {
                    // The boundary-value solves: f and y (2 words per complex value, nk values
                    // per z level), the per-k tables (5 nz + 6 words per k).
                    let nk = ((grid[0] / 2.0).floor() + 1.0) * grid[1];
                    for timing in &run.timings {
                        out!("{}", timing.breakdown());
                        // The pressure's solve has 1 component, the velocity's 3.
                        let comps = if timing.label.contains("pressure") {
                            1.0
                        } else {
                            3.0
                        };
                        for (kernel, median, _) in &timing.dispatches {
                            if kernel.contains("bvp") {
                                let words = nk * (2.0 * 2.0 * comps * points + 5.0 * points + 6.0);
                                outln!(
                                    "      {kernel} ({comps} components): {:.1} GB/s at the words it reads and writes once",
                                    4.0 * words / median.as_secs_f64() / 1e9
                                );
                            }
                        }
                    }
                }
            }
        }
    }
    Ok(())
}
