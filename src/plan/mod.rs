//! The planner: graph + requested outputs + input shapes -> [`Plan`], pure data.
//!
//! It runs only what the requested outputs need (and the states they depend on), infers
//! every value's type, orders the work, fuses element-wise chains into generated kernels,
//! and assigns buffers with reuse. A plan needs no GPU: `mesoflow inspect` prints it and
//! tests check it on machines without one. The executor compiles it afterwards.

mod check;
mod demand;
mod fold;
mod forward;
mod fuse;
mod infer;
mod lower;
mod memory;
mod request;
mod schedule;
mod show;

use std::collections::{BTreeMap, BTreeSet};

pub use check::{Validation, validate_file};
pub use fuse::{FusedKernel, MAX_FUSED_NODES};
pub use show::{human_bytes, to_dot, to_text};

use crate::gpu::{DeviceCaps, NodePlan};
use crate::graph::{Graph, NodeId, Problems};
use crate::ids::IdVec;
use crate::transform::Folding;
use crate::value::ValueType;

/// What the caller asks of the planner.
#[derive(Clone, Debug)]
pub struct PlanOptions {
    /// Outputs to compute; `None` computes all of them.
    pub outputs: Option<Vec<String>>,
    /// Types of the graph inputs that are given. Inputs not listed are absent.
    pub inputs: BTreeMap<String, ValueType>,
    /// Fuse element-wise chains (on by default; off for comparisons and benchmarks).
    pub fuse: bool,
    /// Give outputs declared in place of an input that input's buffer where it is safe
    /// (`memory.rs`; on by default; off for comparisons and benchmarks).
    pub in_place: bool,
}

crate::typed_id!(
    /// A value of a plan: index into [`Plan::values`].
    ValueId
);
crate::typed_id!(
    /// A planner-owned buffer: index into [`Plan::buffers`].
    BufferId
);

/// When a launch runs: once before the first step, or every step.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Phase {
    Prologue,
    Step,
}

/// Where a value lives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Storage {
    /// The upload buffer of a graph input.
    Input(usize),
    /// A state's buffer: the current value (`next` false) or the one being written for the
    /// next step. Two buffers per state swap roles every step.
    State { state: usize, next: bool },
    /// A planner-owned buffer.
    Buffer(BufferId),
    /// Inside a fused kernel only: never stored.
    Register,
    /// During planning only: a planner buffer of this role, not yet assigned.
    Pending(BufferRole),
}

#[derive(Clone, Debug)]
pub struct PlanValue {
    pub name: String,
    pub ty: ValueType,
    pub phase: Phase,
    pub storage: Storage,
}

/// Why a planner buffer exists.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BufferRole {
    /// Pooled: holds different short-lived values over a step.
    Pool,
    /// A requested output, kept until it is read back.
    Output,
    /// A node's persistent output, kept (and zeroed once) across steps.
    Persistent,
}

#[derive(Clone, Debug)]
pub struct PlanBuffer {
    pub bytes: u64,
    pub role: BufferRole,
    /// Names of the values it holds over the run.
    pub holds: Vec<String>,
}

/// A spectral node folded into the transform that produces its input.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FoldedSpectral {
    pub node: NodeId,
    /// Its output, written by the transform's last pass.
    pub output: ValueId,
    /// The inverse transform (reading `output`) whose first pass the transform's last
    /// pass runs too: `output` then holds the spectrum transformed back along one axis.
    pub inverse: Option<NodeId>,
}

/// How a transform's launch shares passes with its neighbours (see `fold.rs`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TransformFold {
    /// Every pass of its own.
    Alone,
    /// Applies a spectral node in its last pass (its own output is never stored).
    Hosts(FoldedSpectral),
    /// An inverse transform whose first pass ran in the last pass of the forward
    /// transform that hosts the spectral node it reads.
    FirstPassElsewhere,
}

