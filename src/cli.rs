//! The `mesoflow` command line. Raw arguments (clap) become validated requests here, and
//! every failure becomes a message and an exit code: 2 for problems in what the user gave
//! (graph files, params, inputs, arguments), 1 for failures while running, 3 for a run
//! whose outputs hold NaN or infinite values from finite inputs (written all the same).

use std::collections::BTreeMap;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};

use clap::{Parser, Subcommand};
use thiserror::Error;

use mesoflow::exec::{Checkpoint, ExecError, Profile, Program, RunOptions, RunStats};
use mesoflow::expr::{self, ParamValue};
use mesoflow::gpu::{DeviceCaps, GpuContext, GpuError, KernelCache};
use mesoflow::graph::{self, Graph, LoadOptions};
use mesoflow::node::{ParamKind, Registry};
use mesoflow::plan::{self, Plan, PlanOptions};
use mesoflow::scene::{self, CompiledScene};
use mesoflow::value::{HostArray, HostData, ValueType};

use crate::bench::{BenchCommand, BenchError};

#[derive(Parser, Debug)]
#[command(
    name = "mesoflow",
    version,
    about = "Complex-fluid simulation algorithms on the GPU as graphs of compute nodes"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Run a graph file, or a scene (a JSON file with `"scene": 1`: built into the graph
    /// it needs, its particles placed, its outputs and steps taken from it).
    Run {
        graph: PathBuf,
        /// Set a graph param: NAME=VALUE (a number, a string, or a JSON array such as [64,64,64]).
        #[arg(long = "set", value_name = "NAME=VALUE")]
        sets: Vec<String>,
        /// Give a graph input from an NPY file: NAME=FILE.npy.
        #[arg(long = "input", value_name = "NAME=FILE")]
        inputs: Vec<String>,
        /// Request an output, and write it to a file when =FILE is given: NAME[=FILE.npy]
        /// or NAME[=FILE.gsd] (a HOOMD-schema trajectory; outputs may share one: positions
        /// and velocities become particles/position and /velocity, others go under log/).
        /// Without any --output, every output the inputs and params allow is computed and
        /// summarised (the others are named, with why).
        #[arg(long = "output", value_name = "NAME[=FILE]")]
        outputs: Vec<String>,
        /// Number of time steps (default: a scene's `run.steps`, else 1).
        #[arg(long)]
        steps: Option<u64>,
        /// Write a frame of each output given a file every K steps (and after the last),
        /// streamed to disk while the run goes on: FILE.npy holds (frames, ...), FILE.gsd
        /// one frame each. The steps and random draws are those of one run.
        #[arg(long, value_name = "K")]
        every: Option<u64>,
        /// Write a checkpoint at the end of the run (a GSD file of the states, the step
        /// count and what else the steps carry), from which --resume goes on; with
        /// --every, also after every frame (each replacing the one before).
        #[arg(long, value_name = "FILE")]
        checkpoint: Option<PathBuf>,
        /// Go on from a checkpoint: --steps more steps, bit for bit as if the run that
        /// wrote it had not stopped. Give the same graph, --set params, --seed and inputs
        /// (checked: a difference is an error that names it).
        #[arg(long, value_name = "FILE")]
        resume: Option<PathBuf>,
        /// Random seed (the built-in param `seed`).
        #[arg(long)]
        seed: Option<u64>,
        /// Print GPU time per node.
        #[arg(long)]
        profile: bool,
        /// Print GPU time per dispatch (each in a pass of its own): the passes inside nodes.
        #[arg(long)]
        profile_dispatches: bool,
        /// Do not fuse element-wise nodes.
        #[arg(long)]
        no_fuse: bool,
        /// Give every output a buffer of its own, even one its node could write in place
        /// of its input (the flip loops' meshes): to compare, or time, the copies.
        #[arg(long)]
        no_in_place: bool,
        /// Bitwise reproducible results from run to run on this adapter with this binary
        /// and these inputs: integer (fixed-point) sums where float atomics would add in
        /// any order, counting sorts stable inside a bin (README: Deterministic runs).
        #[arg(long)]
        deterministic: bool,
    },
    /// Check graph files: structure, params, kinds, ports, types and shapes (no GPU needed).
    Validate {
        #[arg(required = true)]
        graphs: Vec<PathBuf>,
    },
    /// Print the plan of a graph or a scene: order, fused groups, buffers, peak memory.
    Inspect {
        graph: PathBuf,
        #[arg(long = "set", value_name = "NAME=VALUE")]
        sets: Vec<String>,
        /// Take an input's shape from an NPY file (otherwise its declared shape, with sizes
        /// from the inputs given or the sizes' defaults).
        #[arg(long = "input", value_name = "NAME=FILE")]
        inputs: Vec<String>,
        /// Plan with this optional input at its declared shape (optional inputs not given
        /// are absent, as in a run).
        #[arg(long = "with", value_name = "NAME")]
        with: Vec<String>,
        /// Plan for these outputs only.
        #[arg(long = "output", value_name = "NAME")]
        outputs: Vec<String>,
        #[arg(long, default_value_t = 1)]
        steps: u64,
        #[arg(long)]
        no_fuse: bool,
        /// Plan without in-place outputs (as `run --no-in-place`).
        #[arg(long)]
        no_in_place: bool,
        /// Plan a deterministic run (as `run --deterministic`).
        #[arg(long)]
        deterministic: bool,
        /// Print Graphviz DOT instead of text.
        #[arg(long)]
        dot: bool,
        /// For a scene: print the graph file it builds instead of the plan.
        #[arg(long)]
        graph_text: bool,
    },
    /// Show the GPU adapter mesoflow would use and what it can do.
    Info,
    /// List every node kind with its ports, params and a one-line doc, then the host
    /// functions param expressions may call.
    Nodes {
        /// Show only this kind.
        kind: Option<String>,
    },
    /// Benchmarks run on the GPU (see BENCHMARKS.md).
    Bench {
        #[command(subcommand)]
        which: BenchCommand,
    },
    /// What the Vulkan driver makes of kernels: build each kernel a run wrote with
    /// MESOFLOW_KERNEL_DUMP=<folder> (its .wgsl files) on the device again and print the
    /// driver's statistics for it (registers, spills, code size: whatever the driver
    /// reports through VK_KHR_pipeline_executable_properties). For kernel work.
    KernelStats {
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// Also write the driver's internal representations (its IR or machine code, where
        /// it gives them) of each kernel into this folder, as <file stem>.<executable>.<n>.txt.
        #[arg(long, value_name = "FOLDER")]
        ir: Option<PathBuf>,
    },
}

