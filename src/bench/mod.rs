//! `mesoflow bench ...`: benchmarks meant for the GPU machine. Each prints one table
//! (BENCHMARKS.md records them with adapter and date); comparisons with other libraries
//! run in the same command through the scripts in `benches/`.
//!
//! Node benchmarks go through the engine like any graph: [`time_graph`] plans and
//! compiles a graph file and times each launch with GPU timestamps.

mod fcm;
mod fft;
mod mpcd;
mod primitives;
mod pse;
mod reduce;
mod spread;

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::Subcommand;

use crate::cli::CliError;
use crate::exec::{Profile, Program, RunOptions};
use crate::gpu::{Binding, CompileCtx, GpuContext, KernelCache, KernelSpec, WG_1D};
use crate::graph::{self, LoadOptions};
use crate::plan::{self, PlanOptions};
use crate::value::{HostArray, ValueType};

/// GPU time of one launch of a timed graph.
#[derive(Clone, Debug)]
pub struct Timing {
    pub label: String,
    pub median: Duration,
    /// Mean over the timed steps: the amortised cost of a launch whose dispatches run on
    /// some steps only (`Period`), which its median does not show.
    pub mean: Duration,
    pub min: Duration,
    /// With MESOFLOW_BENCH_DISPATCHES set: each dispatch's kernel, median and mean time
    /// (each in a pass of its own, so their sum is a little above `median`; the mean
    /// shows what a dispatch that runs every K steps costs amortised).
    pub dispatches: Vec<(String, Duration, Duration)>,
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

/// A timed graph run: per-launch GPU times and the outputs of the last step.
pub struct TimedRun {
    pub timings: Vec<Timing>,
    pub outputs: BTreeMap<String, HostArray>,
}

impl TimedRun {
    /// Sum of the launches' medians: the GPU time of one step.
    pub fn step_time(&self) -> Duration {
        self.timings.iter().map(|t| t.median).sum()
    }