impl TransformFold {
    /// What the transform's recipe, dispatches and notes follow.
    pub fn folding(&self) -> Folding {
        match self {
            TransformFold::Alone => Folding::Alone,
            TransformFold::Hosts(FoldedSpectral { inverse: None, .. }) => Folding::Spectral,
            TransformFold::Hosts(FoldedSpectral {
                inverse: Some(_), ..
            }) => Folding::SpectralThenInverse,
            TransformFold::FirstPassElsewhere => Folding::FirstPassFolded,
        }
    }
}

/// One unit of GPU work.
#[derive(Clone, Debug)]
pub enum Launch {
    /// A node that records its own dispatches, or a spectral node's kernel.
    Node {
        node: NodeId,
        inputs: Vec<Option<ValueId>>,
        outputs: Vec<ValueId>,
        scratch: Vec<ValueId>,
        /// The node's own decisions for these inputs (see `Node::notes`).
        notes: Vec<String>,
        /// The node's decision, handed back to it when it compiles (`Signature::plan`).
        plan: Option<NodePlan>,
        /// (output port, input port) pairs its kind declares in place
        /// (`PortSpec::in_place_of`): `memory.rs` decides which share a buffer.
        in_place: Vec<(usize, usize)>,
    },
    /// A transform (see `crate::transform`), with what it folds in.
    Transform {
        node: NodeId,
        inputs: Vec<Option<ValueId>>,
        /// When it hosts a spectral node, its own output is never stored (a register
        /// value): the launch writes the spectral node's output instead.
        outputs: Vec<ValueId>,
        scratch: Vec<ValueId>,
        notes: Vec<String>,
        plan: Option<NodePlan>,
        fold: TransformFold,
    },
    /// One generated kernel for a chain of element-wise nodes.
    Fused(FusedKernel),
    /// Engine copy (a state whose next value is not written in place).
    Copy { src: ValueId, dst: ValueId },
    /// An iterative node (see `GpuIterative`) with its loop body: the executor runs the
    /// node's start, then `body` and the node's iteration until the host says stop.
    Loop {
        node: NodeId,
        inputs: Vec<Option<ValueId>>,
        outputs: Vec<ValueId>,
        scratch: Vec<ValueId>,
        notes: Vec<String>,
        plan: Option<NodePlan>,
        body: Vec<Launch>,
        /// (output port, input port) pairs: iterate outputs the node refills from an
        /// iterate input after every body run (`PortSpec::refilled_from`), which an
        /// in-place output in the body may overwrite.
        refills: Vec<(usize, usize)>,
        /// (output port, input port) pairs: iterate outputs the node sets from a plain
        /// input at the start (`PortSpec::started_from`: `repeat`'s `current`).
        starts: Vec<(usize, usize)>,
        /// (output port, output port) pairs: outputs the node sets from an iterate
        /// output after the last iteration (`PortSpec::final_of`: `repeat`'s `out`).
        finals: Vec<(usize, usize)>,
    },
}

/// A value written into the buffer of another whose last read comes before it
/// (`memory.rs` decides; see [`Via`]): the copy between them is skipped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct InPlace {
    pub node: NodeId,
    /// The value whose buffer is handed on (read for the last time where `output` is
    /// written).
    pub input: ValueId,
    /// The value written into it.
    pub output: ValueId,
    pub via: Via,
}

/// Which copy an [`InPlace`] saves.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Via {
    /// A node's output in place of its input (`PortSpec::in_place_of`): the node skips
    /// its copy, and where `output` is the loop's own result (`next`) of a loop that
    /// refills `input` from it (`repeat`'s `current`), the loop skips its copy too.
    Node,
    /// A loop's iterate output (`input`: a plain input of the loop node; `output`: the
    /// iterate output it starts from it, `PortSpec::started_from`): the loop starts where
    /// the value lies, its `start` copies nothing.
    Start,
    /// A loop's final value (`input`: the iterate output; `output`: the output set from
    /// it after the last iteration, `PortSpec::final_of`): the loop's `finish` copies
    /// nothing. Where `output` has a buffer of its own (a state's next value, a requested
    /// output), every value sharing with `input` lives there.
    Finish,
}

/// A state as planned.
#[derive(Clone, Debug)]
pub struct StatePlan {
    pub name: String,
    pub ty: ValueType,
    /// The prologue value copied into the state before the first step.
    pub init: ValueId,
    /// The state's current value during a step.
    pub current: ValueId,
}