/// A failure of a command, with its exit code.
#[derive(Debug, Error)]
pub enum CliError {
    /// Something the user gave is wrong (exit 2).
    #[error("{0}")]
    Input(String),
    /// Running failed (exit 1).
    #[error("{0}")]
    Runtime(String),
    /// The run finished, but outputs hold NaN or infinite values from finite inputs
    /// (exit 3); the outputs asked for were written all the same, for debugging.
    #[error("{0}")]
    NonFinite(String),
    #[error(transparent)]
    Bench(#[from] BenchError),
}

impl CliError {
    /// 2 for problems in what the user gave, 1 for failures while running.
    pub fn exit_code(&self) -> u8 {
        match self {
            CliError::Input(_) => 2,
            CliError::Runtime(_) => 1,
            CliError::NonFinite(_) => 3,
            CliError::Bench(e) if e.is_bad_input() => 2,
            CliError::Bench(_) => 1,
        }
    }
}

impl From<ExecError> for CliError {
    fn from(e: ExecError) -> Self {
        match e {
            ExecError::Input { .. } => CliError::Input(e.to_string()),
            other => CliError::Runtime(other.to_string()),
        }
    }
}

impl From<GpuError> for CliError {
    fn from(e: GpuError) -> Self {
        CliError::Runtime(e.to_string())
    }
}

/// Runs one command.
pub fn execute(cmd: Command) -> Result<(), CliError> {
    let registry = mesoflow::nodes::registry();
    match cmd {
        Command::Run {
            graph,
            sets,
            inputs,
            outputs,
            steps,
            every,
            checkpoint,
            resume,
            seed,
            profile,
            profile_dispatches,
            no_fuse,
            no_in_place,
            deterministic,
        } => {
            let profile = match (profile, profile_dispatches) {
                (_, true) => Profile::Dispatches,
                (true, false) => Profile::Launches,
                (false, false) => Profile::Off,
            };
            let scene = scene_of(&graph, seed)?;
            run(
                &registry,
                &graph,
                scene,
                &sets,
                &inputs,
                &outputs,
                steps,
                every,
                Continuation {
                    checkpoint: checkpoint.as_deref(),
                    resume: resume.as_deref(),
                },
                seed,
                profile,
                !no_fuse,
                !no_in_place,
                deterministic,
            )
        }
        Command::Validate { graphs } => validate(&registry, &graphs),
        Command::Inspect {
            graph,
            sets,
            inputs,
            with,
            outputs,
            steps,
            no_fuse,
            no_in_place,
            deterministic,
            dot,
            graph_text,
        } => inspect(
            &registry,
            &graph,
            scene_of(&graph, None)?,
            graph_text,
            &sets,
            &inputs,
            &with,
            &outputs,
            steps,
            !no_fuse,
            !no_in_place,
            deterministic,
            dot,
        ),
        Command::Nodes { kind } => nodes(&registry, kind.as_deref()),
        Command::Info => {
            let gpu = GpuContext::new()?;
            outln!("{}", gpu.caps.summary());
            Ok(())
        }
        Command::Bench { which } => Ok(crate::bench::run(which)?),
        Command::KernelStats { files, ir } => kernel_stats(&files, ir.as_deref()),
    }
}

fn kernel_stats(files: &[PathBuf], ir: Option<&Path>) -> Result<(), CliError> {
    use mesoflow::gpu::driver_stats::{DriverStats, read_dump};
    // Every file is read first, so a wrong one fails before the device opens.
    let kernels = files
        .iter()
        .map(|f| read_dump(f).map(|k| (f, k)))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| CliError::Input(e.to_string()))?;
    let wanted = std::env::var("MESOFLOW_ADAPTER")
        .ok()
        .filter(|s| !s.is_empty());
    // A device or driver that cannot do it fails the run (1), as no adapter does for
    // `info`; only the files are the user's input.
    let stats =
        DriverStats::open(wanted.as_deref()).map_err(|e| CliError::Runtime(e.to_string()))?;
    outln!("driver statistics on {}", stats.adapter);
    if let Some(dir) = ir {
        std::fs::create_dir_all(dir)
            .map_err(|e| CliError::Input(format!("--ir {}: {e}", dir.display())))?;
    }
    let mut failed = Vec::new();
    for (file, kernel) in &kernels {
        outln!("{} ({}):", kernel.label, file.display());
        let executables = match stats.kernel(kernel, ir.is_some()) {
            Ok(e) => e,
            Err(message) => {
                outln!("  cannot build it: {message}");
                failed.push(file.display().to_string());
                continue;
            }
        };
        for (i, e) in executables.iter().enumerate() {
            outln!("  {} (subgroup {})", e.name, e.subgroup_size);
            for s in &e.statistics {
                outln!("    {:<28} {:>12}   {}", s.name, s.value, s.description);
            }
            if let Some(dir) = ir {
                let stem = file
                    .file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_default();
                for (n, (name, body)) in e.representations.iter().enumerate() {
                    let path = dir.join(format!("{stem}.{i}.{n}.txt"));
                    std::fs::write(&path, format!("// {name}\n{body}"))
                        .map_err(|err| CliError::Runtime(format!("{}: {err}", path.display())))?;
                }
            }
        }
    }
    if failed.is_empty() {
        Ok(())
    } else {
        Err(CliError::Runtime(format!(
            "the driver could not build {}",
            failed.join(", ")
        )))
    }
}

