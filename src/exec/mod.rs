//! The executor: compiles a [`Plan`] into buffers, pipelines and bind groups once, then
//! runs it. Only the executor submits to the queue.
//!
//! A run uploads the inputs, runs the prologue (state initial values), then records the
//! time steps into compute passes, many dispatches per pass and several steps per
//! submission, with at most two submissions in flight. Nothing comes back to the host
//! between steps: the step index lives in a GPU buffer (the clock) that a tiny kernel
//! advances at the end of every step, and states swap between two buffers by parity.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use thiserror::Error;

use crate::gpu::{
    Binding, CompileCtx, CompileError, Dispatch, GpuContext, GpuError, KernelCache, KernelSpec,
    NodeIo, NodePlan, Slot, WG_1D,
};
use crate::graph::{Graph, NodeId};
use crate::ids::IdVec;
use crate::node::{Decision, IterativeKernels, LoopError, Lowering};
use crate::plan::{BufferId, FusedKernel, Launch, Phase, Plan, Storage, TransformFold, ValueId};
use crate::transform;
use crate::value::HostArray;

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
    #[error("{0}")]
    Run(String),
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

/// GPU time of one launch over a run.
#[derive(Clone, Debug)]
pub struct ProfileRow {
    pub label: String,
    pub kinds: String,
    pub dispatches: usize,
    pub calls: u64,
    pub total: Duration,
    /// The time of each call, in order.
    pub samples: Vec<Duration>,
    /// With `Profile::Dispatches`: each dispatch's kernel label and its time per call.
    pub dispatch_samples: Vec<(String, Vec<Duration>)>,
}

impl ProfileRow {
    fn of(c: &Compiled) -> Self {
        ProfileRow {
            label: c.label.clone(),
            kinds: c.kinds.clone(),
            dispatches: c.dispatches.len(),
            calls: 0,
            total: Duration::ZERO,
            samples: Vec::new(),
            dispatch_samples: c
                .dispatches
                .iter()
                .map(|d| (d.kernel.label.clone(), Vec::new()))
                .collect(),
        }
    }

    /// One more call taking `dt`.
    fn add(&mut self, dt: Duration) {
        self.total += dt;
        self.samples.push(dt);
        self.calls += 1;
    }

    /// Median time of one call.
    pub fn median(&self) -> Duration {
        let mut s = self.samples.clone();
        s.sort();
        if s.is_empty() {
            Duration::ZERO
        } else {
            s[s.len() / 2]
        }
    }
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

/// Timestamp queries for the timed units of a profiled step, two per unit.
struct StepTimer {
    units: Vec<(usize, Option<usize>)>,
    queries: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    /// Nanoseconds per tick.
    period: f64,
}

impl StepTimer {
    fn new(gpu: &GpuContext, units: Vec<(usize, Option<usize>)>) -> Self {
        let count = (2 * units.len()).max(2) as u32;
        StepTimer {
            queries: gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("profile"),
                ty: wgpu::QueryType::Timestamp,
                count,
            }),
            resolve: gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("profile resolve"),
                size: 8 * count as u64,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            }),
            period: gpu.queue.get_timestamp_period() as f64,
            units,
        }
    }
}

struct Compiled {
    label: String,
    kinds: String,
    dispatches: Vec<Dispatch>,
    /// An iterative node with its body (its `dispatches` are then empty).
    looped: Option<std::sync::Arc<CompiledLoop>>,
}

struct CompiledLoop {
    node: NodeId,
    kernels: IterativeKernels,
    body: Vec<Compiled>,
    /// Two readback buffers for the status: iteration k copies into `staging[k % 2]`.
    staging: [wgpu::Buffer; 2],
}