/// Memory totals, in bytes.
#[derive(Clone, Debug, Default)]
pub struct MemoryReport {
    pub inputs: u64,
    pub states: u64,
    pub pool: u64,
    pub outputs: u64,
    pub persistent: u64,
    /// What the pooled values would take without reuse.
    pub pool_without_reuse: u64,
}

impl MemoryReport {
    /// Peak planner-owned GPU memory (node tables and kernels' constants come on top).
    pub fn total(&self) -> u64 {
        self.inputs + self.states + self.pool + self.outputs + self.persistent
    }
}

/// A complete plan.
#[derive(Clone, Debug)]
pub struct Plan {
    pub caps: DeviceCaps,
    pub values: IdVec<ValueId, PlanValue>,
    pub buffers: IdVec<BufferId, PlanBuffer>,
    /// Graph inputs that are given, with their types.
    pub inputs: Vec<(usize, ValueType)>,
    pub states: Vec<StatePlan>,
    pub prologue: Vec<Launch>,
    pub step: Vec<Launch>,
    /// Step launches (indices into `step`) whose values only the requested outputs read
    /// (a scatter back into the input's order, a relabelled mesh): the executor runs them
    /// on the last step of each run only, the other steps skip them. Empty where nothing
    /// is carried from a step to the next (no state, no persistent value): every step
    /// is then the whole computation.
    pub last_step_only: BTreeSet<usize>,
    /// Requested outputs and the value each reads after the last step.
    pub outputs: Vec<(String, ValueId)>,
    pub memory: MemoryReport,
    /// Nodes the graph has but this plan does not run.
    pub pruned: Vec<NodeId>,
    /// Nodes read through: for these inputs their output is one of their inputs
    /// unchanged (see `Node::forwards`), so they do no work.
    pub forwarded: Vec<NodeId>,
    /// Values given the buffer of a value read for the last time where they are written
    /// (`memory.rs`), in launch order.
    pub in_place: Vec<InPlace>,
}

impl Plan {
    /// Step launches that run on every step (those only outputs read run on the last
    /// step of a run only: `last_step_only`).
    pub fn launches_every_step(&self) -> usize {
        self.step.len() - self.last_step_only.len()
    }

    pub fn launches(&self) -> impl Iterator<Item = (Phase, &Launch)> {
        self.prologue
            .iter()
            .map(|l| (Phase::Prologue, l))
            .chain(self.step.iter().map(|l| (Phase::Step, l)))
    }
}

/// Plans a graph for the given outputs and inputs, pass by pass: the request (outputs
/// asked, inputs given), demand (what they need), type inference, forwarding (nodes read
/// through), scheduling, lowering to launches, and buffer assignment.
pub fn plan(graph: &Graph, opts: &PlanOptions, caps: &DeviceCaps) -> Result<Plan, Problems> {
    let request = request::resolve(graph, opts, caps)?;
    let demand = demand::of(graph, &request.outputs)?;
    let types = infer::infer(graph, &demand, &request.input_types, &request.outputs, caps)?;
    let (graph, forwarded) = forward::read_through(graph, &demand, &types);
    let demand = if forwarded.is_empty() {
        demand
    } else {
        demand::of(&graph, &request.outputs)?
    };
    let schedule = schedule::schedule(&graph, &demand, &types, &forwarded)?;
    let mut plan = lower::lower(&graph, opts, caps, &request, &demand, &types, &schedule);
    plan.forwarded = forwarded;
    memory::assign(&mut plan, opts.in_place);
    Ok(plan)
}

/// What [`plan_available`] planned, and the outputs it left out with their problems.
pub struct Available {
    pub plan: Plan,
    /// Outputs that do not plan for these inputs and params, in declaration order.
    pub left_out: Vec<(String, Problems)>,
}