fn split_pair<'s>(arg: &'s str, flag: &str, what: &str) -> Result<(&'s str, &'s str), CliError> {
    arg.split_once('=')
        .filter(|(n, v)| !n.is_empty() && !v.is_empty())
        .ok_or_else(|| CliError::Input(format!("--{flag} `{arg}`: expected {what}")))
}

/// `--set NAME=VALUE` arguments as param values.
fn parse_sets(sets: &[String]) -> Result<BTreeMap<String, ParamValue>, CliError> {
    expr::parse_overrides(sets).map_err(|e| CliError::Input(format!("--set {e}")))
}

fn load(registry: &Registry, path: &Path, opts: &LoadOptions) -> Result<Graph, CliError> {
    graph::load(&resolve(path), registry, opts).map_err(|p| CliError::Input(p.to_string()))
}

/// A graph argument's graph: the file's, or the one a scene built.
fn load_graph(
    registry: &Registry,
    path: &Path,
    scene: Option<&CompiledScene>,
    opts: &LoadOptions,
) -> Result<Graph, CliError> {
    match scene {
        Some(s) => graph::load_text(&resolve(path), &s.graph, registry, opts).map_err(|p| {
            CliError::Input(format!(
                "the graph the scene builds: {p}\n(--set reaches that graph's params, dt and temperature; the rest is set in the scene file)"
            ))
        }),
        None => load(registry, path, opts),
    }
}

/// The scene a graph argument names, built (its generated particles placed with `seed`
/// where given), or None for a graph file.
fn scene_of(path: &Path, seed: Option<u64>) -> Result<Option<CompiledScene>, CliError> {
    let path = resolve(path);
    if !scene::is_scene(&path) {
        return Ok(None);
    }
    scene::compile(&path, seed)
        .map(Some)
        .map_err(|e| CliError::Input(e.to_string()))
}

/// A graph argument: the file when it exists, else a graph of the library by name
/// (`fcm`, `examples/colloids`), else the path as given (its load names it missing).
fn resolve(path: &Path) -> PathBuf {
    if path.exists() {
        return path.to_path_buf();
    }
    path.to_str()
        .and_then(graph::library::find)
        .unwrap_or_else(|| path.to_path_buf())
}

fn read_inputs(g: &Graph, args: &[String]) -> Result<BTreeMap<String, HostArray>, CliError> {
    let mut out = BTreeMap::new();
    for a in args {
        let (name, file) = split_pair(a, "input", "NAME=FILE.npy")?;
        let Some(i) = g.input(name) else {
            let known: Vec<&str> = g.inputs.iter().map(|i| i.name.as_str()).collect();
            return Err(CliError::Input(format!(
                "--input {name}: the graph has no input `{name}` (inputs: {})",
                if known.is_empty() {
                    "none".into()
                } else {
                    known.join(", ")
                }
            )));
        };
        if out.contains_key(name) {
            return Err(CliError::Input(format!("--input {name} is given twice")));
        }
        let arr = mesoflow::npy::read_input(Path::new(file), &g.inputs[i].shape)
            .map_err(|e| CliError::Input(format!("--input {name}: {e}")))?;
        out.insert(name.to_string(), arr);
    }
    Ok(out)
}