impl Compiled {
    fn plain(label: String, kinds: String, dispatches: Vec<Dispatch>) -> Self {
        Compiled {
            label,
            kinds,
            dispatches,
            looped: None,
        }
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
    /// Pipelines built for this program (cache misses).
    pub kernels_built: usize,
    /// Bytes nodes allocated for uniforms and tables.
    pub table_bytes: u64,
    steps_done: u64,
    /// Iterations of each loop per step over the last run.
    iterations: Vec<(String, Vec<u32>)>,
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
        let built_before = cache.built;
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
            kernels_built: 0,
            table_bytes: 0,
            steps_done: 0,
            iterations: Vec::new(),
        };
        let mut prologue = Vec::new();
        for l in &plan.prologue {
            prologue.push(program.compile_launch(&mut cx, l, 0)?);
        }
        let mut even = Vec::new();
        let mut odd = Vec::new();
        for l in &plan.step {
            let c0 = program.compile_launch(&mut cx, l, 0)?;
            let touches_state = l
                .reads()
                .into_iter()
                .chain(l.writes())
                .any(|v| matches!(plan.values[v].storage, Storage::State { .. }));
            let c1 = if touches_state {
                program.compile_launch(&mut cx, l, 1)?
            } else {
                Compiled {
                    label: c0.label.clone(),
                    kinds: c0.kinds.clone(),
                    dispatches: c0.dispatches.clone(),
                    looped: c0.looped.clone(),
                }
            };
            even.push(c0);
            odd.push(c1);
        }
        let table_bytes = cx.allocated.get();
        program.prologue = prologue;
        program.step = [even, odd];
        program.table_bytes = table_bytes;
        program.kernels_built = cache.built - built_before;
        gpu.take_errors()?;
        Ok(program)
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

