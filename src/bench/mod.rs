//! `mesoflow bench ...`: benchmarks meant for the GPU machine. Each prints one table;
//! `benches/gpu.sh SUITE` runs them with the peers measured in the same call (the PyTorch
//! scripts, CUDA), and BENCHMARKS.md keeps the current tables.
//!
//! Node benchmarks go through the engine like any graph: [`time_loaded`] plans and
//! compiles a graph and times it twice, per launch (each launch in a compute pass of its
//! own, between GPU timestamps: where the time goes) and per step end to end (the step's
//! dispatches in one pass as a normal run records them, first to last timestamp: the
//! time of the whole call, gaps between kernels included, as a peer timed with CUDA
//! events around its call is measured). Tables show both; comparisons with peers use
//! the end-to-end figure.
//!
//! Nothing here depends on the command line: `cli` parses the arguments into a
//! [`BenchCommand`] and wraps [`BenchError`].

mod disks;
mod dpstokes;
mod fcm;
mod fft;
mod mpcd;
mod nbody;
mod overhead;
mod poisson;
mod primitives;
mod pse;
mod reduce;
mod spread;

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::Subcommand;
use thiserror::Error;

use mesoflow::exec::{ExecError, Profile, Program, RunOptions};
use mesoflow::expr::{self, OverrideError, ParamValue};
use mesoflow::gpu::{CompileError, GpuContext, GpuError, KernelCache};
use mesoflow::graph::{self, Graph, LoadOptions, Problems};
use mesoflow::node;
use mesoflow::plan::{self, PlanOptions};
use mesoflow::value::{HostArray, RefArray, ValueType};