#[allow(clippy::too_many_arguments)]
fn run(
    registry: &Registry,
    path: &Path,
    scene: Option<CompiledScene>,
    sets: &[String],
    input_args: &[String],
    output_args: &[String],
    steps: Option<u64>,
    every: Option<u64>,
    continuation: Continuation,
    seed: Option<u64>,
    profile: Profile,
    fuse: bool,
    in_place: bool,
    deterministic: bool,
) -> Result<(), CliError> {
    let steps = steps.or(scene.as_ref().and_then(|s| s.steps)).unwrap_or(1);
    if steps == 0 {
        return Err(CliError::Input("--steps must be at least 1".into()));
    }
    // A scene's trajectory and interval stand where the command line gives none.
    let scene_outputs: Vec<String> = match &scene {
        Some(s) if output_args.is_empty() => s
            .outputs
            .iter()
            .map(|(name, file)| format!("{name}={}", file.display()))
            .collect(),
        _ => Vec::new(),
    };
    let output_args = if scene_outputs.is_empty() {
        output_args
    } else {
        &scene_outputs[..]
    };
    // The scene's interval goes with its outputs: `--output` given, frames only with
    // `--every`.
    let every = match &scene {
        Some(s) if !scene_outputs.is_empty() => every.or(s.every),
        _ => every,
    };
    if every == Some(0) {
        return Err(CliError::Input("--every must be at least 1".into()));
    }
    if every.is_some() && profile != Profile::Off {
        return Err(CliError::Input(
            "--every streams frames between chunks of steps: profile a run without it".into(),
        ));
    }
    let overrides = parse_sets(sets)?;
    let seed = match (seed, overrides.get("seed")) {
        (Some(_), Some(_)) => {
            return Err(CliError::Input(
                "give the seed once: --seed or --set seed=".into(),
            ));
        }
        (Some(s), None) => s,
        (None, Some(ParamValue::Number(x))) if *x >= 0.0 && x.fract() == 0.0 => *x as u64,
        (None, Some(v)) => {
            return Err(CliError::Input(format!(
                "--set seed={v}: expected a non-negative integer"
            )));
        }
        (None, None) => scene.as_ref().and_then(|s| s.seed).unwrap_or(0),
    };
    let g = load_graph(
        registry,
        path,
        scene.as_ref(),
        &LoadOptions {
            overrides,
            steps,
            seed,
        },
    )?;
    let mut data = read_inputs(&g, input_args)?;
    if let Some(s) = &scene {
        for (name, a) in &s.inputs {
            data.entry(name.clone()).or_insert_with(|| a.clone());
        }
    }
    let missing: Vec<String> = g
        .inputs
        .iter()
        .filter(|i| !i.optional && !data.contains_key(&i.name))
        .map(|i| format!("--input {}=FILE.npy ({})", i.name, i.shape.describe()))
        .collect();
    if !missing.is_empty() {
        return Err(CliError::Input(format!(
            "{}: missing required inputs: {}",
            path.display(),
            missing.join(", ")
        )));
    }
    // Requested outputs and where they go; checked before any GPU work.
    let requested = output_requests(&g, output_args)?;
    let gpu = GpuContext::new()?;
    note!("mesoflow: {}", gpu.caps.summary());
    let opts = PlanOptions {
        outputs: Some(requested.iter().map(|(name, _)| name.clone()).collect()),
        inputs: data.iter().map(|(k, v)| (k.clone(), v.ty)).collect(),
        fuse,
        in_place,
    };
    let caps = DeviceCaps {
        deterministic,
        ..gpu.caps.clone()
    };
    let p = plan_requested(&g, &opts, requested.is_empty(), &caps)?;
    let mut cache = KernelCache::default();
    let mut program = Program::compile(&gpu, &g, &p, &mut cache)?;
    program.upload(&data)?;
    let description = run_description(path, sets, seed, &data);
    if let Some(file) = continuation.resume {
        let (cp, theirs) =
            Checkpoint::read(file).map_err(|e| CliError::Input(format!("--resume: {e}")))?;
        if theirs != description {
            let differs: Vec<String> = description
                .lines()
                .zip(theirs.lines())
                .filter(|(a, b)| a != b)
                .map(|(here, there)| format!("`{there}` there, `{here}` here"))
                .collect();
            return Err(CliError::Input(format!(
                "--resume {}: the checkpoint was written by another run: {}",
                file.display(),
                differs.join("; ")
            )));
        }
        program
            .restore(&cp)
            .map_err(|e| CliError::Input(format!("--resume {}: {e}", file.display())))?;
    }
    let first_step = program.steps_done();
    let progress = std::io::stderr().is_terminal() && std::env::var_os("CI").is_none();
    let files: Vec<(String, PathBuf)> = requested
        .iter()
        .filter_map(|(name, file)| Some((name.clone(), file.clone()?)))
        .collect();
    // Frames: with --every, or where a GSD file is asked for (one frame at the end).
    let streamed = every.is_some() || files.iter().any(|(_, f)| crate::frames::is_gsd(f));
    let every = every.unwrap_or(steps).min(steps);
    let frames = steps.div_ceil(every);
    let (stats, results, streamed_files) = if streamed {
        let sinks = crate::frames::FrameSinks::open(&files, frames).map_err(CliError::Runtime)?;
        // Frames go to disk on a thread of their own while the next steps run.
        let context = crate::frames::FrameContext::of(&g)
            .with_species(scene.as_ref().map(|s| s.species.clone()))
            .with_box(scene.as_ref().map(|s| s.box_lengths));
        let writer = crate::frames::FrameWriter::start(sinks, context);
        let mut stats: Option<RunStats> = None;
        let mut results = Vec::new();
        let mut done = 0;
        while done < steps {
            let k = every.min(steps - done);
            let opts = RunOptions {
                steps: k,
                profile,
                progress,
            };
            let (chunk, outputs) = program.run_on_and_read(&opts)?;
            done += k;
            if !writer.frame(first_step + done, outputs.clone()) {
                break; // the writer failed: its error comes from finish
            }
            // With frames, the checkpoint follows them: a run that stops on the way can
            // go on from its last frame (the one after the last step is written below).
            if let Some(file) = continuation.checkpoint
                && done < steps
            {
                write_checkpoint(&program, file, &description)?;
            }
            stats = Some(match stats {
                None => chunk,
                Some(s) => RunStats {
                    steps: done,
                    wall: s.wall + chunk.wall,
                    ..chunk
                },
            });
            results = outputs;
        }
        let written = writer.finish().map_err(CliError::Runtime)?;
        (stats.expect("at least one step"), results, written)
    } else {
        // From the prologue, or from a restored checkpoint.
        let stats = program.run_on(&RunOptions {
            steps,
            profile,
            progress,
        })?;
        (stats, program.read_outputs()?, Vec::new())
    };
    // Judged now, reported after the files: a user debugging NaN wants to see them.
    let non_finite = program.check_finite(&results).err();
    if let Some(input) = program.non_finite_input() {
        note!(
            "mesoflow: input `{input}` holds NaN or infinite values: the outputs are not checked for them"
        );
    }
    note!(
        "mesoflow: {} step{} in {:.3} s ({} dispatches per step, GPU memory {} planned + {} tables)",
        stats.steps,
        if stats.steps == 1 { "" } else { "s" },
        stats.wall.as_secs_f64(),
        program.dispatches_per_step(),
        plan::human_bytes(p.memory.total()),
        plan::human_bytes(program.table_bytes),
    );
    for (node, counts) in program.loop_iterations() {
        if let (Some(lo), Some(hi)) = (counts.iter().min(), counts.iter().max()) {
            let mean = counts.iter().map(|&k| k as f64).sum::<f64>() / counts.len() as f64;
            note!("mesoflow: loop `{node}`: {mean:.1} iterations per step (min {lo}, max {hi})");
        }
    }
    // Every file first, all or none; then the report. Streamed files are in place.
    let files: BTreeMap<&str, &Path> = requested
        .iter()
        .filter(|_| !streamed)
        .filter_map(|(name, file)| Some((name.as_str(), file.as_deref()?)))
        .collect();
    let to_write: Vec<(&str, &Path, &HostArray)> = results
        .iter()
        .filter_map(|(name, arr)| Some((name.as_str(), *files.get(name.as_str())?, arr)))
        .collect();
    let pairs: Vec<(&Path, &HostArray)> = to_write.iter().map(|&(_, f, a)| (f, a)).collect();
    if let Err(e) = mesoflow::npy::write_all(&pairs) {
        let name = to_write[e.index].0;
        let written: Vec<&str> = to_write[..e.in_place].iter().map(|w| w.0).collect();
        return Err(CliError::Runtime(format!(
            "--output {name}: {}; {}",
            e.source,
            if written.is_empty() {
                "no output was written".to_string()
            } else {
                format!("only {} were written", written.join(", "))
            }
        )));
    }
    if let Some(file) = continuation.checkpoint {
        write_checkpoint(&program, file, &description)?;
        note!(
            "mesoflow: checkpoint after step {} -> {}",
            program.steps_done(),
            file.display()
        );
    }
    if profile != Profile::Off {
        print_profile(&stats);
    }
    for (name, arr) in &results {
        let streamed_to = streamed_files
            .iter()
            .find(|(names, _)| names.contains(name));
        match (files.get(name.as_str()), streamed_to) {
            (Some(f), _) => outln!("{name}: {} -> {}", arr.ty, f.display()),
            (None, Some((_, f))) => {
                outln!("{name}: {} -> {} ({} frames)", arr.ty, f.display(), frames)
            }
            (None, None) => outln!("{name}: {}", summary(arr)),
        }
    }
    match non_finite {
        None => Ok(()),
        Some(e) => Err(CliError::NonFinite(format!(
            "{e}; {}",
            if to_write.is_empty() {
                "nothing was written".to_string()
            } else {
                "the outputs were written all the same (exit code 3)".to_string()
            }
        ))),
    }
}