    /// The buffers a node's launch binds, for a step of the given parity.
    fn node_io<'p>(
        &'p self,
        inputs: &[Option<ValueId>],
        outputs: &[ValueId],
        scratch: &[ValueId],
        plan: Option<&'p NodePlan>,
        parity: usize,
    ) -> NodeIo<'p> {
        let slot = |v: ValueId| Slot {
            buffer: self.buffer(v, parity),
            ty: self.plan.values[v].ty,
        };
        NodeIo {
            inputs: inputs.iter().map(|v| v.map(slot)).collect(),
            outputs: outputs.iter().map(|&v| slot(v)).collect(),
            scratch: scratch.iter().map(|&v| self.buffer(v, parity)).collect(),
            plan,
        }
    }

    /// Compiles one launch for a step of the given parity, by its kind.
    fn compile_launch(
        &self,
        cx: &mut CompileCtx,
        l: &Launch,
        parity: usize,
    ) -> Result<Compiled, ExecError> {
        match l {
            Launch::Node {
                node,
                inputs,
                outputs,
                scratch,
                plan,
                ..
            } => {
                let io = self.node_io(inputs, outputs, scratch, plan.as_ref(), parity);
                self.compile_node(cx, *node, &io)
            }
            Launch::Transform {
                node,
                inputs,
                outputs,
                scratch,
                plan,
                fold,
                ..
            } => {
                // A transform that hosts a spectral node writes the latter's output.
                let outputs = match fold {
                    TransformFold::Hosts(f) => std::slice::from_ref(&f.output),
                    _ => outputs.as_slice(),
                };
                let io = self.node_io(inputs, outputs, scratch, plan.as_ref(), parity);
                self.compile_transform(cx, *node, fold, &io)
            }
            Launch::Fused(k) => self.compile_fused(cx, k, parity),
            Launch::Copy { src, dst } => self.compile_copy(cx, *src, *dst, parity),
            Launch::Loop {
                node,
                inputs,
                outputs,
                scratch,
                plan,
                body,
                ..
            } => {
                let io = self.node_io(inputs, outputs, scratch, plan.as_ref(), parity);
                self.compile_loop(cx, *node, body, &io, parity)
            }
        }
    }

    /// A node that records its own dispatches, or a spectral node run alone.
    fn compile_node(
        &self,
        cx: &mut CompileCtx,
        node: NodeId,
        io: &NodeIo,
    ) -> Result<Compiled, ExecError> {
        let inst = &self.graph.nodes[node];
        let err = |source| ExecError::Compile {
            node: inst.id.clone(),
            source,
        };
        let dispatches = match inst.node.lowering() {
            Lowering::Kernels(k) => k.compile(cx, io).map_err(err)?,
            Lowering::Spectral(body) => {
                let input = io.inputs[0].ok_or_else(|| {
                    err(CompileError::Unsupported(
                        "a spectral node needs its input".into(),
                    ))
                })?;
                vec![
                    transform::standalone_dispatch(
                        cx,
                        "spectral",
                        &body,
                        Some(input.buffer),
                        io.outputs[0],
                    )
                    .map_err(err)?,
                ]
            }
            _ => panic!(
                "node `{}` scheduled as a single launch cannot run as one",
                inst.id
            ),
        };
        Ok(Compiled::plain(
            inst.id.clone(),
            inst.kind.to_string(),
            dispatches,
        ))
    }

    /// A transform with what it folds in.
    fn compile_transform(
        &self,
        cx: &mut CompileCtx,
        node: NodeId,
        fold: &TransformFold,
        io: &NodeIo,
    ) -> Result<Compiled, ExecError> {
        let g = self.graph;
        let inst = &g.nodes[node];
        let Lowering::Transform(t) = inst.node.lowering() else {
            panic!("node `{}` scheduled as a transform is not one", inst.id)
        };
        let err = |source| ExecError::Compile {
            node: inst.id.clone(),
            source,
        };
        let TransformFold::Hosts(f) = fold else {
            let dispatches = t.compile(cx, io, fold.folding(), None).map_err(err)?;
            return Ok(Compiled::plain(
                inst.id.clone(),
                inst.kind.to_string(),
                dispatches,
            ));
        };
        let s = &g.nodes[f.node];
        let Lowering::Spectral(body) = s.node.lowering() else {
            panic!("folded node `{}` is not spectral", s.id)
        };
        Ok(Compiled::plain(
            format!("{} + {}", inst.id, s.id),
            format!("{}+{}", inst.kind, s.kind),
            t.compile(cx, io, fold.folding(), Some(&body))
                .map_err(err)?,
        ))
    }

    /// A chain of element-wise nodes as its generated kernel.
    fn compile_fused(
        &self,
        cx: &mut CompileCtx,
        k: &FusedKernel,
        parity: usize,
    ) -> Result<Compiled, ExecError> {
        let g = self.graph;
        let ids: Vec<&str> = k.nodes.iter().map(|&n| g.nodes[n].id.as_str()).collect();
        let kinds: Vec<&str> = k.nodes.iter().map(|&n| g.nodes[n].kind).collect();
        let label = if ids.len() == 1 {
            ids[0].to_string()
        } else {
            format!("fused[{}]", ids.join(", "))
        };
        let mut bindings = vec![Binding::StorageRead];
        if k.uses_clock {
            bindings.push(Binding::StorageRead);
        }
        bindings.extend(k.inputs.iter().map(|_| Binding::StorageRead));
        bindings.extend(k.outputs.iter().map(|_| Binding::StorageReadWrite));
        let spec = KernelSpec::new(
            format!("pointwise {}", kinds.join("+")),
            k.source.clone(),
            &bindings,
        );
        let kernel = cx.kernel(&spec).map_err(|source| ExecError::Compile {
            node: label.clone(),
            source,
        })?;
        let params = cx.table("pointwise params", bytemuck::cast_slice(&k.params));
        let mut bufs: Vec<&wgpu::Buffer> = vec![&params];
        if k.uses_clock {
            bufs.push(cx.clock);
        }
        bufs.extend(k.inputs.iter().map(|&v| self.buffer(v, parity)));
        bufs.extend(k.outputs.iter().map(|&v| self.buffer(v, parity)));
        let d = cx.dispatch(&kernel, &bufs, cx.grid_1d(k.len, WG_1D));
        Ok(Compiled::plain(label, kinds.join("+"), vec![d]))
    }

    /// The engine's copy of a value into a state buffer.
    fn compile_copy(
        &self,
        cx: &mut CompileCtx,
        src: ValueId,
        dst: ValueId,
        parity: usize,
    ) -> Result<Compiled, ExecError> {
        let words = self.plan.values[src].ty.words();
        let kernel = cx
            .kernel(&KernelSpec::new(
                "copy",
                cx.shader("engine/copy.wgsl").map_err(engine_err)?,
                &[
                    Binding::StorageRead,
                    Binding::StorageReadWrite,
                    Binding::Uniform,
                ],
            ))
            .map_err(engine_err)?;
        let shape = cx.uniform("copy shape", bytemuck::bytes_of(&(words as u32)));
        let d = cx.dispatch(
            &kernel,
            &[self.buffer(src, parity), self.buffer(dst, parity), &shape],
            cx.grid_1d(words, WG_1D),
        );
        let label = format!("copy -> {}", self.plan.values[dst].name);
        Ok(Compiled::plain(label, "copy".into(), vec![d]))
    }

    /// An iterative node with its loop body and the staging buffers its decisions read.
    fn compile_loop(
        &self,
        cx: &mut CompileCtx,
        node: NodeId,
        body: &[Launch],
        io: &NodeIo,
        parity: usize,
    ) -> Result<Compiled, ExecError> {
        let inst = &self.graph.nodes[node];
        let Lowering::Iterative(it) = inst.node.lowering() else {
            panic!("node `{}` scheduled as a loop does not iterate", inst.id)
        };
        let kernels = it.compile(cx, io).map_err(|source| ExecError::Compile {
            node: inst.id.clone(),
            source,
        })?;
        let body = body
            .iter()
            .map(|l| self.compile_launch(cx, l, parity))
            .collect::<Result<Vec<_>, _>>()?;
        let staging = [0, 1].map(|i| {
            self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(&format!("{} status {i}", inst.id)),
                size: kernels.status_bytes.max(4).next_multiple_of(4),
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        });
        Ok(Compiled {
            label: inst.id.clone(),
            kinds: format!("{} (loop of {})", inst.kind, body.len()),
            dispatches: Vec::new(),
            looped: Some(std::sync::Arc::new(CompiledLoop {
                node,
                kernels,
                body,
                staging,
            })),
        })
    }

    /// Uploads the given graph inputs; their types must be the planned ones.
    pub fn upload(&self, inputs: &BTreeMap<String, HostArray>) -> Result<(), ExecError> {
        for (i, t) in &self.plan.inputs {
            let name = &self.graph.inputs[*i].name;
            let a = inputs.get(name).ok_or_else(|| ExecError::Input {
                name: name.clone(),
                message: "not given".into(),
            })?;
            if a.ty != *t {
                return Err(ExecError::Input {
                    name: name.clone(),
                    message: format!("planned as {t}, given {}", a.ty),
                });
            }
            if !a.data.is_empty() {
                self.gpu
                    .queue
                    .write_buffer(&self.input_buffers[i], 0, a.data.as_bytes());
            }
        }
        Ok(())
    }

    /// Records the dispatches that run on step `step` (see `Period`).
    fn record(pass: &mut wgpu::ComputePass, dispatches: &[Dispatch], step: u64) {
        for d in dispatches {
            if d.workgroups.contains(&0) || !d.runs_at(step) {
                continue;
            }
            pass.set_pipeline(&d.kernel.pipeline);
            pass.set_bind_group(0, &d.bind_group, &[]);
            pass.dispatch_workgroups(d.workgroups[0], d.workgroups[1], d.workgroups[2]);
        }
    }

    /// Resets persistent values and the clock, then runs the prologue.
    fn start(&mut self) -> Result<(), ExecError> {
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        for (b, info) in self.buffers.iter().zip(&self.plan.buffers) {
            if info.role == crate::plan::BufferRole::Persistent {
                enc.clear_buffer(b, 0, None);
            }
        }
        enc.clear_buffer(&self.clock, 0, None);
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            for c in &self.prologue {
                Self::record(&mut pass, &c.dispatches, 0);
            }
        }
        let idx = self.gpu.queue.submit([enc.finish()]);
        self.gpu.wait(idx)?;
        self.steps_done = 0;
        self.iterations.clear();
        Ok(())
    }

    fn has_loops(&self) -> bool {
        self.step[0].iter().any(|c| c.looped.is_some())
    }

    /// Submits the dispatches that run on step `step` in one compute pass.
    fn submit(&self, dispatches: &[&Dispatch], step: u64) -> wgpu::SubmissionIndex {
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            for d in dispatches {
                Self::record(&mut pass, std::slice::from_ref(*d), step);
            }
        }
        self.gpu.queue.submit([enc.finish()])
    }

    /// Runs an iterative node: `pending` (work recorded before it) goes out with the
    /// first iteration; each iteration ends with a host round trip that reads the node's
    /// status and asks it whether to go on. Leaves the node's finishing dispatches in
    /// `pending` and returns the number of iterations.
    fn run_loop<'p>(
        &'p self,
        lp: &'p CompiledLoop,
        pending: &mut Vec<&'p Dispatch>,
        step: u64,
    ) -> Result<u32, ExecError> {
        let inst = &self.graph.nodes[lp.node];
        let Lowering::Iterative(it) = inst.node.lowering() else {
            unreachable!("compiled as a loop")
        };
        // Iteration k goes out with a copy of the status after it. While the host reads
        // and judges iteration k, iteration k + 1 already runs (speculatively: when k
        // finishes, its work is discarded; it only wrote basis rows past the answer), so
        // the GPU does not idle through the round trip.
        let bytes = lp.kernels.status_bytes.max(4).next_multiple_of(4);
        let submit_iteration = |pending: &mut Vec<&'p Dispatch>, k: usize| {
            for c in &lp.body {
                pending.extend(&c.dispatches);
            }
            pending.extend(&lp.kernels.iterate);
            let mut enc = self.gpu.device.create_command_encoder(&Default::default());
            {
                let mut pass = enc.begin_compute_pass(&Default::default());
                for d in pending.iter() {
                    Self::record(&mut pass, std::slice::from_ref(*d), step);
                }
            }
            enc.copy_buffer_to_buffer(&lp.kernels.status, 0, &lp.staging[k % 2], 0, bytes);
            pending.clear();
            self.gpu.queue.submit([enc.finish()])
        };
        pending.extend(&lp.kernels.start);
        let mut iterations = 1usize;
        let mut current = submit_iteration(pending, iterations);
        loop {
            let next = submit_iteration(pending, iterations + 1);
            let staging = &lp.staging[iterations % 2];
            let (tx, rx) = std::sync::mpsc::channel();
            staging.slice(..).map_async(wgpu::MapMode::Read, move |r| {
                let _ = tx.send(r);
            });
            self.gpu.wait(current)?;
            rx.recv()
                .map_err(|_| GpuError::Device("buffer map callback never ran".into()))?
                .map_err(|e| GpuError::Device(format!("mapping a status buffer failed: {e}")))?;
            let status =
                staging.slice(..).get_mapped_range().map_err(|e| {
                    GpuError::Device(format!("reading a status buffer failed: {e}"))
                })?[..lp.kernels.status_bytes as usize]
                    .to_vec();
            staging.unmap();
            match it.decide(iterations, &status) {
                Ok(Decision::Continue) => {
                    iterations += 1;
                    current = next;
                }
                Ok(Decision::Finish(answer)) => {
                    self.gpu.queue.write_buffer(
                        &lp.kernels.answer,
                        lp.kernels.answer_offset,
                        &answer,
                    );
                    pending.extend(&lp.kernels.finish);
                    return Ok(iterations as u32);
                }
                Err(source) => {
                    return Err(ExecError::Loop {
                        node: inst.id.clone(),
                        kind: inst.kind,
                        step: step + 1,
                        source,
                    });
                }
            }
        }
    }

    /// Submits one step of a program with loops; returns the last submission and the
    /// iterations of each loop.
    fn submit_step_with_loops(
        &self,
        step: u64,
    ) -> Result<(wgpu::SubmissionIndex, Vec<u32>), ExecError> {
        let parity = (step % 2) as usize;
        let mut pending: Vec<&Dispatch> = Vec::new();
        let mut counts = Vec::new();
        for c in &self.step[parity] {
            match &c.looped {
                None => pending.extend(&c.dispatches),
                Some(lp) => counts.push(self.run_loop(lp, &mut pending, step)?),
            }
        }
        pending.push(&self.clock_tick);
        Ok((self.submit(&pending, step), counts))
    }

    /// Runs a loop alone and waits for it: its wall time (host round trips included) and
    /// its iterations.
    fn time_loop(&self, lp: &CompiledLoop, step: u64) -> Result<(Duration, u32), ExecError> {
        let t = Instant::now();
        let mut pending = Vec::new();
        let k = self.run_loop(lp, &mut pending, step)?;
        let idx = self.submit(&pending, step);
        self.gpu.wait(idx)?;
        Ok((t.elapsed(), k))
    }

    /// Iterations each loop took at every step of the last run, by node id.
    pub fn loop_iterations(&self) -> &[(String, Vec<u32>)] {
        &self.iterations
    }

    fn note_iterations(&mut self, counts: Vec<u32>) {
        if self.iterations.is_empty() {
            self.iterations = self.step[0]
                .iter()
                .filter(|c| c.looped.is_some())
                .map(|c| (c.label.clone(), Vec::new()))
                .collect();
        }
        for (row, k) in self.iterations.iter_mut().zip(counts) {
            row.1.push(k);
        }
    }

    /// Runs the prologue and `steps` time steps.
    pub fn run(&mut self, opts: &RunOptions) -> Result<RunStats, ExecError> {
        if opts.steps == 0 {
            return Err(ExecError::Run(
                "the number of steps must be at least 1".into(),
            ));
        }
        let t0 = Instant::now();
        self.start()?;
        let stats = match opts.profile {
            Profile::Off => self.run_batched(opts)?,
            Profile::Launches => self.run_profiled(opts.steps, false)?,
            Profile::Dispatches => self.run_profiled(opts.steps, true)?,
            Profile::Steps => self.run_timed_steps(opts.steps)?,
        };
        Ok(RunStats {
            wall: t0.elapsed(),
            ..stats
        })
    }

    fn run_batched(&mut self, opts: &RunOptions) -> Result<RunStats, ExecError> {
        let per_step: usize = self.step[0]
            .iter()
            .map(|c| c.dispatches.len())
            .sum::<usize>()
            + 1;
        // Several steps per submission, bounded so that the progress bar moves and the
        // driver's queue stays shallow.
        let steps_per_submit = ((4096 / per_step).max(1) as u64).min(opts.steps);
        let bar = if opts.progress && opts.steps > 1 {
            let b = indicatif::ProgressBar::new(opts.steps);
            b.set_style(
                indicatif::ProgressStyle::with_template(
                    "{bar:40} {pos}/{len} steps  {per_sec}  eta {eta}",
                )
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
            );
            Some(b)
        } else {
            None
        };
        let mut in_flight: Option<(wgpu::SubmissionIndex, u64)> = None;
        let mut done = 0;
        if self.has_loops() {
            // Loops decide on the host, so steps go out one at a time.
            while done < opts.steps {
                let (idx, counts) = self.submit_step_with_loops(self.steps_done + done)?;
                self.note_iterations(counts);
                self.gpu.wait(idx)?;
                done += 1;
                if let Some(b) = &bar {
                    b.inc(1);
                }
            }
        }
        while done < opts.steps {
            let n = steps_per_submit.min(opts.steps - done);
            let mut enc = self.gpu.device.create_command_encoder(&Default::default());
            {
                let mut pass = enc.begin_compute_pass(&Default::default());
                for s in 0..n {
                    let step = self.steps_done + done + s;
                    let parity = (step % 2) as usize;
                    for c in &self.step[parity] {
                        Self::record(&mut pass, &c.dispatches, step);
                    }
                    Self::record(&mut pass, std::slice::from_ref(&self.clock_tick), step);
                }
            }
            let idx = self.gpu.queue.submit([enc.finish()]);
            if let Some((prev, k)) = in_flight.take() {
                self.gpu.wait(prev)?;
                if let Some(b) = &bar {
                    b.inc(k);
                }
            }
            in_flight = Some((idx, n));
            done += n;
        }
        if let Some((prev, k)) = in_flight {
            self.gpu.wait(prev)?;
            if let Some(b) = &bar {
                b.inc(k);
            }
        }
        if let Some(b) = bar {
            b.finish_and_clear();
        }
        self.steps_done += opts.steps;
        Ok(RunStats {
            steps: opts.steps,
            wall: Duration::ZERO,
            profile: Vec::new(),
            timed_by_gpu: false,
            step_samples: Vec::new(),
        })
    }

    /// Runs steps one launch (or dispatch) per compute pass with timestamps around each
    /// pass, or with a wait after each launch where the device has no timestamp queries.
    fn run_profiled(&mut self, steps: u64, per_dispatch: bool) -> Result<RunStats, ExecError> {
        let mut rows: Vec<ProfileRow> = self.step[0].iter().map(ProfileRow::of).collect();
        let use_gpu = self.gpu.caps.timestamps;
        let timer = use_gpu.then(|| StepTimer::new(self.gpu, self.timed_units(per_dispatch)));
        for s in 0..steps {
            let step = self.steps_done + s;
            let counts = match &timer {
                Some(timer) => self.profile_step_by_timestamps(timer, step, &mut rows)?,
                None => self.profile_step_on_host(step, &mut rows)?,
            };
            self.note_iterations(counts);
        }
        self.steps_done += steps;
        Ok(RunStats {
            steps,
            wall: Duration::ZERO,
            profile: rows,
            timed_by_gpu: use_gpu,
            step_samples: Vec::new(),
        })
    }

    /// Times whole steps: each step's dispatches in one compute pass, recorded as
    /// `run_batched` records them, with timestamps written at the pass's beginning and
    /// end, one step per submission. A step's time thus runs from its first kernel's start
    /// to its last one's end, the gaps between kernels included: what CUDA events around
    /// a library call measure. A program with loops makes host round trips inside its
    /// steps, and a device without timestamp queries has no GPU clock to read: those
    /// steps are timed on the host, from the first submission to the end of the wait.
    fn run_timed_steps(&mut self, steps: u64) -> Result<RunStats, ExecError> {
        let by_gpu = self.gpu.caps.timestamps && !self.has_loops();
        let queries = by_gpu.then(|| {
            self.gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("step timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: 2,
            })
        });
        let resolve = self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("step timestamps resolve"),
            size: 16,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let period = self.gpu.queue.get_timestamp_period() as f64;
        let mut samples = Vec::with_capacity(steps as usize);
        for s in 0..steps {
            let step = self.steps_done + s;
            let parity = (step % 2) as usize;
            let Some(qs) = &queries else {
                let t = Instant::now();
                let idx = if self.has_loops() {
                    let (idx, counts) = self.submit_step_with_loops(step)?;
                    self.note_iterations(counts);
                    idx
                } else {
                    let dispatches: Vec<&Dispatch> = self.step[parity]
                        .iter()
                        .flat_map(|c| &c.dispatches)
                        .chain(std::iter::once(&self.clock_tick))
                        .collect();
                    self.submit(&dispatches, step)
                };
                self.gpu.wait(idx)?;
                samples.push(t.elapsed());
                continue;
            };
            let mut enc = self.gpu.device.create_command_encoder(&Default::default());
            {
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("step"),
                    timestamp_writes: Some(wgpu::ComputePassTimestampWrites {
                        query_set: qs,
                        beginning_of_pass_write_index: Some(0),
                        end_of_pass_write_index: Some(1),
                    }),
                });
                for c in &self.step[parity] {
                    Self::record(&mut pass, &c.dispatches, step);
                }
                Self::record(&mut pass, std::slice::from_ref(&self.clock_tick), step);
            }
            enc.resolve_query_set(qs, 0..2, &resolve, 0);
            let idx = self.gpu.queue.submit([enc.finish()]);
            self.gpu.wait(idx)?;
            let ticks: Vec<u64> =
                bytemuck::pod_collect_to_vec(&self.gpu.read_buffer(&resolve, 16)?);
            samples.push(Duration::from_nanos(
                (ticks[1].saturating_sub(ticks[0]) as f64 * period) as u64,
            ));
        }
        self.steps_done += steps;
        Ok(RunStats {
            steps,
            wall: Duration::ZERO,
            profile: Vec::new(),
            timed_by_gpu: by_gpu,
            step_samples: samples,
        })
    }

    /// The timed units of a step: each launch, or each dispatch of each launch. A loop is
    /// one unit, timed on the host (its decisions are host round trips).
    fn timed_units(&self, per_dispatch: bool) -> Vec<(usize, Option<usize>)> {
        if !per_dispatch {
            return (0..self.step[0].len()).map(|i| (i, None)).collect();
        }
        self.step[0]
            .iter()
            .enumerate()
            .flat_map(|(i, c)| {
                let whole = c.looped.is_some();
                let parts = if whole { 1 } else { c.dispatches.len() };
                (0..parts).map(move |d| (i, (!whole).then_some(d)))
            })
            .collect()
    }

    /// One step, each unit in a compute pass of its own between two timestamps.
    fn profile_step_by_timestamps(
        &self,
        timer: &StepTimer,
        step: u64,
        rows: &mut [ProfileRow],
    ) -> Result<Vec<u32>, ExecError> {
        let parity = (step % 2) as usize;
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        let mut host_timed: Vec<(usize, Duration)> = Vec::new();
        let mut counts = Vec::new();
        for (u, &(i, d)) in timer.units.iter().enumerate() {
            let c = &self.step[parity][i];
            if let Some(lp) = &c.looped {
                let before = std::mem::replace(
                    &mut enc,
                    self.gpu.device.create_command_encoder(&Default::default()),
                );
                let idx = self.gpu.queue.submit([before.finish()]);
                self.gpu.wait(idx)?;
                let (dt, k) = self.time_loop(lp, step)?;
                host_timed.push((u, dt));
                counts.push(k);
                continue;
            }
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(&c.label),
                timestamp_writes: Some(wgpu::ComputePassTimestampWrites {
                    query_set: &timer.queries,
                    beginning_of_pass_write_index: Some(2 * u as u32),
                    end_of_pass_write_index: Some(2 * u as u32 + 1),
                }),
            });
            match d {
                Some(d) => Self::record(&mut pass, std::slice::from_ref(&c.dispatches[d]), step),
                None => Self::record(&mut pass, &c.dispatches, step),
            }
        }
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            Self::record(&mut pass, std::slice::from_ref(&self.clock_tick), 0);
        }
        let timed = timer.units.len();
        if timed > 0 {
            enc.resolve_query_set(&timer.queries, 0..2 * timed as u32, &timer.resolve, 0);
        }
        let idx = self.gpu.queue.submit([enc.finish()]);
        self.gpu.wait(idx)?;
        if timed == 0 {
            return Ok(counts);
        }
        let bytes = self.gpu.read_buffer(&timer.resolve, 16 * timed as u64)?;
        let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&bytes);
        let mut per_launch = vec![Duration::ZERO; rows.len()];
        for (u, &(i, d)) in timer.units.iter().enumerate() {
            let dt = match host_timed.iter().find(|(h, _)| *h == u) {
                Some((_, dt)) => *dt,
                None => Duration::from_nanos(
                    (ticks[2 * u + 1].saturating_sub(ticks[2 * u]) as f64 * timer.period) as u64,
                ),
            };
            per_launch[i] += dt;
            if let Some(d) = d {
                rows[i].dispatch_samples[d].1.push(dt);
            }
        }
        for (row, dt) in rows.iter_mut().zip(per_launch) {
            row.add(dt);
        }
        Ok(counts)
    }

    /// One step, each launch submitted alone and timed on the host.
    fn profile_step_on_host(
        &self,
        step: u64,
        rows: &mut [ProfileRow],
    ) -> Result<Vec<u32>, ExecError> {
        let parity = (step % 2) as usize;
        let mut counts = Vec::new();
        for (i, c) in self.step[parity].iter().enumerate() {
            if let Some(lp) = &c.looped {
                let (dt, k) = self.time_loop(lp, step)?;
                counts.push(k);
                rows[i].add(dt);
                continue;
            }
            let t = Instant::now();
            let idx = self.submit(&c.dispatches.iter().collect::<Vec<_>>(), step);
            self.gpu.wait(idx)?;
            rows[i].add(t.elapsed());
        }
        let idx = self.submit(&[&self.clock_tick], 0);
        self.gpu.wait(idx)?;
        Ok(counts)
    }

    /// Reads back the requested outputs (their values after the last step run).
    pub fn read_outputs(&self) -> Result<Vec<(String, HostArray)>, ExecError> {
        if self.steps_done == 0 {
            return Err(ExecError::Run("outputs are read after a run".into()));
        }
        let parity = ((self.steps_done - 1) % 2) as usize;
        let mut out = Vec::new();
        for (name, v) in &self.plan.outputs {
            let ty = self.plan.values[*v].ty;
            let bytes = self.gpu.read_buffer(self.buffer(*v, parity), ty.bytes())?;
            out.push((name.clone(), HostArray::from_bytes(ty, &bytes)));
        }
        Ok(out)
    }

    /// Number of dispatches recorded per step (the clock tick included).
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

fn engine_err(source: CompileError) -> ExecError {
    ExecError::Compile {
        node: "(engine)".into(),
        source,
    }
}
