//! The executor: compiles a [`Plan`] into buffers, pipelines and bind groups once, then
//! runs it. Only the executor submits to the queue.
//!
//! A run uploads the inputs, runs the prologue (state initial values), then records the
//! time steps into compute passes, many dispatches per pass and several steps per
//! submission, with at most two submissions in flight. Nothing comes back to the host
//! between steps: the step index lives in a GPU buffer (the clock) that a tiny kernel
//! advances at the end of every step, and states swap between two buffers by parity.

use std::collections::BTreeMap;
use std::time::Duration;

use thiserror::Error;

mod checkpoint;
mod compile;
mod profile;
mod run;

pub use profile::ProfileRow;

use crate::gpu::{
    Binding, CompileCtx, CompileError, Dispatch, GpuContext, GpuError, KernelCache, KernelSpec,
};
use crate::graph::{Graph, NodeId};
use crate::ids::IdVec;
use crate::node::{IterativeKernels, LoopError};
use crate::plan::{BufferId, Phase, Plan, Storage, ValueId};
use crate::value::{HostArray, HostWords, NonFinite};

pub use checkpoint::Checkpoint;

#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ExecError {
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error("node `{node}`: {source}")]
    Compile { node: String, source: CompileError },
    #[error("input `{name}`: {message}")]
    Input { name: String, message: String },
    /// An iterative node stopped without an answer (`step` counts from 1).
    #[error("node `{node}` ({kind}), step {step}: {source}")]
    Loop {
        node: String,
        kind: &'static str,
        step: u64,
        #[source]
        source: LoopError,
    },
    /// The device refused a launch's buffers or dispatches (wgpu validation), said as the
    /// launch's nodes and the values it binds rather than wgpu's own buffer labels.
    #[error("{launch}: the device refused it: {reason} (it binds {binds})")]
    Refused {
        launch: String,
        reason: String,
        binds: String,
    },
    /// The device could not allocate the plan's buffers.
    #[error(
        "the device cannot hold this plan's buffers ({planned} in all; `mesoflow inspect` lists them): {reason}"
    )]
    Memory { planned: String, reason: String },
    /// Outputs hold NaN or infinite values although every input was finite: something
    /// in the graph (a param, a division) left f32's range. Each output with its count
    /// and first index; the outputs themselves can still be read (`read_outputs`).
    #[error("{}", describe_non_finite(.0))]
    NonFinite(Vec<(String, NonFinite)>),
    #[error("{0}")]
    Run(String),
    /// A buffer of the plan is larger than the adapter allows; found before allocating.
    #[error(
        "{what} takes {bytes} bytes ({} MiB), more than this adapter's {limit} of {max} bytes ({} MiB); nothing was allocated",
        bytes >> 20,
        max >> 20
    )]
    TooLarge {
        what: String,
        bytes: u64,
        limit: &'static str,
        max: u64,
    },
}

/// Checks every buffer the plan will allocate against the adapter's limits before any
/// is created (wgpu would otherwise fail inside `create_buffer`): each one at most
/// `max_buffer_size` and, as kernels bind buffers whole, `max_storage_buffer_binding_size`.
/// wgpu does not expose the device's total memory, so the plan's total
/// (`MemoryReport::total`, what `inspect` prints) cannot be checked against it; a run
/// past it fails when the driver runs out.
fn check_buffer_sizes(gpu: &GpuContext, graph: &Graph, plan: &Plan) -> Result<(), ExecError> {
    let mut sized: Vec<(String, u64)> = Vec::new();
    for (i, t) in &plan.inputs {
        sized.push((format!("input `{}`", graph.inputs[*i].name), t.bytes()));
    }
    for s in &plan.states {
        sized.push((format!("state `{}`", s.name), s.ty.bytes()));
    }
    for (i, b) in plan.buffers.iter().enumerate() {
        sized.push((format!("planned buffer {i}"), b.bytes));
    }
    let caps = &gpu.caps;
    for (what, bytes) in sized {
        for (limit, max) in [
            ("max_buffer_size", caps.max_buffer),
            ("max_storage_buffer_binding_size", caps.max_binding),
        ] {
            if bytes.max(16).next_multiple_of(16) > max {
                return Err(ExecError::TooLarge {
                    what,
                    bytes,
                    limit,
                    max,
                });
            }
        }
    }
    Ok(())
}