/// Where a run starts from and what it leaves for the next.
pub struct Continuation<'a> {
    checkpoint: Option<&'a Path>,
    resume: Option<&'a Path>,
}

/// Writes the program's checkpoint to `file` (replacing the one before, whole).
fn write_checkpoint(program: &Program, file: &Path, description: &str) -> Result<(), CliError> {
    program.checkpoint()?.write(file, description).map_err(|e| {
        CliError::Runtime(format!(
            "--checkpoint: cannot write {}: {e}",
            file.display()
        ))
    })
}

/// What a resumed run must share with the one that wrote its checkpoint: the graph file,
/// the --set params, the seed and the inputs (a hash of each), one per line.
fn run_description(
    path: &Path,
    sets: &[String],
    seed: u64,
    data: &BTreeMap<String, HostArray>,
) -> String {
    let mut sets = sets.to_vec();
    sets.sort();
    let graph = path.canonicalize().unwrap_or_else(|_| path.to_path_buf());
    let inputs: Vec<String> = data
        .iter()
        .map(|(name, a)| {
            // FNV-1a over the type and the words.
            let mut h: u64 = 0xcbf2_9ce4_8422_2325;
            let words: Vec<u32> = match &a.data {
                HostData::F32(v) => v.iter().map(|x| x.to_bits()).collect(),
                HostData::U32(v) => v.clone(),
            };
            for b in
                a.ty.to_string()
                    .bytes()
                    .chain(words.iter().flat_map(|w| w.to_le_bytes()))
            {
                h = (h ^ b as u64).wrapping_mul(0x0100_0000_01b3);
            }
            format!("{name}={h:016x}")
        })
        .collect();
    format!(
        "graph {}\nset {}\nseed {seed}\ninputs {}",
        graph.display(),
        sets.join(" "),
        inputs.join(" ")
    )
}