    /// Sum of the launches' means: one step amortised over the timed steps.
    pub fn mean_step_time(&self) -> Duration {
        self.timings.iter().map(|t| t.mean).sum()
    }
}

/// Runs the program back to back for at least half a second, doubling the steps, so the
/// GPU's clocks are up before timing: a GPU that idled while the host prepared data runs
/// its first milliseconds of work at reduced clocks (seen on an H100: a 3-D FFT timed 4x
/// slower right after the host had built its input).
fn warm_up(program: &mut Program) -> Result<(), CliError> {
    let start = Instant::now();
    let mut steps = 2;
    while start.elapsed() < Duration::from_millis(500) {
        program
            .run(&RunOptions {
                steps,
                profile: Profile::Off,
                progress: false,
            })
            .map_err(runtime)?;
        steps = (steps * 2).min(1 << 14);
    }
    Ok(())
}

/// Plans, compiles and runs `graph_json` for `reps` steps with per-launch GPU timestamps
/// (after a warm-up of at least half a second of back-to-back runs).
pub fn time_graph(
    gpu: &GpuContext,
    graph_json: &str,
    inputs: &BTreeMap<String, HostArray>,
    reps: u64,
    fuse: bool,
) -> Result<TimedRun, CliError> {
    let dir = std::env::temp_dir().join(format!("mesoflow-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(runtime)?;
    let file = dir.join("timed.json");
    std::fs::write(&file, graph_json).map_err(runtime)?;
    let registry = crate::nodes::registry();
    let g = graph::load(&file, &registry, &LoadOptions::default())
        .map_err(|p| CliError::Input(p.to_string()))?;
    let run = time_loaded(gpu, &g, inputs, None, reps, fuse);
    let _ = std::fs::remove_dir_all(&dir);
    run.map(|(run, _)| run)
}

/// [`time_graph`] for a loaded graph and these outputs (all when `None`); also returns
/// the plan's memory total in bytes.
pub fn time_loaded(
    gpu: &GpuContext,
    g: &graph::Graph,
    inputs: &BTreeMap<String, HostArray>,
    outputs: Option<Vec<String>>,
    reps: u64,
    fuse: bool,
) -> Result<(TimedRun, u64), CliError> {
    let opts = PlanOptions {
        outputs,
        inputs: inputs.iter().map(|(k, v)| (k.clone(), v.ty)).collect(),
        fuse,
    };
    let p = plan::plan(g, &opts, &gpu.caps).map_err(|e| CliError::Input(e.to_string()))?;
    let mut cache = KernelCache::default();
    let mut program = Program::compile(gpu, g, &p, &mut cache).map_err(runtime)?;
    program.upload(inputs).map_err(runtime)?;
    warm_up(&mut program)?;
    let stats = program
        .run(&RunOptions {
            steps: reps,
            profile: Profile::Launches,
            progress: false,
        })
        .map_err(runtime)?;
    // Per-dispatch medians on request (a second, separately timed run).
    let per_dispatch = if std::env::var_os("MESOFLOW_BENCH_DISPATCHES").is_some() {
        program
            .run(&RunOptions {
                steps: reps,
                profile: Profile::Dispatches,
                progress: false,
            })
            .map_err(runtime)?
            .profile
    } else {
        Vec::new()
    };
    let outputs = program
        .read_outputs()
        .map_err(runtime)?
        .into_iter()
        .collect();
    let timings = stats
        .profile
        .iter()
        .map(|r| Timing {
            label: r.label.clone(),
            median: r.median(),
            mean: r.total / (r.calls.max(1) as u32),
            min: r.samples.iter().min().copied().unwrap_or_default(),
            dispatches: per_dispatch
                .iter()
                .find(|d| d.label == r.label)
                .map(|d| {
                    d.dispatch_samples
                        .iter()
                        .map(|(kernel, samples)| {
                            let mean =
                                samples.iter().sum::<Duration>() / (samples.len().max(1) as u32);
                            (kernel.clone(), median_duration(samples), mean)
                        })
                        .collect()
                })
                .unwrap_or_default(),
        })
        .collect();
    Ok((TimedRun { timings, outputs }, p.memory.total()))
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
    },
    /// MPCD particle-steps per second (3D SRD) at several particle counts.
    Mpcd {
        /// The MPCD graph file.
        #[arg(long, default_value = "graphs/mpcd.json")]
        graph: PathBuf,
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
    },
}

/// `--sizes` values L:N.
fn parse_sizes(sizes: &[String]) -> Result<Vec<(f64, u32)>, CliError> {
    sizes
        .iter()
        .map(|s| {
            let parsed = s
                .split_once(':')
                .and_then(|(l, n)| Some((l.parse::<f64>().ok()?, n.parse::<u32>().ok()?)));
            parsed.filter(|(l, n)| *l > 0.0 && *n > 0).ok_or_else(|| {
                CliError::Input(format!(
                    "--sizes `{s}`: expected L:N with L > 0 and N > 0 (e.g. 129:100000)"
                ))
            })
        })
        .collect()
}

pub fn run(cmd: BenchCommand) -> Result<(), CliError> {
    match cmd {
        BenchCommand::Overhead {
            nodes,
            elements,
            reps,
        } => overhead(nodes, elements, reps),
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
        } => {
            let kernels = if kernels.iter().any(|k| k == "all") {
                crate::nodes::spread::window::NAMES
                    .iter()
                    .map(|s| s.to_string())
                    .collect()
            } else {
                kernels
            };
            let sizes = parse_sizes(&sizes)?;
            fcm::run(&fcm::FcmBench {
                graph,
                kernels,
                tolerances,
                sizes,
                noise,
                reps,
                error_box,
                error_samples,
                plot,
                sets: crate::cli::parse_sets(&sets)?.into_iter().collect(),
            })
        }
        BenchCommand::Mpcd {
            graph,
            sizes,
            density,
            reps,
            sets,
        } => mpcd::run(&mpcd::MpcdBench {
            graph,
            sizes,
            density,
            reps,
            sets: crate::cli::parse_sets(&sets)?.into_iter().collect(),
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
        } => pse::run(&pse::PseBench {
            graph,
            splits,
            tolerance,
            sizes: parse_sizes(&sizes)?,
            noise,
            reps,
            error_box,
            sets: crate::cli::parse_sets(&sets)?.into_iter().collect(),
        }),
    }
}

/// A runtime error of a bench (GPU, graph or reference), as the CLI reports it.
fn runtime(e: impl std::fmt::Display) -> CliError {
    CliError::Runtime(e.to_string())
}

/// A node's f64 reference outputs (`cpu_reference`) for `params` and `inputs`: what the
/// benches check their GPU outputs against.
pub(crate) fn node_reference(
    kind: &str,
    params: &BTreeMap<String, crate::expr::ParamValue>,
    inputs: &[Option<crate::value::RefArray>],
) -> Result<Vec<crate::value::RefArray>, CliError> {
    let registry = crate::nodes::registry();
    let kind = registry
        .get(kind)
        .ok_or_else(|| runtime(format!("no node kind `{kind}`")))?;
    let params = crate::node::check_params(&kind.params(), params)
        .map_err(|e| runtime(format!("{} params: {e:?}", kind.name())))?;
    let node = kind.build(&params).map_err(runtime)?;
    let types: Vec<Option<ValueType>> = inputs.iter().map(|r| r.as_ref().map(|r| r.ty)).collect();
    let sig = node
        .infer(&types)
        .map_err(|e| runtime(format!("{}: {e:?}", kind.name())))?;
    let mut out: Vec<_> = sig
        .outputs
        .iter()
        .map(|t| crate::value::RefArray::new(*t, vec![0.0; t.words() as usize]))
        .collect();
    node.cpu_reference(inputs, &mut out, crate::node::RefCtx::default());
    Ok(out)
}

/// A graph file with a chain of `n` scale nodes.
pub fn chain_graph(n: usize) -> String {
    let mut nodes = Vec::new();
    for i in 0..n {
        let src = if i == 0 {
            "inputs.x".to_string()
        } else {
            format!("s{}.out", i - 1)
        };
        nodes.push(format!(
            r#"{{"id": "s{i}", "kind": "scale", "params": {{"factor": 1.0001}}, "inputs": {{"x": "{src}"}}}}"#
        ));
    }
    format!(
        r#"{{"mesoflow": 1, "doc": "chain of {n} scale nodes",
  "inputs": {{"x": {{"type": "particles", "cols": 1}}}},
  "nodes": [{}],
  "outputs": {{"y": "s{}.out"}}}}"#,
        nodes.join(",\n"),
        n - 1
    )
}