/// Plans every output of the graph that plans for these inputs and params (an output may
/// need an optional input not given, or other params than these): all of them when they
/// plan together, else those that plan each on their own, the others left out with their
/// problems. An error (the problems of planning them all) when none plans.
/// `opts.outputs` is ignored.
pub fn plan_available(
    graph: &Graph,
    opts: &PlanOptions,
    caps: &DeviceCaps,
) -> Result<Available, Problems> {
    let with = |outputs: Option<Vec<String>>| {
        let opts = PlanOptions {
            outputs,
            ..opts.clone()
        };
        plan(graph, &opts, caps)
    };
    let all_problems = match with(None) {
        Ok(plan) => {
            return Ok(Available {
                plan,
                left_out: Vec::new(),
            });
        }
        Err(e) => e,
    };
    let mut planned = Vec::new();
    let mut left_out = Vec::new();
    for o in &graph.outputs {
        match with(Some(vec![o.name.clone()])) {
            Ok(_) => planned.push(o.name.clone()),
            Err(e) => left_out.push((o.name.clone(), e)),
        }
    }
    if planned.is_empty() {
        return Err(all_problems);
    }
    Ok(Available {
        plan: with(Some(planned))?,
        left_out,
    })
}

/// Why a value of `bytes` cannot live in one buffer of the device, if it cannot: the
/// host says so by name (the input, the node's port) before wgpu refuses a binding.
pub(super) fn too_large_for(caps: &DeviceCaps, bytes: u64) -> Option<String> {
    let limit = caps.max_binding.min(caps.max_buffer);
    (bytes > limit).then(|| {
        format!(
            "{bytes} bytes ({}): more than this device binds in one buffer ({limit} bytes, {})",
            human_bytes(bytes),
            human_bytes(limit)
        )
    })
}

impl Launch {
    /// Values the launch reads.
    pub fn reads(&self) -> Vec<ValueId> {
        match self {
            Launch::Node { inputs, .. } | Launch::Transform { inputs, .. } => {
                inputs.iter().flatten().copied().collect()
            }
            Launch::Fused(k) => k.inputs.clone(),
            Launch::Copy { src, .. } => vec![*src],
            Launch::Loop { inputs, body, .. } => {
                // What the loop reads from before it: values its body or the node itself
                // do not produce.
                let made: BTreeSet<ValueId> = self.writes().into_iter().collect();
                let mut r: Vec<ValueId> = inputs.iter().flatten().copied().collect();
                r.extend(body.iter().flat_map(|l| l.reads()));
                let mut seen = BTreeSet::new();
                r.retain(|v| !made.contains(v) && seen.insert(*v));
                r
            }
        }
    }

    /// Values the launch writes (scratch included).
    pub fn writes(&self) -> Vec<ValueId> {
        match self {
            Launch::Node {
                outputs, scratch, ..
            } => outputs.iter().chain(scratch).copied().collect(),
            Launch::Transform {
                outputs,
                scratch,
                fold,
                ..
            } => {
                let hosted = match fold {
                    TransformFold::Hosts(f) => Some(f.output),
                    _ => None,
                };
                outputs
                    .iter()
                    .chain(scratch)
                    .copied()
                    .chain(hosted)
                    .collect()
            }
            Launch::Fused(k) => k.outputs.clone(),
            Launch::Copy { dst, .. } => vec![*dst],
            Launch::Loop {
                outputs,
                scratch,
                body,
                ..
            } => outputs
                .iter()
                .chain(scratch)
                .copied()
                .chain(body.iter().flat_map(|l| l.writes()))
                .collect(),
        }
    }

    /// The graph nodes it runs.
    pub fn nodes(&self) -> Vec<NodeId> {
        match self {
            Launch::Node { node, .. } => vec![*node],
            Launch::Transform { node, fold, .. } => {
                let hosted = match fold {
                    TransformFold::Hosts(f) => Some(f.node),
                    _ => None,
                };
                std::iter::once(*node).chain(hosted).collect()
            }
            Launch::Fused(k) => k.nodes.clone(),
            Launch::Copy { .. } => vec![],
            Launch::Loop { node, body, .. } => std::iter::once(*node)
                .chain(body.iter().flat_map(|l| l.nodes()))
                .collect(),
        }
    }
}