/// The `--output NAME[=FILE.npy]` arguments: each output at most once, each file for one
/// output, in a folder that exists (checked before any GPU work).
fn output_requests(
    g: &Graph,
    output_args: &[String],
) -> Result<Vec<(String, Option<PathBuf>)>, CliError> {
    let mut requested: Vec<(String, Option<PathBuf>)> = Vec::new();
    // Each file as its folder's canonical path and its name, to tell `a.npy` and
    // `./a.npy` for one file.
    let mut targets: Vec<(PathBuf, &str)> = Vec::new();
    for o in output_args {
        let (name, file) = match o.split_once('=') {
            Some((n, f)) if !n.is_empty() && !f.is_empty() => (n, Some(PathBuf::from(f))),
            Some(_) => {
                return Err(CliError::Input(format!(
                    "--output `{o}`: expected NAME or NAME=FILE.npy"
                )));
            }
            None => (o.as_str(), None),
        };
        if g.output(name).is_none() {
            let known: Vec<&str> = g.outputs.iter().map(|o| o.name.as_str()).collect();
            return Err(CliError::Input(format!(
                "--output {name}: the graph has no output `{name}` (outputs: {})",
                known.join(", ")
            )));
        }
        if requested.iter().any(|(n, _)| n == name) {
            return Err(CliError::Input(format!("--output {name} is given twice")));
        }
        if let Some(f) = &file {
            let dir = f
                .parent()
                .filter(|p| !p.as_os_str().is_empty())
                .unwrap_or(Path::new("."));
            let Ok(canonical_dir) = dir
                .canonicalize()
                .map(|d| d.join(f.file_name().unwrap_or_default()))
            else {
                return Err(CliError::Input(format!(
                    "--output {name}: folder {} does not exist",
                    dir.display()
                )));
            };
            if !dir.is_dir() {
                return Err(CliError::Input(format!(
                    "--output {name}: {} is not a folder",
                    dir.display()
                )));
            }
            if f.is_dir() {
                return Err(CliError::Input(format!(
                    "--output {name}: {} is a folder",
                    f.display()
                )));
            }
            // One GSD trajectory may hold several outputs; any other file holds one.
            let shared = crate::frames::is_gsd(f);
            if let Some((_, other)) = targets.iter().find(|(t, _)| *t == canonical_dir && !shared) {
                return Err(CliError::Input(format!(
                    "--output {name}: {} is also the file of --output {other}",
                    f.display()
                )));
            }
            targets.push((canonical_dir, name));
        }
        requested.push((name.to_string(), file));
    }
    Ok(requested)
}

/// The plan for the outputs asked for; with none asked for (`every`), for every output the
/// inputs and params allow, the others named on stderr with why (asked for by name, an
/// output that does not plan is an error).
fn plan_requested(
    g: &Graph,
    opts: &PlanOptions,
    every: bool,
    caps: &DeviceCaps,
) -> Result<Plan, CliError> {
    if !every {
        return plan::plan(g, opts, caps).map_err(|e| CliError::Input(e.to_string()));
    }
    let available =
        plan::plan_available(g, opts, caps).map_err(|e| CliError::Input(e.to_string()))?;
    for (name, problems) in &available.left_out {
        note!(
            "mesoflow: output `{name}` is left out (these inputs and params do not give it; --output {name} asks for it): {}",
            problems.to_string().trim_end()
        );
    }
    Ok(available.plan)
}