/// What `--profile` times.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Profile {
    Off,
    /// Each launch in a compute pass of its own, timed with timestamps.
    Launches,
    /// Each dispatch in a compute pass of its own (the passes of an FFT, say).
    Dispatches,
    /// Whole steps end to end, each recorded as the unprofiled run records it
    /// (`RunStats::step_samples`).
    Steps,
}

/// How to run.
#[derive(Clone, Debug)]
pub struct RunOptions {
    pub steps: u64,
    /// Time launches or dispatches on the GPU (one host round trip per step).
    pub profile: Profile,
    /// Draw a progress bar (on a terminal only).
    pub progress: bool,
}

/// Host time a program's batched runs spent, summed over its runs (where a per-call cost
/// goes: Python's `Program.host_times`).
#[derive(Clone, Copy, Debug, Default)]
pub struct HostTimes {
    /// Recording the steps' dispatches and submitting them.
    pub submit: Duration,
    /// Waiting for the GPU.
    pub wait: Duration,
    /// Copying outputs out of the mapped readback buffers.
    pub read: Duration,
}

#[derive(Clone, Debug)]
pub struct RunStats {
    pub steps: u64,
    pub wall: Duration,
    /// Per-launch GPU times when profiling; `timed_by_gpu` says whether timestamps were used.
    pub profile: Vec<ProfileRow>,
    pub timed_by_gpu: bool,
    /// With `Profile::Steps`: each step's time from its first kernel's start to its last
    /// one's end, the gaps between kernels included (timed on the host around the step
    /// where `timed_by_gpu` is false).
    pub step_samples: Vec<Duration>,
}

struct Compiled {
    label: String,
    kinds: String,
    dispatches: Vec<Dispatch>,
    /// An iterative node with its body (its `dispatches` are then empty).
    looped: Option<std::sync::Arc<CompiledLoop>>,
    /// Only outputs read what it writes (`Plan::last_step_only`): it runs on the last
    /// step of a run only.
    last_only: bool,
}

struct CompiledLoop {
    node: NodeId,
    kernels: IterativeKernels,
    body: Vec<Compiled>,
    /// Readback buffers for the status, one per iteration in flight: iteration k copies
    /// into `staging[k % staging.len()]`.
    staging: Vec<wgpu::Buffer>,
    /// Where the GPU knows when the loop stopped (`IterativeKernels::gpu_stop`).
    gate: Option<LoopGate>,
    /// A gated loop's iterations at its last run: the size of its next first batch.
    last_iterations: std::sync::atomic::AtomicUsize,
}

/// Iterations of a gated loop's first batch, before any step has told how many it takes.
const FIRST_BATCH: usize = 2;

/// The indirect arguments of a gated loop's iteration: one (x, y, z) per dispatch of
/// [`CompiledLoop::iteration`], in its order, that `dispatch` (shaders/engine/gate.wgsl)
/// writes after `start` and after each iteration: the static counts while the loop runs,
/// zeros once its node has set its `stopped` word.
struct LoopGate {
    args: wgpu::Buffer,
    dispatch: Dispatch,
}

/// A step whose loops all stop on the GPU, recorded as one submission (exec/run.rs,
/// `submit_step_chained`): everything after its first loop's batch goes out as indirect
/// dispatches whose workgroup counts `tails` write (shaders/engine/gate.wgsl `tail`), one
/// after each loop's batch, for the dispatches up to the next loop's batch (its `finish`,
/// the launches between, the next loop's `start`; after the last loop, the clock tick
/// too): the static counts where the loop is done and every loop before it too, zeros
/// otherwise. The host reads the loops' statuses once, at the end; a loop its batch did
/// not finish goes on in further batches, then the step from that loop's tail on goes out
/// again.
struct StepChain {
    /// One (x, y, z) per slot: the dispatches after the first loop's batch in recording
    /// order (every dispatch of the step's launches, whether it runs on this step or not).
    args: wgpu::Buffer,
    /// After each loop (in the step's order), the gate of its tail.
    tails: Vec<Dispatch>,
    /// Each loop's first slot (its `finish`'s first dispatch).
    tail_first: Vec<usize>,
}