/// A failure of a benchmark.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum BenchError {
    /// A bad argument.
    #[error("{0}")]
    Args(String),
    #[error("--set {0}")]
    Overrides(#[from] OverrideError),
    /// A graph file that does not load, or a graph that does not plan.
    #[error(transparent)]
    Graph(#[from] Problems),
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error(transparent)]
    Exec(#[from] ExecError),
    #[error("a bench kernel: {0}")]
    Kernel(#[from] CompileError),
    #[error("{context}: {source}")]
    Io {
        context: String,
        source: std::io::Error,
    },
    /// A node's f64 reference could not be computed for the bench's own inputs.
    #[error("the f64 reference of `{kind}`: {message}")]
    Reference { kind: String, message: String },
    /// A result failed its check (so that a fast wrong kernel does not pass).
    #[error("{0}")]
    Wrong(String),
    #[error("--plot {path}: {message}")]
    Plot { path: PathBuf, message: String },
}

impl BenchError {
    /// Whether the failure lies in what the user gave (arguments, graph files, params)
    /// rather than in running.
    pub fn is_bad_input(&self) -> bool {
        matches!(
            self,
            BenchError::Args(_) | BenchError::Overrides(_) | BenchError::Graph(_)
        )
    }

    fn io(context: impl Into<String>) -> impl FnOnce(std::io::Error) -> BenchError {
        let context = context.into();
        move |source| BenchError::Io { context, source }
    }
}

/// GPU time of one launch of a timed graph.
#[derive(Clone, Debug)]
pub struct Timing {
    pub label: String,
    pub median: Duration,
    /// Mean over the timed steps: the amortised cost of a launch whose dispatches run on
    /// some steps only (`Period`, or the last step only), which its median does not show.
    pub mean: Duration,
    /// With MESOFLOW_BENCH_DISPATCHES set: each dispatch's kernel, median and mean time
    /// (each in a pass of its own, so their sum is a little above `median`; the mean
    /// shows what a dispatch that runs every K steps costs amortised).
    pub dispatches: Vec<(String, Duration, Duration)>,
    /// Only outputs read the launch: it ran on the run's last step only (one sample).
    pub last_step_only: bool,
}

impl Timing {
    /// The per-dispatch breakdown as indented lines (empty without it).
    pub fn breakdown(&self) -> String {
        self.dispatches
            .iter()
            .enumerate()
            .map(|(i, (k, median, mean))| {
                format!(
                    "      {} #{i:<2} {:<44} {:>10.4} ms (mean {:.4})\n",
                    self.label,
                    k,
                    median.as_secs_f64() * 1e3,
                    mean.as_secs_f64() * 1e3
                )
            })
            .collect()
    }
}

fn median_duration(samples: &[Duration]) -> Duration {
    let mut s = samples.to_vec();
    s.sort();
    s.get(s.len() / 2).copied().unwrap_or_default()
}

fn mean_duration(samples: &[Duration]) -> Duration {
    samples.iter().sum::<Duration>() / (samples.len().max(1) as u32)
}

/// A timed graph: per-launch and end-to-end GPU times, and the outputs of the last step.
pub struct TimedRun {
    pub timings: Vec<Timing>,
    /// Each loop's iterations per step over the timed runs (`Program::loop_iterations`).
    pub loops: Vec<(String, Vec<u32>)>,
    /// Each timed step end to end: first to last timestamp of the step's one compute
    /// pass, or the host's time from submission to the end of the wait for a graph with
    /// loops or on a device without timestamp queries.
    pub steps: Vec<Duration>,
    /// The mean step of a run of as many steps, unprofiled (host clock): what a
    /// simulation's step costs, where the host records a step while the one before runs
    /// (chained loops) or several steps go out together.
    pub run_step: Duration,
    pub outputs: BTreeMap<String, HostArray>,
    /// The plan's GPU memory in bytes.
    pub memory: u64,
}

impl TimedRun {
    /// Sum of the launches' medians: one step's GPU time without the gaps between
    /// kernels (each launch timed in a pass of its own; those only outputs read, which
    /// run on a run's last step only, left out).
    pub fn launch_sum(&self) -> Duration {
        self.timings
            .iter()
            .filter(|t| !t.last_step_only)
            .map(|t| t.median)
            .sum()
    }

    /// Sum of the launches' means: one step amortised over the timed steps.
    pub fn mean_launch_sum(&self) -> Duration {
        self.timings.iter().map(|t| t.mean).sum()
    }

    /// Median step end to end: the time of one call, as peers are timed.
    pub fn end_to_end(&self) -> Duration {
        median_duration(&self.steps)
    }

    /// Mean step end to end (amortising dispatches that run on some steps only).
    pub fn mean_end_to_end(&self) -> Duration {
        mean_duration(&self.steps)
    }
}

/// The GPU of a bench timed `reps` times (refused when 0), its adapter line printed.
fn open_gpu(reps: u64) -> Result<GpuContext, BenchError> {
    if reps == 0 {
        return Err(BenchError::Args("--reps must be positive".into()));
    }
    let gpu = GpuContext::new()?;
    outln!("adapter: {}", gpu.caps.summary());
    Ok(gpu)
}

/// How end-to-end figures of loop-free graphs are taken on this device, for table
/// headers (a graph with loops is timed on the host clock anyway: `TimedRun::steps`).
fn end_to_end_clock(gpu: &GpuContext) -> &'static str {
    if gpu.caps.timestamps {
        "GPU timestamps"
    } else {
        "host clock"
    }
}

/// Runs the program back to back for at least half a second, doubling the steps, so the
/// GPU's clocks are up before timing: a GPU that idled while the host prepared data runs
/// its first milliseconds of work at reduced clocks (seen on an H100: a 3-D FFT timed 4x
/// slower right after the host had built its input).
fn warm_up(program: &mut Program) -> Result<(), BenchError> {
    let start = Instant::now();
    let mut steps = 2;
    while start.elapsed() < Duration::from_millis(500) {
        program.run(&RunOptions {
            steps,
            profile: Profile::Off,
            progress: false,
        })?;
        steps = (steps * 2).min(1 << 14);
    }
    Ok(())
}

/// Loads a graph given as JSON text (through a temporary file) with its defaults.
fn load_text(graph_json: &str) -> Result<Graph, BenchError> {
    let dir = std::env::temp_dir().join(format!("mesoflow-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(BenchError::io(dir.display().to_string()))?;
    let file = dir.join("timed.json");
    std::fs::write(&file, graph_json).map_err(BenchError::io(file.display().to_string()))?;
    let loaded = graph::load(&file, &mesoflow::nodes::registry(), &LoadOptions::default());
    let _ = std::fs::remove_dir_all(&dir);
    Ok(loaded?)
}

/// [`time_loaded`] for a graph given as JSON text, every output.
pub fn time_graph(
    gpu: &GpuContext,
    graph_json: &str,
    inputs: &BTreeMap<String, HostArray>,
    reps: u64,
    fuse: bool,
) -> Result<TimedRun, BenchError> {
    time_loaded(gpu, &load_text(graph_json)?, inputs, None, reps, fuse)
}

/// Plans and compiles `g` for these outputs (all when `None`), warms the GPU up (at
/// least half a second of back-to-back runs), then runs `reps` steps timed per launch and
/// `reps` steps timed end to end (and with MESOFLOW_BENCH_DISPATCHES `reps` more timed
/// per dispatch).
pub fn time_loaded(
    gpu: &GpuContext,
    g: &Graph,
    inputs: &BTreeMap<String, HostArray>,
    outputs: Option<Vec<String>>,
    reps: u64,
    fuse: bool,
) -> Result<TimedRun, BenchError> {
    let engine = Engine {
        fuse,
        in_place: true,
        chain_loops: true,
    };
    time_loaded_with(gpu, g, inputs, outputs, reps, engine)
}

/// What the planner and executor may do, to time what each saves.
pub struct Engine {
    /// Fuse element-wise chains (`PlanOptions::fuse`).
    pub fuse: bool,
    /// Outputs in place of their inputs (`PlanOptions::in_place`).
    pub in_place: bool,
    /// A step's loops chained in one submission (`Program::set_chain_loops`).
    pub chain_loops: bool,
}

/// [`time_loaded`] with the engine's choices given.
pub fn time_loaded_with(
    gpu: &GpuContext,
    g: &Graph,
    inputs: &BTreeMap<String, HostArray>,
    outputs: Option<Vec<String>>,
    reps: u64,
    engine: Engine,
) -> Result<TimedRun, BenchError> {
    let opts = PlanOptions {
        outputs,
        inputs: inputs.iter().map(|(k, v)| (k.clone(), v.ty)).collect(),
        fuse: engine.fuse,
        in_place: engine.in_place,
    };
    let p = plan::plan(g, &opts, &gpu.caps)?;
    let mut cache = KernelCache::default();
    let mut program = Program::compile(gpu, g, &p, &mut cache)?;
    program.set_chain_loops(engine.chain_loops);
    program.upload(inputs)?;
    warm_up(&mut program)?;
    let timed = |program: &mut Program, profile| {
        program.run(&RunOptions {
            steps: reps,
            profile,
            progress: false,
        })
    };
    let per_launch = timed(&mut program, Profile::Launches)?;
    let per_step = timed(&mut program, Profile::Steps)?;
    let run = program.run_on(&RunOptions {
        steps: reps,
        profile: Profile::Off,
        progress: false,
    })?;
    let per_dispatch = if std::env::var_os("MESOFLOW_BENCH_DISPATCHES").is_some() {
        timed(&mut program, Profile::Dispatches)?.profile
    } else {
        Vec::new()
    };
    let outputs = program.read_outputs()?.into_iter().collect();
    let timings = per_launch
        .profile
        .iter()
        .map(|r| Timing {
            label: r.label.clone(),
            median: r.median(),
            // Amortised over the steps: a launch only outputs read ran once.
            mean: r.total / (if r.last_step_only { reps } else { r.calls }).max(1) as u32,
            dispatches: per_dispatch
                .iter()
                .find(|d| d.label == r.label)
                .map(|d| {
                    d.dispatch_samples
                        .iter()
                        .map(|(kernel, samples)| {
                            (
                                kernel.clone(),
                                median_duration(samples),
                                mean_duration(samples),
                            )
                        })
                        .collect()
                })
                .unwrap_or_default(),
            last_step_only: r.last_step_only,
        })
        .collect();
    Ok(TimedRun {
        timings,
        loops: program.loop_iterations().to_vec(),
        steps: per_step.step_samples,
        run_step: run.wall / reps as u32,
        outputs,
        memory: p.memory.total(),
    })
}

#[derive(Subcommand, Debug)]
pub enum BenchCommand {
    /// Executor overhead: a chain of tiny unfused pointwise nodes against raw wgpu.
    Overhead {
        /// Nodes in the chain.
        #[arg(long, default_value_t = 1000)]
        nodes: usize,
        /// Elements per node (tiny, so that launch cost dominates).
        #[arg(long, default_value_t = 256)]
        elements: u32,
        /// Repetitions of the whole chain.
        #[arg(long, default_value_t = 50)]
        reps: u64,
    },
    /// Spreading and interpolation per particle (UAMMD's setups) on an n^3 grid.
    Spread {
        #[arg(long, default_value_t = 128)]
        cells: u32,
        #[arg(long, default_value_t = 20)]
        reps: u64,
        /// Workgroup sizes to time (64, 128, 256).
        #[arg(long, value_delimiter = ',', default_values_t = [256])]
        workgroups: Vec<u32>,
        /// Rows of the table to run (0-7, in its order; default all).
        #[arg(long, value_delimiter = ',')]
        cases: Vec<usize>,
    },
    /// Sum (blocked and compensated), dot and max of n f32.
    Reduce {
        #[arg(long, default_value_t = 100_000_000)]
        n: u32,
        #[arg(long, default_value_t = 20)]
        reps: u64,
    },
    /// Stable radix sort of n random u32 keys with their permutation (the `sort` node).
    Sort {
        #[arg(long, default_value_t = 10_000_000)]
        n: u32,
        #[arg(long, default_value_t = 20)]
        reps: u64,
        /// The sort's `variant` (auto, tile4096, tile2048, subgroup, portable), or
        /// `all`: each in turn on the same keys, one row each.
        #[arg(long, default_value = "auto")]
        variant: String,
    },
    /// Exclusive scan of n random u32 (the `scan` node).
    Scan {
        #[arg(long, default_value_t = 100_000_000)]
        n: u32,
        #[arg(long, default_value_t = 20)]
        reps: u64,
        /// Kernel path: auto, subgroup or portable.
        #[arg(long, default_value = "auto")]
        variant: String,
    },
    /// 3-D real FFTs (rfft then irfft) on cubic grids, with their error against rustfft.
    Fft {
        /// Cubic grid sizes.
        #[arg(long, value_delimiter = ',', default_values_t = [64, 96, 128, 162, 189, 192, 216, 256, 375, 384])]
        sizes: Vec<u32>,
        /// Components transformed together.
        #[arg(long, default_value_t = 3)]
        comps: u32,
        /// Timed runs per size (the median is reported).
        #[arg(long, default_value_t = 20)]
        reps: u64,
        /// Largest size whose forward error is checked against the f64 host reference
        /// (seconds and gigabytes of host work at 384).
        #[arg(long, default_value_t = 512)]
        max_ref: u32,
        /// Fold a spectral_filter between the transforms (a convolution's cost).
        #[arg(long)]
        filter: bool,
    },
    /// The FCM graph's speed against its error per kernel and tolerance (UAMMD's sizes by
    /// default): GPU time of one M F, self- and pair-mobility errors against f64 references.
    Fcm {
        /// The FCM graph file.
        #[arg(long, default_value = "graphs/fcm.json")]
        graph: PathBuf,
        /// Kernels (gaussian, es, peskin3, peskin4, peskin6), or `all`.
        #[arg(long, value_delimiter = ',', default_values_t = ["gaussian".to_string()])]
        kernels: Vec<String>,
        #[arg(long, value_delimiter = ',', default_values_t = [1e-2, 1e-3, 1e-4])]
        tolerances: Vec<f64>,
        /// Box sides and particle counts as L:N (default: UAMMD's benchmark sizes for each
        /// tolerance).
        #[arg(long, value_delimiter = ',')]
        sizes: Vec<String>,
        /// Also time M F plus the Fourier-space noise (kT = 1).
        #[arg(long)]
        noise: bool,
        #[arg(long, default_value_t = 20)]
        reps: u64,
        /// Side of the cubic box (in radii) the errors are measured in.
        #[arg(long, default_value_t = 32.0)]
        error_box: f64,
        /// Random positions for the self-mobility error.
        #[arg(long, default_value_t = 16)]
        error_samples: usize,
        /// Draw error against time into this SVG file.
        #[arg(long)]
        plot: Option<PathBuf>,
        /// Other graph params for the timed runs (NAME=VALUE, as in `run`).
        #[arg(long = "set")]
        sets: Vec<String>,
        /// Plan deterministic runs (as `run --deterministic`): what bitwise
        /// reproducibility costs.
        #[arg(long)]
        deterministic: bool,
    },
    /// MPCD particle-steps per second (3D SRD; 2D; with spheres) at several particle counts.
    Mpcd {
        /// The MPCD graph file (default: graphs/mpcd.json; mpcd2d.json with --dims 2;
        /// mpcd_spheres.json with --spheres).
        #[arg(long)]
        graph: Option<PathBuf>,
        /// Dimensions: 3 (a cubic box) or 2 (a square).
        #[arg(long, default_value_t = 3)]
        dims: u32,
        /// Spheres on a cubic lattice (a cube: 1, 8, 64...; 3D).
        #[arg(long, default_value_t = 0)]
        spheres: u32,
        /// The spheres' radius.
        #[arg(long, default_value_t = 4.0)]
        sphere_radius: f64,
        /// Particle counts (rounded to whole cubic boxes of cells).
        #[arg(long, value_delimiter = ',', default_values_t = [1_000_000u64, 10_000_000, 50_000_000])]
        sizes: Vec<u64>,
        /// Mean particles per cell.
        #[arg(long, default_value_t = 10.0)]
        density: f64,
        #[arg(long, default_value_t = 20)]
        reps: u64,
        /// Other graph params (NAME=VALUE, as in `run`).
        #[arg(long = "set")]
        sets: Vec<String>,
    },
    /// Doubly periodic Stokes (dpstokes.json) per wall mode and size: M F end to end, grid,
    /// memory, the self-mobility error, and fcm.json on a grid of the same points beside it.
    Dpstokes {
        /// The DP Stokes graph file.
        #[arg(long, default_value = "graphs/dpstokes.json")]
        graph: PathBuf,
        /// The FCM graph timed beside it.
        #[arg(long, default_value = "graphs/fcm.json")]
        fcm_graph: PathBuf,
        /// Wall modes.
        #[arg(long, value_delimiter = ',', default_values_t = ["bottom".to_string(), "slit".to_string(), "none".to_string()])]
        walls: Vec<String>,
        /// Particle counts (box side 128 sqrt(N / 10^5)).
        #[arg(long, value_delimiter = ',', default_values_t = [10000u32, 100000, 1000000])]
        sizes: Vec<u32>,
        #[arg(long, default_value_t = 1e-3)]
        tolerance: f64,
        /// dpstokes.json's windows: es or gaussian.
        #[arg(long, default_value = "es")]
        kernel: String,
        /// The solve between the Chebyshev transforms, a row each: auto (staged up to 4096
        /// wave numbers, fused past them up to slab_solve's points), fused (slab_solve, one
        /// kernel, a wave number's lines in registers), lanes (slab_solve's lanes kernel, a
        /// wave number's line over a segment of subgroup lanes), staged (slab_solve's staged
        /// kernel, the forward transform along z inside) or chain (the nodes one by one);
        /// e.g. `--slab fused,lanes,staged,chain`.
        #[arg(long, value_delimiter = ',', default_values_t = ["auto".to_string()])]
        slab: Vec<String>,
        /// dpstokes.json's spread_kernel, the kernels of spread_chebyshev and
        /// interpolate_chebyshev: auto, workgroup or lanes.
        #[arg(long, default_value = "auto")]
        spread_kernel: String,
        #[arg(long, default_value_t = 10)]
        reps: u64,
    },
    /// Brownian disks with a Delaunay mesh (bd_delaunay.json, S1): time per step split
    /// into forces, flips and overlap correction, the loops' iterations, and the
    /// long-range force's pair interactions per second.
    Disks {
        /// The graph file.
        #[arg(long, default_value = "graphs/bd_delaunay.json")]
        graph: PathBuf,
        /// S1 Table 1 configurations (c0 to c4).
        #[arg(long, value_delimiter = ',', default_values_t = ["c0".to_string()])]
        configs: Vec<String>,
        /// Force ranges: long (all pairs), short (cell list), verlet (short through a
        /// neighbour list).
        #[arg(long, value_delimiter = ',', default_values_t = ["long".to_string(), "short".to_string()])]
        ranges: Vec<String>,
        /// Disk counts (2^10 to 2^20 on a GPU; the mesh is built on the host).
        #[arg(long, value_delimiter = ',', default_values_t = [1024u32, 16384, 262144, 1048576])]
        sizes: Vec<u32>,
        /// Timed steps per size (after a warm-up).
        #[arg(long, default_value_t = 10)]
        reps: u64,
        /// Numbering of the start's disks: random (the lattice's sites drawn in random
        /// order), or lattice (the same sites in the lattice's row order). The graph
        /// numbers the disks in a Morton order of its own before the first step, so this
        /// changes the user's numbering only (and which noise each disk draws).
        #[arg(long, default_value = "random", value_parser = ["random", "lattice"])]
        order: String,
        /// Plan without in-place outputs (each flip evaluation copies the mesh and each
        /// flip loop iteration copies it back): to time what they save.
        #[arg(long)]
        no_in_place: bool,
        /// Run each step's loops with a host round trip each (the step's launches after a
        /// loop submitted once the host has read its status) instead of chained in one
        /// submission a step: to time what chaining saves.
        #[arg(long)]
        no_chain: bool,
    },
    /// Direct pair mobilities (rpy_open.json, rpy_wall.json; translation and grand):
    /// time, pair interactions per second and GFLOP/s at the kernels' flop counts.
    Nbody {
        /// The folder of rpy_open.json and rpy_wall.json.
        #[arg(long, default_value = "graphs")]
        graphs: PathBuf,
        /// Particle counts.
        #[arg(long, value_delimiter = ',', default_values_t = [1000, 10000, 100000])]
        sizes: Vec<u32>,
        #[arg(long, default_value_t = 10)]
        reps: u64,
    },
    /// Poisson speed against error: per tolerance and size the fastest split, its errors
    /// against an f64 Ewald sum, and fcm.json's M F timed beside it.
    Poisson {
        /// The Poisson graph file.
        #[arg(long, default_value = "graphs/poisson.json")]
        graph: PathBuf,
        /// The FCM graph timed beside it.
        #[arg(long, default_value = "graphs/fcm.json")]
        fcm_graph: PathBuf,
        #[arg(long, value_delimiter = ',', default_values_t = [1e-2, 1e-3, 1e-4, 1e-5])]
        tolerances: Vec<f64>,
        /// Ewald splits to try (0: unsplit); the fastest is reported.
        #[arg(long, value_delimiter = ',', default_values_t = [0.0, 0.2, 0.3, 0.4, 0.5, 0.7, 1.0])]
        splits: Vec<f64>,
        /// Box sides and charge counts as L:N (default 64:10000,128:100000,276:1000000).
        #[arg(long, value_delimiter = ',')]
        sizes: Vec<String>,
        #[arg(long, default_value_t = 20)]
        reps: u64,
        /// Side of the cubic box the errors are measured in.
        #[arg(long, default_value_t = 24.0)]
        error_box: f64,
        /// Other graph params (NAME=VALUE, as in `run`).
        #[arg(long = "set")]
        sets: Vec<String>,
    },
    /// PSE speed against error per split (time of one M F, with --noise also M F +
    /// M^(1/2) W; self- and pair-mobility errors against f64 references).
    Pse {
        /// The PSE graph file.
        #[arg(long, default_value = "graphs/pse.json")]
        graph: PathBuf,
        /// Ewald splitting parameters xi to measure.
        #[arg(long, value_delimiter = ',', default_values_t = [0.3, 0.4, 0.5, 0.6, 0.8, 1.0])]
        splits: Vec<f64>,
        #[arg(long, default_value_t = 1e-3)]
        tolerance: f64,
        /// Box sides and particle counts as L:N (default: UAMMD's, 64:10000,128:100000).
        #[arg(long, value_delimiter = ',')]
        sizes: Vec<String>,
        /// Also time M F + sqrt(2 kT) M^(1/2) W (kT = 1).
        #[arg(long)]
        noise: bool,
        #[arg(long, default_value_t = 20)]
        reps: u64,
        /// Side of the cubic box (in radii) the errors are measured in.
        #[arg(long, default_value_t = 24.0)]
        error_box: f64,
        /// Other graph params for the timed runs (NAME=VALUE, as in `run`).
        #[arg(long = "set")]
        sets: Vec<String>,
        /// Plan deterministic runs (as `run --deterministic`): what bitwise
        /// reproducibility costs.
        #[arg(long)]
        deterministic: bool,
    },
}

/// `--sizes` values L:N.
fn parse_sizes(sizes: &[String]) -> Result<Vec<(f64, u32)>, BenchError> {
    sizes
        .iter()
        .map(|s| {
            let parsed = s
                .split_once(':')
                .and_then(|(l, n)| Some((l.parse::<f64>().ok()?, n.parse::<u32>().ok()?)));
            parsed.filter(|(l, n)| *l > 0.0 && *n > 0).ok_or_else(|| {
                BenchError::Args(format!(
                    "--sizes `{s}`: expected L:N with L > 0 and N > 0 (e.g. 129:100000)"
                ))
            })
        })
        .collect()
}

/// `--set` values as graph param overrides, in the order given.
fn parse_sets(sets: &[String]) -> Result<Vec<(String, ParamValue)>, BenchError> {
    Ok(expr::parse_overrides(sets)?.into_iter().collect())
}

/// Runs one benchmark and prints its table.
pub fn run(cmd: BenchCommand) -> Result<(), BenchError> {
    match cmd {
        BenchCommand::Overhead {
            nodes,
            elements,
            reps,
        } => overhead::run(nodes, elements, reps),
        BenchCommand::Reduce { n, reps } => reduce::run(n, reps),
        BenchCommand::Spread {
            cells,
            reps,
            workgroups,
            cases,
        } => spread::run(cells, reps, &workgroups, &cases),
        BenchCommand::Sort { n, reps, variant } => primitives::sort(n, reps, &variant),
        BenchCommand::Scan { n, reps, variant } => primitives::scan(n, reps, &variant),
        BenchCommand::Fft {
            sizes,
            comps,
            reps,
            max_ref,
            filter,
        } => fft::run(&sizes, comps, reps, max_ref, filter),
        BenchCommand::Fcm {
            graph,
            kernels,
            tolerances,
            sizes,
            noise,
            reps,
            error_box,
            error_samples,
            plot,
            sets,
            deterministic,
        } => {
            let kernels = if kernels.iter().any(|k| k == "all") {
                mesoflow::nodes::spread::window::NAMES
                    .iter()
                    .map(|s| s.to_string())
                    .collect()
            } else {
                kernels
            };
            fcm::run(&fcm::FcmBench {
                graph,
                kernels,
                tolerances,
                sizes: parse_sizes(&sizes)?,
                noise,
                reps,
                error_box,
                error_samples,
                plot,
                sets: parse_sets(&sets)?,
                deterministic,
            })
        }
        BenchCommand::Mpcd {
            graph,
            dims,
            spheres,
            sphere_radius,
            sizes,
            density,
            reps,
            sets,
        } => mpcd::run(&mpcd::MpcdBench {
            graph,
            dims,
            spheres,
            sphere_radius,
            sizes,
            density,
            reps,
            sets: parse_sets(&sets)?,
        }),
        BenchCommand::Dpstokes {
            graph,
            fcm_graph,
            walls,
            sizes,
            tolerance,
            kernel,
            slab,
            spread_kernel,
            reps,
        } => dpstokes::run(&dpstokes::DpStokesBench {
            graph,
            fcm_graph,
            walls,
            sizes,
            tolerance,
            kernel,
            slab,
            spread_kernel,
            reps,
        }),
        BenchCommand::Disks {
            graph,
            configs,
            ranges,
            sizes,
            reps,
            order,
            no_in_place,
            no_chain,
        } => disks::run(&disks::DisksBench {
            graph,
            configs,
            ranges,
            sizes,
            reps,
            in_order: order == "lattice",
            in_place: !no_in_place,
            chain_loops: !no_chain,
        }),
        BenchCommand::Nbody {
            graphs,
            sizes,
            reps,
        } => nbody::run(&nbody::NbodyBench {
            graphs_dir: graphs,
            sizes,
            reps,
        }),
        BenchCommand::Poisson {
            graph,
            fcm_graph,
            tolerances,
            splits,
            sizes,
            reps,
            error_box,
            sets,
        } => poisson::run(&poisson::PoissonBench {
            graph,
            fcm_graph,
            tolerances,
            splits,
            sizes: if sizes.is_empty() {
                vec![(64.0, 10_000), (128.0, 100_000), (276.0, 1_000_000)]
            } else {
                parse_sizes(&sizes)?
            },
            reps,
            error_box,
            sets: parse_sets(&sets)?,
        }),
        BenchCommand::Pse {
            graph,
            splits,
            tolerance,
            sizes,
            noise,
            reps,
            error_box,
            sets,
            deterministic,
        } => pse::run(&pse::PseBench {
            graph,
            splits,
            tolerance,
            sizes: parse_sizes(&sizes)?,
            noise,
            reps,
            error_box,
            sets: parse_sets(&sets)?,
            deterministic,
        }),
    }
}

/// A node's f64 reference outputs (`cpu_reference`) for `params` and `inputs`: what the
/// benches check their GPU outputs against.
fn node_reference(
    kind: &str,
    params: &BTreeMap<String, ParamValue>,
    inputs: &[Option<RefArray>],
) -> Result<Vec<RefArray>, BenchError> {
    let failed = |message: String| BenchError::Reference {
        kind: kind.to_string(),
        message,
    };
    let registry = mesoflow::nodes::registry();
    let node_kind = registry
        .get(kind)
        .ok_or_else(|| failed("no such node kind".into()))?;
    let params =
        node::check_params(node_kind.params(), params).map_err(|e| failed(format!("{e:?}")))?;
    let built = node_kind
        .build(&params)
        .map_err(|e| failed(e.to_string()))?;
    let types: Vec<Option<ValueType>> = inputs.iter().map(|r| r.as_ref().map(|r| r.ty)).collect();
    // Output types only: the baseline adapter serves (the decisions do not change them).
    let sig = built
        .infer(&types, &mesoflow::gpu::DeviceCaps::baseline())
        .map_err(|e| failed(format!("{e:?}")))?;
    let mut out: Vec<_> = sig
        .outputs
        .iter()
        .map(|t| RefArray::new(*t, vec![0.0; t.words() as usize]))
        .collect();
    built.cpu_reference(inputs, &mut out, node::RefCtx::default());
    Ok(out)
}

/// Median of a sample (sorts it).
fn median(v: &mut [f64]) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Milliseconds of a duration, for tables.
fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}