/// Shape and statistics of an array, with its first values.
fn summary(a: &HostArray) -> String {
    let v = a.data.to_f64();
    if v.is_empty() {
        return format!("{} (empty)", a.ty);
    }
    let min = v.iter().cloned().fold(f64::INFINITY, f64::min);
    let max = v.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    let head: Vec<String> = match &a.data {
        HostData::F32(x) => x.iter().take(6).map(|x| format!("{x:.6e}")).collect(),
        HostData::U32(x) => x.iter().take(6).map(|x| x.to_string()).collect(),
    };
    let more = if v.len() > 6 { ", ..." } else { "" };
    if v.len() == 1 {
        format!("{} = {}", a.ty, head[0])
    } else {
        format!(
            "{}  min {min:.6e}  max {max:.6e}  mean {mean:.6e}  [{}{more}]",
            a.ty,
            head.join(", ")
        )
    }
}

fn print_profile(stats: &RunStats) {
    let total: f64 = stats.profile.iter().map(|r| r.total.as_secs_f64()).sum();
    outln!(
        "profile: GPU time per launch over {} step{} ({})",
        stats.steps,
        if stats.steps == 1 { "" } else { "s" },
        if stats.timed_by_gpu {
            "timestamp queries"
        } else {
            "wall clock with a wait per launch: no timestamp queries on this device"
        }
    );
    outln!(
        "  {:<40} {:<28} {:>6} {:>12} {:>12} {:>6}",
        "launch",
        "kinds",
        "calls",
        "total ms",
        "mean us",
        "%"
    );
    let mut rows = stats.profile.clone();
    rows.sort_by_key(|r| std::cmp::Reverse(r.total));
    for r in rows {
        let t = r.total.as_secs_f64();
        outln!(
            "  {:<40} {:<28} {:>6} {:>12.4} {:>12.2} {:>6.1}",
            r.label,
            r.kinds,
            r.calls,
            t * 1e3,
            if r.calls > 0 {
                t * 1e6 / r.calls as f64
            } else {
                0.0
            },
            if total > 0.0 { 100.0 * t / total } else { 0.0 }
        );
        for (kernel, samples) in &r.dispatch_samples {
            if samples.is_empty() {
                continue;
            }
            let d: f64 = samples.iter().map(|d| d.as_secs_f64()).sum();
            outln!(
                "    {:<38} {:<28} {:>6} {:>12.4} {:>12.2}",
                "",
                kernel,
                samples.len(),
                d * 1e3,
                d * 1e6 / samples.len() as f64
            );
        }
    }
    outln!(
        "  {:<40} {:<28} {:>6} {:>12.4}",
        "total",
        "",
        "",
        total * 1e3
    );
    let last: Vec<&str> = stats
        .profile
        .iter()
        .filter(|r| r.last_step_only)
        .map(|r| r.label.as_str())
        .collect();
    if !last.is_empty() {
        outln!(
            "  run on the last step only (only outputs read them): {}",
            last.join(", ")
        );
    }
}

fn validate(registry: &Registry, graphs: &[PathBuf]) -> Result<(), CliError> {
    let mut failures = Vec::new();
    for path in graphs {
        match scene_of(path, None) {
            Ok(Some(s)) => match validate_scene(registry, path, &s) {
                Ok(summary) => outln!("{}: ok ({summary})", path.display()),
                Err(e) => failures.push(format!("{}: {e}\n", path.display())),
            },
            Err(e) => failures.push(format!("{e}\n")),
            Ok(None) => match plan::validate_file(registry, &resolve(path)) {
                Ok(summary) => outln!("{}: ok ({summary})", path.display()),
                Err(e) => failures.push(e.to_string()),
            },
        }
    }
    if failures.is_empty() {
        Ok(())
    } else {
        Err(CliError::Input(failures.join("")))
    }
}

/// A scene's graph loaded and planned for its particles, on device-independent
/// capabilities (as `validate` plans graph files).
fn validate_scene(registry: &Registry, path: &Path, s: &CompiledScene) -> Result<String, CliError> {
    let g = load_graph(registry, path, Some(s), &LoadOptions::default())?;
    let opts = PlanOptions {
        outputs: None,
        inputs: s.inputs.iter().map(|(k, v)| (k.clone(), v.ty)).collect(),
        fuse: true,
        in_place: true,
    };
    let caps = DeviceCaps {
        max_binding: u64::MAX,
        max_buffer: u64::MAX,
        ..DeviceCaps::baseline()
    };
    let p = plan::plan(&g, &opts, &caps).map_err(|e| CliError::Input(e.to_string()))?;
    Ok(format!(
        "scene: {} particles of {} species, {} nodes, {} launches per step",
        s.species.typeid.len(),
        s.species.names.len(),
        g.nodes.len(),
        p.launches_every_step()
    ))
}