impl CompiledLoop {
    /// One iteration's dispatches: the body's, then the node's `iterate`.
    fn iteration(&self) -> impl Iterator<Item = &Dispatch> {
        self.body
            .iter()
            .flat_map(|c| &c.dispatches)
            .chain(&self.kernels.iterate)
    }

    /// A gated loop's batch: one iteration more than its last run took, so a loop that
    /// needs one more this time still stops within its first batch, while one that needs
    /// as many costs an iteration's launches (gated off).
    fn next_batch(&self) -> usize {
        self.last_iterations
            .load(std::sync::atomic::Ordering::Relaxed)
            .max(1)
            + 1
    }

    /// Copies the loop's status into its first staging buffer.
    fn copy_status(&self, enc: &mut wgpu::CommandEncoder) {
        let bytes = self.kernels.status_bytes.max(4).next_multiple_of(4);
        enc.copy_buffer_to_buffer(&self.kernels.status, 0, &self.staging[0], 0, bytes);
    }
}

impl Compiled {
    fn plain(label: String, kinds: String, dispatches: Vec<Dispatch>) -> Self {
        Compiled {
            label,
            kinds,
            dispatches,
            looped: None,
            last_only: false,
        }
    }

    /// Whether it runs on a step: every step, or, when only outputs read it, the last
    /// step of the run.
    fn runs_on(&self, last_step: bool) -> bool {
        last_step || !self.last_only
    }
}

/// A compiled plan, ready to run repeatedly.
pub struct Program<'a> {
    gpu: &'a GpuContext,
    graph: &'a Graph,
    plan: &'a Plan,
    input_buffers: BTreeMap<usize, wgpu::Buffer>,
    state_buffers: Vec<[wgpu::Buffer; 2]>,
    buffers: IdVec<BufferId, wgpu::Buffer>,
    clock: wgpu::Buffer,
    prologue: Vec<Compiled>,
    /// Step launches for even and odd steps (they differ only in state buffers).
    step: [Vec<Compiled>; 2],
    clock_tick: Dispatch,
    /// The chained form of each parity's step, where every loop stops on the GPU.
    chains: [Option<StepChain>; 2],
    /// Whether steps with loops go out chained (`chains`); on by default.
    chain_loops: bool,
    /// The chain word the loop gates and tail gates share (gate.wgsl): 1 while every
    /// loop of the step so far is done.
    loop_chain: wgpu::Buffer,
    /// Whether `loop_chain` may hold 0 (its start, or a tail gate that found its loop
    /// unfinished or failed): the next submission that needs it sets it first.
    chain_cleared: std::sync::atomic::AtomicBool,
    /// Pipelines built for this program (cache misses).
    pub kernels_built: usize,
    /// Bytes nodes allocated for uniforms and tables.
    pub table_bytes: u64,
    steps_done: u64,
    /// Iterations of each loop per step over the last run.
    iterations: Vec<(String, Vec<u32>)>,
    /// The inputs whose last upload held NaN or infinite values: then NaN or infinite
    /// outputs may come from them, and [`Program::check_finite`] does not judge.
    non_finite_inputs: std::collections::BTreeSet<String>,
    /// Host copies of the last data of the inputs that nodes check together
    /// (`Node::check_inputs_together`), for uploads that give only some of them.
    joint_inputs: BTreeMap<usize, HostArray>,
    /// One host-visible buffer per output, kept between reads (the plan's order).
    readback: Vec<wgpu::Buffer>,
    /// Host time of the batched runs so far.
    pub host_times: HostTimes,
}