fn overhead(nodes: usize, elements: u32, reps: u64) -> Result<(), CliError> {
    if nodes == 0 || reps == 0 {
        return Err(CliError::Input(
            "--nodes and --reps must be positive".into(),
        ));
    }
    let gpu = GpuContext::new().map_err(runtime)?;
    let dir = std::env::temp_dir().join(format!("mesoflow-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(runtime)?;
    let file = dir.join("chain.json");
    std::fs::write(&file, chain_graph(nodes)).map_err(runtime)?;
    let registry = crate::nodes::registry();
    let g = graph::load(&file, &registry, &LoadOptions::default())
        .map_err(|p| CliError::Input(p.to_string()))?;
    let ty = ValueType::Particles { n: elements, k: 1 };
    let opts = PlanOptions {
        outputs: None,
        inputs: [("x".to_string(), ty)].into_iter().collect(),
        fuse: false,
    };
    let p = plan::plan(&g, &opts, &gpu.caps).map_err(|e| CliError::Input(e.to_string()))?;
    let mut cache = KernelCache::default();
    let mut program = Program::compile(&gpu, &g, &p, &mut cache).map_err(runtime)?;
    let x = HostArray::f32(ty, (0..elements).map(|i| i as f32).collect());
    program
        .upload(&[("x".to_string(), x)].into_iter().collect())
        .map_err(runtime)?;
    let run = |program: &mut Program, steps: u64| {
        program.run(&RunOptions {
            steps,
            profile: Profile::Off,
            progress: false,
        })
    };
    run(&mut program, 2).map_err(runtime)?; // warm-up
    let mut exec_times = Vec::new();
    for _ in 0..5 {
        let stats = run(&mut program, reps).map_err(runtime)?;
        exec_times.push(stats.wall.as_secs_f64());
    }
    let exec = median(&mut exec_times) / (reps as f64 * nodes as f64);

    // Raw wgpu: one pipeline, pre-made bind groups, all dispatches in one pass per submit.
    let src = crate::gpu::shaders::resolve(&raw_kernel_source()).map_err(runtime)?;
    let mut cx = CompileCtx {
        gpu: &gpu,
        kernels: &mut cache,
        clock: &dummy(&gpu),
        allocated: Default::default(),
    };
    let k = cx
        .kernel(&KernelSpec::new(
            "raw scale",
            src,
            &[
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::Uniform,
            ],
        ))
        .map_err(runtime)?;
    let bufs: Vec<wgpu::Buffer> = (0..2).map(|_| storage(&gpu, elements as u64 * 4)).collect();
    let uni = cx.uniform("n", bytemuck::bytes_of(&elements));
    let dispatches: Vec<_> = (0..nodes)
        .map(|i| {
            cx.dispatch(
                &k,
                &[&bufs[i % 2], &bufs[(i + 1) % 2], &uni],
                cx.grid_1d(elements as u64, WG_1D),
            )
        })
        .collect();
    let per_submit = (4096 / (nodes + 1)).max(1) as u64;
    let raw_run = |reps: u64| -> Result<f64, CliError> {
        let t = Instant::now();
        let mut last = None;
        let mut done = 0;
        while done < reps {
            let n = per_submit.min(reps - done);
            let mut enc = gpu.device.create_command_encoder(&Default::default());
            {
                let mut pass = enc.begin_compute_pass(&Default::default());
                for _ in 0..n {
                    for d in &dispatches {
                        pass.set_pipeline(&d.kernel.pipeline);
                        pass.set_bind_group(0, &d.bind_group, &[]);
                        pass.dispatch_workgroups(d.workgroups[0], d.workgroups[1], d.workgroups[2]);
                    }
                }
            }
            let idx = gpu.queue.submit([enc.finish()]);
            if let Some(prev) = last.replace(idx) {
                gpu.wait(prev).map_err(runtime)?;
            }
            done += n;
        }
        if let Some(prev) = last {
            gpu.wait(prev).map_err(runtime)?;
        }
        Ok(t.elapsed().as_secs_f64())
    };
    raw_run(2)?;
    let mut raw_times = Vec::new();
    for _ in 0..5 {
        raw_times.push(raw_run(reps)?);
    }
    let raw = median(&mut raw_times) / (reps as f64 * nodes as f64);

    // Submit-and-wait round trip of one tiny dispatch.
    let mut rt = Vec::new();
    for _ in 0..50 {
        let t = Instant::now();
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            let d = &dispatches[0];
            pass.set_pipeline(&d.kernel.pipeline);
            pass.set_bind_group(0, &d.bind_group, &[]);
            pass.dispatch_workgroups(d.workgroups[0], d.workgroups[1], d.workgroups[2]);
        }
        let idx = gpu.queue.submit([enc.finish()]);
        gpu.wait(idx).map_err(runtime)?;
        rt.push(t.elapsed().as_secs_f64());
    }
    let roundtrip = median(&mut rt);
    let _ = std::fs::remove_dir_all(&dir);

    println!("adapter: {}", gpu.caps.summary());
    println!(
        "chain of {nodes} unfused pointwise nodes, {elements} elements each, {reps} repetitions, median of 5"
    );
    println!("{:<44} {:>12}", "", "us per node");
    println!(
        "{:<44} {:>12.3}",
        "mesoflow executor (graph file, planned)",
        exec * 1e6
    );
    println!(
        "{:<44} {:>12.3}",
        "raw wgpu (same kernel, one pass per submit)",
        raw * 1e6
    );
    println!("{:<44} {:>12.3}", "ratio executor / raw", exec / raw);
    println!(
        "{:<44} {:>12.1}",
        "submit-and-wait round trip (us)",
        roundtrip * 1e6
    );
    Ok(())
}

fn raw_kernel_source() -> String {
    format!(
        "#import common/index.wgsl\n@group(0) @binding(0) var<storage, read> x: array<f32>;\n@group(0) @binding(1) var<storage, read_write> y: array<f32>;\n@group(0) @binding(2) var<uniform> n: vec4<u32>;\n@compute @workgroup_size({WG_1D})\nfn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {{\n    let i = flat_index(wid, nwg, lid, {WG_1D}u);\n    if (i < n.x) {{ y[i] = 1.0001 * x[i]; }}\n}}\n"
    )
}

fn storage(gpu: &GpuContext, bytes: u64) -> wgpu::Buffer {
    gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("bench"),
        size: bytes.max(16),
        usage: wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

fn dummy(gpu: &GpuContext) -> wgpu::Buffer {
    storage(gpu, 16)
}

/// Median of a sample (sorts it).
pub fn median(v: &mut [f64]) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}