#[allow(clippy::too_many_arguments)]
fn inspect(
    registry: &Registry,
    path: &Path,
    scene: Option<CompiledScene>,
    graph_text: bool,
    sets: &[String],
    input_args: &[String],
    with: &[String],
    outputs: &[String],
    steps: u64,
    fuse: bool,
    in_place: bool,
    deterministic: bool,
    dot: bool,
) -> Result<(), CliError> {
    if graph_text {
        let Some(s) = &scene else {
            return Err(CliError::Input(format!(
                "--graph-text: {} is a graph file, not a scene",
                path.display()
            )));
        };
        outln!("{}", s.graph);
        return Ok(());
    }
    let overrides = parse_sets(sets)?;
    let g = load_graph(
        registry,
        path,
        scene.as_ref(),
        &LoadOptions {
            overrides,
            steps,
            seed: 0,
        },
    )?;
    let mut given: BTreeMap<String, ValueType> = read_inputs(&g, input_args)?
        .into_iter()
        .map(|(name, arr)| (name, arr.ty))
        .collect();
    if let Some(s) = &scene {
        for (name, a) in &s.inputs {
            given.entry(name.clone()).or_insert(a.ty);
        }
    }
    for name in with {
        match g.inputs.iter().find(|i| &i.name == name) {
            Some(i) if i.optional => {}
            Some(_) => {
                return Err(CliError::Input(format!(
                    "--with {name}: input `{name}` is required (planned in any case)"
                )));
            }
            None => {
                let known: Vec<&str> = g.inputs.iter().map(|i| i.name.as_str()).collect();
                return Err(CliError::Input(format!(
                    "--with {name}: no such input (inputs: {})",
                    known.join(", ")
                )));
            }
        }
    }
    let with: Vec<&str> = with.iter().map(String::as_str).collect();
    let inputs = g.assumed_input_types(&given, &with);
    let caps = DeviceCaps {
        deterministic,
        ..match GpuContext::new() {
            Ok(gpu) => gpu.caps.clone(),
            Err(_) => DeviceCaps::baseline(),
        }
    };
    let opts = PlanOptions {
        outputs: Some(outputs.to_vec()),
        inputs,
        fuse,
        in_place,
    };
    let p = plan_requested(&g, &opts, outputs.is_empty(), &caps)?;
    if dot {
        out!("{}", plan::to_dot(&g, &p));
    } else {
        out!("{}", plan::to_text(&g, &p));
    }
    Ok(())
}

fn nodes(registry: &Registry, only: Option<&str>) -> Result<(), CliError> {
    let mut shown = 0;
    for k in registry.kinds() {
        if only.is_some_and(|o| o != k.name()) {
            continue;
        }
        shown += 1;
        outln!("{}: {}", k.name(), k.doc());
        for p in k.inputs() {
            outln!(
                "  in   {:<14} {}{} - {}",
                p.name,
                p.ty,
                if p.optional { " (optional)" } else { "" },
                p.doc
            );
        }
        for p in k.outputs() {
            let mut marks = String::new();
            if p.persistent {
                marks.push_str(" (persistent)");
            }
            if let Some(i) = p.in_place_of {
                marks.push_str(&format!(" (in place of {i} where the plan can)"));
            }
            if let Some(i) = p.refilled_from {
                marks.push_str(&format!(" (refilled from {i}: the body may overwrite it)"));
            }
            if let Some(i) = p.started_from {
                marks.push_str(&format!(
                    " (started from {i}: in its buffer where the plan can)"
                ));
            }
            if let Some(c) = p.final_of {
                marks.push_str(&format!(
                    " (final value of {c}: in its buffer where the plan can)"
                ));
            }
            outln!("  out  {:<14} {}{marks} - {}", p.name, p.ty, p.doc);
        }
        for p in k.params() {
            outln!("  prm  {:<14} {} - {}", p.name, p.describe(), p.doc);
        }
        outln!();
    }
    let f32_ranged = registry
        .kinds()
        .filter(|k| only.is_none_or(|o| o == k.name()))
        .flat_map(|k| k.params())
        .any(|p| match p.kind {
            ParamKind::Number { max, .. } | ParamKind::Numbers { max, .. } => {
                max == mesoflow::node::F32_PARAM_MAX
            }
            _ => false,
        });
    if f32_ranged {
        outln!("{}", mesoflow::node::F32_RANGE_NOTE);
        outln!();
    }
    if only.is_none() {
        outln!("Host functions for param expressions (planning in f64 on the host):");
        for f in registry.functions().iter() {
            outln!("  {}", f.doc);
        }
    }
    if shown == 0 {
        let hint = only
            .and_then(|o| registry.suggest(o))
            .map(|s| format!(" (did you mean `{s}`?)"))
            .unwrap_or_default();
        return Err(CliError::Input(format!(
            "no node kind `{}`{hint}",
            only.unwrap_or("")
        )));
    }
    Ok(())
}