fn storage_buffer(gpu: &GpuContext, label: &str, bytes: u64) -> wgpu::Buffer {
    gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes.max(16).next_multiple_of(16),
        usage: wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

impl<'a> Program<'a> {
    /// Allocates the plan's buffers and compiles every launch.
    pub fn compile(
        gpu: &'a GpuContext,
        graph: &'a Graph,
        plan: &'a Plan,
        cache: &mut KernelCache,
    ) -> Result<Self, ExecError> {
        check_buffer_sizes(gpu, graph, plan)?;
        let built_before = cache.built;
        // The plan's buffers, with what the device refuses (memory it lacks) said as the
        // plan's memory rather than as a buffer label.
        let out_of_memory = gpu.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let invalid = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let input_buffers = plan
            .inputs
            .iter()
            .map(|(i, t)| {
                (
                    *i,
                    storage_buffer(gpu, &format!("inputs.{}", graph.inputs[*i].name), t.bytes()),
                )
            })
            .collect();
        let state_buffers = plan
            .states
            .iter()
            .map(|s| {
                [
                    storage_buffer(gpu, &format!("state.{} A", s.name), s.ty.bytes()),
                    storage_buffer(gpu, &format!("state.{} B", s.name), s.ty.bytes()),
                ]
            })
            .collect();
        let buffers = plan
            .buffers
            .iter()
            .enumerate()
            .map(|(i, b)| storage_buffer(gpu, &format!("buf {i}"), b.bytes))
            .collect();
        let clock = storage_buffer(gpu, "clock", 16);
        let refused = [
            pollster::block_on(invalid.pop()),
            pollster::block_on(out_of_memory.pop()),
        ];
        if let Some(e) = refused.into_iter().flatten().next() {
            return Err(ExecError::Memory {
                planned: crate::plan::human_bytes(plan.memory.total()),
                reason: reason(&e),
            });
        }
        let mut cx = CompileCtx {
            gpu,
            kernels: cache,
            clock: &clock,
            allocated: std::cell::Cell::new(0),
        };
        let tick_kernel = cx
            .kernel(&KernelSpec::new(
                "clock_tick",
                cx.shader("engine/clock_tick.wgsl").map_err(engine_err)?,
                &[Binding::StorageReadWrite],
            ))
            .map_err(engine_err)?;
        let clock_tick = cx.dispatch(&tick_kernel, &[&clock], [1, 1, 1]);
        let mut program = Program {
            gpu,
            graph,
            plan,
            input_buffers,
            state_buffers,
            buffers,
            clock: clock.clone(),
            prologue: Vec::new(),
            step: [Vec::new(), Vec::new()],
            clock_tick,
            chains: [None, None],
            chain_loops: true,
            loop_chain: storage_buffer(gpu, "loop chain", 4),
            chain_cleared: true.into(),
            kernels_built: 0,
            table_bytes: 0,
            steps_done: 0,
            iterations: Vec::new(),
            non_finite_inputs: Default::default(),
            joint_inputs: BTreeMap::new(),
            readback: Vec::new(),
            host_times: HostTimes::default(),
        };
        program.readback = program
            .plan
            .outputs
            .iter()
            .map(|(name, v)| {
                program.gpu.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(&format!("readback {name}")),
                    size: program.plan.values[*v]
                        .ty
                        .bytes()
                        .max(4)
                        .next_multiple_of(4),
                    usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                })
            })
            .collect();
        let mut prologue = Vec::new();
        for l in &plan.prologue {
            prologue.push(program.compile_checked(&mut cx, l, 0)?);
        }
        let mut even = Vec::new();
        let mut odd = Vec::new();
        for (i, l) in plan.step.iter().enumerate() {
            let mut c0 = program.compile_checked(&mut cx, l, 0)?;
            c0.last_only = plan.last_step_only.contains(&i);
            let touches_state = l
                .reads()
                .into_iter()
                .chain(l.writes())
                .any(|v| matches!(plan.values[v].storage, Storage::State { .. }));
            let c1 = if touches_state {
                Compiled {
                    last_only: c0.last_only,
                    ..program.compile_checked(&mut cx, l, 1)?
                }
            } else {
                Compiled {
                    label: c0.label.clone(),
                    kinds: c0.kinds.clone(),
                    dispatches: c0.dispatches.clone(),
                    looped: c0.looped.clone(),
                    last_only: c0.last_only,
                }
            };
            even.push(c0);
            odd.push(c1);
        }
        let table_bytes = cx.allocated.get();
        program.prologue = prologue;
        program.step = [even, odd];
        program.chains = [
            program.compile_chain(&mut cx, 0)?,
            program.compile_chain(&mut cx, 1)?,
        ];
        program.table_bytes = table_bytes;
        program.kernels_built = cache.built - built_before;
        gpu.take_errors()?;
        Ok(program)
    }

    /// Compiles a launch with the device's validation errors caught: its buffers, bind
    /// groups and pipelines, and its dispatches recorded once into a pass that is never
    /// submitted (what wgpu checks when a pass is encoded: workgroup counts, bindings).
    /// A launch the device refuses is reported as its nodes and the values it binds, not
    /// as wgpu's internal labels (`fill4`, `sum partial`).
    fn compile_checked(
        &self,
        cx: &mut CompileCtx,
        l: &crate::plan::Launch,
        parity: usize,
    ) -> Result<Compiled, ExecError> {
        let scope = self
            .gpu
            .device
            .push_error_scope(wgpu::ErrorFilter::Validation);
        let compiled = self.compile_launch(cx, l, parity);
        if let Ok(c) = &compiled {
            let mut enc = self.gpu.device.create_command_encoder(&Default::default());
            {
                let mut pass = enc.begin_compute_pass(&Default::default());
                c.record_all(&mut pass);
            }
            drop(enc.finish());
        }
        let refused = pollster::block_on(scope.pop());
        let compiled = compiled?;
        match refused {
            None => Ok(compiled),
            Some(e) => Err(ExecError::Refused {
                launch: self.describe_launch(l),
                reason: reason(&e),
                binds: self.describe_bindings(l),
            }),
        }
    }

    /// A launch as users know it: its node, or its nodes.
    fn describe_launch(&self, l: &crate::plan::Launch) -> String {
        let nodes: Vec<String> = l
            .nodes()
            .iter()
            .map(|&n| {
                let inst = &self.graph.nodes[n];
                format!("`{}` ({})", inst.id, inst.kind)
            })
            .collect();
        match nodes.len() {
            0 => "the engine's state copy".into(),
            1 => format!("node {}", nodes[0]),
            _ => format!("nodes {}", nodes.join(", ")),
        }
    }

    /// The values a launch binds, with their types and sizes.
    fn describe_bindings(&self, l: &crate::plan::Launch) -> String {
        let mut seen = Vec::new();
        for v in l.reads().into_iter().chain(l.writes()) {
            if !seen.contains(&v) {
                seen.push(v);
            }
        }
        seen.iter()
            .map(|&v| {
                let value = &self.plan.values[v];
                format!("{} {}, {} bytes", value.name, value.ty, value.ty.bytes())
            })
            .collect::<Vec<_>>()
            .join("; ")
    }

    /// The buffer of a value for a step of the given parity.
    fn buffer(&self, v: ValueId, parity: usize) -> &wgpu::Buffer {
        match self.plan.values[v].storage {
            Storage::Input(i) => &self.input_buffers[&i],
            Storage::State { state, next } => {
                &self.state_buffers[state][if next { 1 - parity } else { parity }]
            }
            Storage::Buffer(b) => &self.buffers[b],
            Storage::Register | Storage::Pending(_) => {
                panic!("value `{}` has no buffer", self.plan.values[v].name)
            }
        }
    }

    /// Uploads the given graph inputs; their types must be the planned ones, and the
    /// nodes that read them check their data first (`Graph::check_input_data`): nothing is
    /// written unless every input passes. Notes whether any holds NaN or infinite values
    /// ([`Program::non_finite_input`]). Every input the plan reads must be given.
    pub fn upload(&mut self, inputs: &BTreeMap<String, HostArray>) -> Result<(), ExecError> {
        self.write_inputs(inputs, true)
    }

    /// As [`Program::upload`], for some of the inputs: the others keep what their buffers
    /// hold (the last upload's data). An input the plan does not read is an error.
    pub fn update_inputs(&mut self, inputs: &BTreeMap<String, HostArray>) -> Result<(), ExecError> {
        for name in inputs.keys() {
            if !self
                .plan
                .inputs
                .iter()
                .any(|(i, _)| &self.graph.inputs[*i].name == name)
            {
                return Err(ExecError::Input {
                    name: name.clone(),
                    message: "is not an input the program reads".into(),
                });
            }
        }
        self.write_inputs(inputs, false)
    }

    /// As [`Program::update_inputs`], from borrowed words (no host copy unless a node
    /// checks the input's data): every input named is checked before any is written.
    pub fn update_input_words(
        &mut self,
        inputs: &[(&str, HostWords<'_>)],
    ) -> Result<(), ExecError> {
        let mut given = Vec::new();
        for &(name, words) in inputs {
            let Some(&(i, t)) = self
                .plan
                .inputs
                .iter()
                .find(|(i, _)| self.graph.inputs[*i].name == name)
            else {
                return Err(ExecError::Input {
                    name: name.to_string(),
                    message: "is not an input the program reads".into(),
                });
            };
            if words.len() as u64 != t.words() || words.elem() != t.elem() {
                return Err(ExecError::Input {
                    name: name.to_string(),
                    message: format!(
                        "planned as {t}, given {} {:?} words",
                        words.len(),
                        words.elem()
                    ),
                });
            }
            if self.graph.input_is_checked(i, &self.plan.pruned) {
                self.graph
                    .check_input_data(i, &words.to_array(t), &self.plan.pruned)
                    .map_err(|e| ExecError::Input {
                        name: name.to_string(),
                        message: e.to_string(),
                    })?;
            }
            given.push((i, name, words));
        }
        let joint = self.graph.jointly_checked_inputs(&self.plan.pruned);
        let arrays: BTreeMap<usize, HostArray> = given
            .iter()
            .filter(|(i, _, _)| joint.contains(i))
            .map(|&(i, _, words)| {
                let t = self
                    .plan
                    .inputs
                    .iter()
                    .find(|(j, _)| *j == i)
                    .expect("found")
                    .1;
                (i, words.to_array(t))
            })
            .collect();
        self.check_joint(&arrays)?;
        self.joint_inputs.extend(arrays);
        for (i, name, words) in given {
            if words.all_finite() {
                self.non_finite_inputs.remove(name);
            } else {
                self.non_finite_inputs.insert(name.to_string());
            }
            if !words.is_empty() {
                self.gpu
                    .queue
                    .write_buffer(&self.input_buffers[&i], 0, words.as_bytes());
            }
        }
        Ok(())
    }

    fn write_inputs(
        &mut self,
        inputs: &BTreeMap<String, HostArray>,
        all: bool,
    ) -> Result<(), ExecError> {
        let mut given = Vec::new();
        for (i, t) in &self.plan.inputs {
            let name = &self.graph.inputs[*i].name;
            let Some(a) = inputs.get(name) else {
                if all {
                    return Err(ExecError::Input {
                        name: name.clone(),
                        message: "not given".into(),
                    });
                }
                continue;
            };
            if a.ty != *t {
                return Err(ExecError::Input {
                    name: name.clone(),
                    message: format!("planned as {t}, given {}", a.ty),
                });
            }
            self.graph
                .check_input_data(*i, a, &self.plan.pruned)
                .map_err(|e| ExecError::Input {
                    name: name.clone(),
                    message: e.to_string(),
                })?;
            given.push((i, a));
        }
        let joint = self.graph.jointly_checked_inputs(&self.plan.pruned);
        let arrays: BTreeMap<usize, HostArray> = given
            .iter()
            .filter(|(i, _)| joint.contains(i))
            .map(|&(&i, a)| (i, a.clone()))
            .collect();
        self.check_joint(&arrays)?;
        if all {
            self.joint_inputs.clear();
        }
        self.joint_inputs.extend(arrays);
        if all {
            self.non_finite_inputs.clear();
        }
        for (i, a) in given {
            let name = &self.graph.inputs[*i].name;
            if a.non_finite().is_some() {
                self.non_finite_inputs.insert(name.clone());
            } else {
                self.non_finite_inputs.remove(name);
            }
            if !a.data.is_empty() {
                self.gpu
                    .queue
                    .write_buffer(&self.input_buffers[i], 0, a.data.as_bytes());
            }
        }
        Ok(())
    }

    /// The checks of data by several inputs together (`Node::check_inputs_together`) on
    /// `given` (input index to data) beside the kept copies of the other inputs.
    fn check_joint(&self, given: &BTreeMap<usize, HostArray>) -> Result<(), ExecError> {
        if given.is_empty() {
            return Ok(());
        }
        self.graph
            .check_joint_input_data(
                |i| given.get(&i).or_else(|| self.joint_inputs.get(&i)),
                &self.plan.pruned,
            )
            .map_err(|(name, e)| ExecError::Input {
                name,
                message: e.to_string(),
            })
    }

    /// The first input of the last upload that holds NaN or infinite values, if any.
    pub fn non_finite_input(&self) -> Option<&str> {
        self.non_finite_inputs.first().map(|s| s.as_str())
    }

    /// Checks outputs read back after a run for NaN and infinite values:
    /// [`ExecError::NonFinite`] naming every output that holds some, when every input was
    /// finite. Where an input held NaN or infinite values they may flow to the outputs
    /// legitimately, and nothing is checked (`non_finite_input` says which input).
    pub fn check_finite(&self, outputs: &[(String, HostArray)]) -> Result<(), ExecError> {
        if !self.non_finite_inputs.is_empty() {
            return Ok(());
        }
        let found: Vec<(String, NonFinite)> = outputs
            .iter()
            .filter_map(|(name, a)| Some((name.clone(), a.non_finite()?)))
            .collect();
        if found.is_empty() {
            Ok(())
        } else {
            Err(ExecError::NonFinite(found))
        }
    }

    /// [`Program::read_outputs`], then [`Program::check_finite`]: the outputs, or the error
    /// naming those that hold NaN or infinite values from finite inputs.
    pub fn read_finite_outputs(&self) -> Result<Vec<(String, HostArray)>, ExecError> {
        let out = self.read_outputs()?;
        self.check_finite(&out)?;
        Ok(out)
    }

    /// Reads back the requested outputs (their values after the last step run): one
    /// submission copies them all into the readback buffers, one wait. After a run that
    /// failed at a step, an output that is a state holds the last kept step's value; any
    /// other may hold the failed step's partial work or an earlier run's value (the
    /// launches only outputs read run on a run's last step), so read those only after a
    /// run that succeeded (the CLI and the Python package give no outputs of a failed run).
    pub fn read_outputs(&self) -> Result<Vec<(String, HostArray)>, ExecError> {
        if self.steps_done == 0 {
            return Err(ExecError::Run("outputs are read after a run".into()));
        }
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        self.record_output_copies(&mut enc, self.steps_done - 1);
        let idx = self.gpu.queue.submit([enc.finish()]);
        let mapped = self.map_readback();
        self.gpu.wait(idx)?;
        self.collect_readback(mapped)
    }

    /// Records the copies of every output after step `last_step` into the readback
    /// buffers.
    fn record_output_copies(&self, enc: &mut wgpu::CommandEncoder, last_step: u64) {
        let parity = (last_step % 2) as usize;
        for ((_, v), staging) in self.plan.outputs.iter().zip(&self.readback) {
            enc.copy_buffer_to_buffer(self.buffer(*v, parity), 0, staging, 0, staging.size());
        }
    }

    /// Asks for every readback buffer to be mapped once the submitted copies are done:
    /// the receivers of the map results.
    fn map_readback(&self) -> Vec<std::sync::mpsc::Receiver<Result<(), wgpu::BufferAsyncError>>> {
        self.readback
            .iter()
            .map(|staging| {
                let (tx, rx) = std::sync::mpsc::channel();
                staging.slice(..).map_async(wgpu::MapMode::Read, move |r| {
                    let _ = tx.send(r);
                });
                rx
            })
            .collect()
    }

    /// The outputs from the mapped readback buffers (after the wait), each copied once.
    fn collect_readback(
        &self,
        mapped: Vec<std::sync::mpsc::Receiver<Result<(), wgpu::BufferAsyncError>>>,
    ) -> Result<Vec<(String, HostArray)>, ExecError> {
        // Every buffer that mapped is unmapped, errors or not, so the next read can map it.
        let mut out = Vec::new();
        let mut failed = None;
        for (((name, v), staging), rx) in self.plan.outputs.iter().zip(&self.readback).zip(mapped) {
            let read = match rx.recv() {
                Err(_) => Err(GpuError::Device("buffer map callback never ran".into())),
                Ok(Err(e)) => Err(GpuError::Device(format!(
                    "mapping a readback buffer failed: {e}"
                ))),
                Ok(Ok(())) => {
                    let ty = self.plan.values[*v].ty;
                    let array = staging
                        .slice(..)
                        .get_mapped_range()
                        .map(|bytes| HostArray::from_bytes(ty, &bytes))
                        .map_err(|e| {
                            GpuError::Device(format!("reading a mapped buffer failed: {e}"))
                        });
                    staging.unmap();
                    array
                }
            };
            match read {
                Ok(array) => out.push((name.clone(), array)),
                Err(e) => failed = failed.or(Some(e)),
            }
        }
        match failed {
            Some(e) => Err(e.into()),
            None => Ok(out),
        }
    }

    /// The outputs the program computes, in the plan's order.
    pub fn output_names(&self) -> Vec<String> {
        self.plan
            .outputs
            .iter()
            .map(|(name, _)| name.clone())
            .collect()
    }

    /// Number of dispatches recorded per step (the clock tick included; the launches
    /// only outputs read, which run on a run's last step only, counted too).
    pub fn dispatches_per_step(&self) -> usize {
        self.step[0]
            .iter()
            .map(|c| c.dispatches.len())
            .sum::<usize>()
            + 1
    }

    /// Which phase each compiled launch belongs to, with its label (for reports).
    pub fn launch_labels(&self) -> Vec<(Phase, String)> {
        self.prologue
            .iter()
            .map(|c| (Phase::Prologue, c.label.clone()))
            .chain(self.step[0].iter().map(|c| (Phase::Step, c.label.clone())))
            .collect()
    }
}

impl Compiled {
    /// Records every dispatch, whatever its step schedule, with a loop's body and its
    /// start, iteration and finish (for validation: never submitted).
    fn record_all(&self, pass: &mut wgpu::ComputePass) {
        let mut all: Vec<&Dispatch> = self.dispatches.iter().collect();
        if let Some(lp) = &self.looped {
            all.extend(&lp.kernels.start);
            for c in &lp.body {
                c.record_all(pass);
            }
            all.extend(&lp.kernels.iterate);
            all.extend(&lp.kernels.finish);
            if let Some(gate) = &lp.gate {
                all.push(&gate.dispatch);
                // The gated iteration as the executor records it.
                for (i, d) in lp.iteration().enumerate() {
                    if !d.workgroups.contains(&0) {
                        Program::record_gated(pass, d, &gate.args, i);
                    }
                }
            }
        }
        for d in all {
            if d.workgroups.contains(&0) {
                continue;
            }
            pass.set_pipeline(&d.kernel.pipeline);
            pass.set_bind_group(0, &d.bind_group, &[]);
            pass.dispatch_workgroups(d.workgroups[0], d.workgroups[1], d.workgroups[2]);
        }
    }
}

/// What wgpu says is wrong, without where it says it happened: the innermost error of its
/// chain (`Buffer binding 0 range ... exceeds ... limit ...`), without the labels of the
/// engine's buffers and kernels, which name nothing a user wrote.
fn reason(e: &wgpu::Error) -> String {
    let mut inner: &dyn std::error::Error = e;
    while let Some(next) = inner.source() {
        inner = next;
    }
    let mut text = inner.to_string();
    // wgpu names resources as "Buffer with 'LABEL' label".
    while let Some(start) = text.find(" with '") {
        let Some(len) = text[start + 7..].find("' label") else {
            break;
        };
        text.replace_range(start..start + 7 + len + 7, "");
    }
    text.trim().to_string()
}

/// "output `velocities` has 3 NaN of 30 values, the first at index 4 (NaN); ...".
fn describe_non_finite(found: &[(String, NonFinite)]) -> String {
    let each: Vec<String> = found
        .iter()
        .map(|(name, f)| format!("output `{name}` has {f}"))
        .collect();
    format!(
        "{}, from finite inputs: a param or an operation of the graph left f32's range (a division by zero, a factor too large)",
        each.join("; ")
    )
}

fn engine_err(source: CompileError) -> ExecError {
    ExecError::Compile {
        node: "(engine)".into(),
        source,
    }
}
