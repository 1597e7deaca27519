//! The planner: graph + requested outputs + input shapes -> [`Plan`], pure data.
//!
//! It runs only what the requested outputs need (and the states they depend on), infers
//! every value's type, orders the work, fuses element-wise chains into generated kernels,
//! and assigns buffers with reuse. A plan needs no GPU: `mesoflow inspect` prints it and
//! tests check it on machines without one. The executor compiles it afterwards.

mod fold;
mod fuse;
mod memory;
mod show;

use std::cmp::Reverse;
use std::collections::{BTreeMap, BTreeSet, BinaryHeap, HashMap};

pub use fuse::FusedKernel;
pub use show::{human_bytes, to_dot, to_text};

use crate::gpu::DeviceCaps;
use crate::graph::{Graph, Problem, Problems, Source};
use crate::node::Lowering;
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
}

/// Index into [`Plan::values`].
pub type ValueId = usize;

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
    /// A planner-owned buffer (index into [`Plan::buffers`]).
    Buffer(usize),
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
    pub node: usize,
    /// Its output, written by the transform's last pass.
    pub output: ValueId,
    /// The inverse transform (reading `output`) whose first pass the transform's last
    /// pass runs too: `output` then holds the spectrum transformed back along one axis.
    pub inverse: Option<usize>,
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
        node: usize,
        inputs: Vec<Option<ValueId>>,
        outputs: Vec<ValueId>,
        scratch: Vec<ValueId>,
        /// The node's own decisions for these inputs (see `Node::notes`).
        notes: Vec<String>,
    },
    /// A transform (see `crate::transform`), with what it folds in.
    Transform {
        node: usize,
        inputs: Vec<Option<ValueId>>,
        /// When it hosts a spectral node, its own output is never stored (a register
        /// value): the launch writes the spectral node's output instead.
        outputs: Vec<ValueId>,
        scratch: Vec<ValueId>,
        notes: Vec<String>,
        fold: TransformFold,
    },
    /// One generated kernel for a chain of element-wise nodes.
    Fused(FusedKernel),
    /// Engine copy (a state whose next value is not written in place).
    Copy { src: ValueId, dst: ValueId },
    /// An iterative node (see `GpuIterative`) with its loop body: the executor runs the
    /// node's start, then `body` and the node's iteration until the host says stop.
    Loop {
        node: usize,
        inputs: Vec<Option<ValueId>>,
        outputs: Vec<ValueId>,
        scratch: Vec<ValueId>,
        notes: Vec<String>,
        body: Vec<Launch>,
    },
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
    pub values: Vec<PlanValue>,
    pub buffers: Vec<PlanBuffer>,
    /// Graph inputs that are given, with their types.
    pub inputs: Vec<(usize, ValueType)>,
    pub states: Vec<StatePlan>,
    pub prologue: Vec<Launch>,
    pub step: Vec<Launch>,
    /// Requested outputs and the value each reads after the last step.
    pub outputs: Vec<(String, ValueId)>,
    pub memory: MemoryReport,
    /// Nodes the graph has but this plan does not run.
    pub pruned: Vec<usize>,
    /// Nodes read through: for these inputs their output is one of their inputs
    /// unchanged (see `Node::forwards`), so they do no work.
    pub forwarded: Vec<usize>,
}

impl Plan {
    pub fn launches(&self) -> impl Iterator<Item = (Phase, &Launch)> {
        self.prologue
            .iter()
            .map(|l| (Phase::Prologue, l))
            .chain(self.step.iter().map(|l| (Phase::Step, l)))
    }
}

/// Plans a graph for the given outputs and inputs.
pub fn plan(graph: &Graph, opts: &PlanOptions, caps: &DeviceCaps) -> Result<Plan, Problems> {
    Planner::new(graph, opts, caps).run()
}

struct Planner<'g> {
    g: &'g Graph,
    opts: &'g PlanOptions,
    caps: &'g DeviceCaps,
    problems: Vec<Problem>,
    /// Inferred output types per node; `None` for an absent node (a required input absent).
    node_types: Vec<Option<Option<Vec<ValueType>>>>,
    scratch: Vec<Vec<u64>>,
    input_types: Vec<Option<ValueType>>,
    state_types: Vec<Option<ValueType>>,
}

impl<'g> Planner<'g> {
    fn new(g: &'g Graph, opts: &'g PlanOptions, caps: &'g DeviceCaps) -> Self {
        Planner {
            g,
            opts,
            caps,
            problems: Vec::new(),
            node_types: vec![None; g.nodes.len()],
            scratch: vec![Vec::new(); g.nodes.len()],
            input_types: vec![None; g.inputs.len()],
            state_types: vec![None; g.states.len()],
        }
    }

    fn fail(&mut self, msg: String) {
        self.problems.push(Problem::file(&self.g.file, msg));
    }

    fn run(mut self) -> Result<Plan, Problems> {
        let g = self.g;
        // Requested outputs.
        let requested: Vec<usize> = match &self.opts.outputs {
            None => (0..g.outputs.len()).collect(),
            Some(names) => {
                let mut v = Vec::new();
                for n in names {
                    match g.output(n) {
                        Some(i) => v.push(i),
                        None => {
                            let known: Vec<&str> =
                                g.outputs.iter().map(|o| o.name.as_str()).collect();
                            self.fail(format!(
                                "unknown output `{n}` (outputs: {})",
                                known.join(", ")
                            ));
                        }
                    }
                }
                v
            }
        };
        // Input types.
        for (name, ty) in &self.opts.inputs {
            match g.input(name) {
                Some(i) => {
                    if let Err(e) = g.inputs[i].shape.check(ty) {
                        self.fail(format!("input `{name}`: {e}"));
                    }
                    self.input_types[i] = Some(*ty);
                }
                None => {
                    let known: Vec<&str> = g.inputs.iter().map(|i| i.name.as_str()).collect();
                    self.fail(format!(
                        "unknown input `{name}` (inputs: {})",
                        known.join(", ")
                    ));
                }
            }
        }
        self.check_sizes();
        if !self.problems.is_empty() {
            return Err(Problems(self.problems));
        }

        // Demand: what the requested outputs need, per phase.
        let mut step_nodes = BTreeSet::new();
        let mut needed_states = BTreeSet::new();
        let mut stack: Vec<Source> = requested.iter().map(|&o| g.outputs[o].source).collect();
        while let Some(s) = stack.pop() {
            match s {
                Source::Node { node, .. } => {
                    if step_nodes.insert(node) {
                        stack.extend(g.nodes[node].inputs.iter().copied());
                    }
                }
                Source::State(i) => {
                    if needed_states.insert(i) {
                        stack.push(g.states[i].next);
                    }
                }
                Source::Input(_) | Source::Absent => {}
            }
        }
        let mut prologue_nodes = BTreeSet::new();
        let mut stack: Vec<Source> = needed_states.iter().map(|&s| g.states[s].init).collect();
        while let Some(s) = stack.pop() {
            match s {
                Source::Node { node, .. } if prologue_nodes.insert(node) => {
                    stack.extend(g.nodes[node].inputs.iter().copied());
                }
                Source::State(i) => {
                    let msg = format!(
                        "the initial value of a state depends on state `{}`; initial values must come from inputs or from nodes that read no state",
                        g.states[i].name
                    );
                    self.fail(msg);
                }
                _ => {}
            }
        }
        if !self.problems.is_empty() {
            return Err(Problems(self.problems));
        }

        // Types: prologue (state inits) first, then states, then the step.
        for &n in &prologue_nodes {
            self.infer_node(n);
        }
        for &s in &needed_states {
            let init = g.states[s].init;
            let t = self.source_type(init);
            if t.is_none() {
                let msg = format!(
                    "state `{}` has no initial value: `{}` is absent (an optional input not given?)",
                    g.states[s].name,
                    g.source_name(init)
                );
                self.fail(msg);
            }
            self.state_types[s] = t;
        }
        for &n in &step_nodes {
            self.infer_node(n);
        }
        if !self.problems.is_empty() {
            return Err(Problems(self.problems));
        }
        for &s in &needed_states {
            let st = &g.states[s];
            match (self.state_types[s], self.source_type(st.next)) {
                (Some(a), Some(b)) if a != b => {
                    let msg = format!(
                        "state `{}` is {a} but its next value `{}` is {b}",
                        st.name,
                        g.source_name(st.next)
                    );
                    self.fail(msg);
                }
                (Some(_), None) => {
                    let msg = format!(
                        "state `{}`: next value `{}` is absent",
                        st.name,
                        g.source_name(st.next)
                    );
                    self.fail(msg);
                }
                _ => {}
            }
        }
        for &o in &requested {
            let out = &g.outputs[o];
            if self.source_type(out.source).is_none() {
                let missing: Vec<String> = g
                    .inputs
                    .iter()
                    .enumerate()
                    .filter(|(i, d)| d.optional && self.input_types[*i].is_none())
                    .map(|(_, d)| d.name.clone())
                    .collect();
                let msg = format!(
                    "output `{}` cannot be computed: it needs an optional input that was not given ({})",
                    out.name,
                    missing.join(", ")
                );
                self.fail(msg);
            }
        }
        if !self.problems.is_empty() {
            return Err(Problems(self.problems));
        }

        // Nodes that forward an input unchanged (for these types) are read through:
        // plan the graph with their readers rewired, where they are unread.
        let forwards: HashMap<usize, Source> = step_nodes
            .iter()
            .chain(&prologue_nodes)
            .filter_map(|&n| {
                let inst = &g.nodes[n];
                let Some(Some(_)) = &self.node_types[n] else {
                    return None;
                };
                let types: Vec<Option<ValueType>> =
                    inst.inputs.iter().map(|s| self.source_type(*s)).collect();
                let i = inst.node.forwards(&types)?;
                Some((n, inst.inputs[i]))
            })
            .collect();
        if !forwards.is_empty() {
            let mut p = plan(&g.forwarding(&forwards), self.opts, self.caps)?;
            p.pruned.retain(|n| !forwards.contains_key(n));
            p.forwarded.extend(forwards.keys());
            p.forwarded.sort_unstable();
            return Ok(p);
        }

        // Absent nodes drop out of the schedule.
        let present = |n: &usize| matches!(self.node_types[*n], Some(Some(_)));
        let iterative = |n: usize| g.nodes[n].input_ports.iter().any(|p| p.iterate);
        for &n in prologue_nodes.iter().filter(|&&n| iterative(n)) {
            let inst = &g.nodes[n];
            self.problems.push(Problem::node(
                &inst.file,
                &inst.id,
                "an iterative node cannot compute a state's initial value (it runs in the steps only)",
            ));
        }
        if !self.problems.is_empty() {
            return Err(Problems(self.problems));
        }
        let prologue_order = self.topo(
            prologue_nodes.iter().copied().filter(present).collect(),
            &BTreeMap::new(),
        );
        // Loops: an iterative node's body is scheduled inside it; the node runs after
        // everything its body reads from outside.
        let step_present: BTreeSet<usize> = step_nodes.iter().copied().filter(present).collect();
        let mut loops: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
        let mut extra_deps: BTreeMap<usize, BTreeSet<usize>> = BTreeMap::new();
        let mut in_body = BTreeSet::new();
        for &l in step_present.iter().filter(|&&n| iterative(n)) {
            let body: BTreeSet<usize> = g
                .loop_body(l)
                .into_iter()
                .filter(|b| step_present.contains(b))
                .collect();
            let outside: BTreeSet<usize> = body
                .iter()
                .flat_map(|&b| g.nodes[b].inputs.iter().copied())
                .filter_map(|s| match s {
                    Source::Node { node, .. } if node != l && !body.contains(&node) => Some(node),
                    _ => None,
                })
                .collect();
            extra_deps.insert(l, outside);
            in_body.extend(body.iter().copied());
            loops.insert(l, self.topo(body.into_iter().collect(), &BTreeMap::new()));
        }
        let step_order = self.topo(
            step_present.difference(&in_body).copied().collect(),
            &extra_deps,
        );
        let pruned: Vec<usize> = (0..g.nodes.len())
            .filter(|n| !(step_nodes.contains(n) || prologue_nodes.contains(n)) || !present(n))
            .collect();

        self.build(
            &requested,
            &needed_states,
            prologue_order,
            step_order,
            &loops,
            pruned,
        )
    }

    /// Every input naming one size must agree on it.
    fn check_sizes(&mut self) {
        use crate::graph::{Dim, InputShape};
        let mut seen: HashMap<String, (u32, String)> = HashMap::new();
        for (i, def) in self.g.inputs.iter().enumerate() {
            let (Some(ty), Some(dim)) = (
                self.input_types[i],
                match &def.shape {
                    InputShape::Particles { rows, .. } | InputShape::Indices { rows } => Some(rows),
                    _ => None,
                },
            ) else {
                continue;
            };
            let n = match ty {
                ValueType::Particles { n, .. } | ValueType::Indices { n } => n,
                _ => continue,
            };
            if let Dim::Size(s) = dim {
                match seen.get(s) {
                    Some((m, other)) if *m != n => {
                        let msg = format!(
                            "input `{}` has {n} rows but input `{other}` has {m}; both are declared with rows `{s}`",
                            def.name
                        );
                        self.fail(msg);
                    }
                    Some(_) => {}
                    None => {
                        seen.insert(s.clone(), (n, def.name.clone()));
                    }
                }
            }
        }
    }

    fn source_type(&self, s: Source) -> Option<ValueType> {
        match s {
            Source::Input(i) => self.input_types[i],
            Source::State(i) => self.state_types[i],
            Source::Node { node, port } => match &self.node_types[node] {
                Some(Some(t)) => t.get(port).copied(),
                _ => None,
            },
            Source::Absent => None,
        }
    }

    /// Infers a node's output types (its inputs are inferred first: the graph is acyclic
    /// apart from state, whose type is known before the step is inferred).
    fn infer_node(&mut self, n: usize) {
        if self.node_types[n].is_some() {
            return;
        }
        let g = self.g;
        let inst = &g.nodes[n];
        for (port, s) in inst.input_ports.iter().zip(&inst.inputs) {
            if let Source::Node { node, .. } = s
                && !port.iterate
            {
                self.infer_node(*node);
            }
        }
        if inst.input_ports.iter().any(|p| p.iterate) {
            // An iterative node's loop body reads the node's own outputs: type the node
            // without its loop input first, then the body, then the node again in full.
            let reported = self.problems.len();
            self.infer_signature(n, true);
            self.problems.truncate(reported);
            if matches!(self.node_types[n], Some(Some(_))) {
                for (port, s) in inst.input_ports.iter().zip(&inst.inputs) {
                    if let Source::Node { node, .. } = s
                        && port.iterate
                    {
                        self.infer_node(*node);
                    }
                }
            }
        }
        self.infer_signature(n, false);
    }

    /// Infers a node's output types from its inputs' (already inferred); with
    /// `without_loop_input`, the input closing an iterative node's loop counts as absent.
    fn infer_signature(&mut self, n: usize, without_loop_input: bool) {
        let g = self.g;
        let inst = &g.nodes[n];
        let mut types = Vec::new();
        let mut absent = false;
        let mut ok = true;
        for (port, src) in inst.input_ports.iter().zip(&inst.inputs) {
            let t = if without_loop_input && port.iterate {
                types.push(None);
                continue;
            } else {
                self.source_type(*src)
            };
            match t {
                None if !port.optional => absent = true,
                Some(t) if !port.ty.accepts(&t) => {
                    ok = false;
                    self.problems.push(Problem::port(
                        &inst.file,
                        &inst.id,
                        port.name,
                        format!(
                            "expects {}, got {t} from `{}`",
                            port.ty,
                            g.source_name(*src)
                        ),
                    ));
                }
                _ => {}
            }
            types.push(t);
        }
        if absent || !ok {
            self.node_types[n] = Some(None);
            return;
        }
        match inst.node.infer(&types) {
            Ok(sig) => {
                if sig.outputs.len() != inst.output_ports.len() {
                    panic!(
                        "node kind `{}` inferred {} outputs for {} ports",
                        inst.kind,
                        sig.outputs.len(),
                        inst.output_ports.len()
                    );
                }
                for (port, t) in inst.output_ports.iter().zip(&sig.outputs) {
                    if t.bytes() > self.caps.max_binding {
                        self.problems.push(Problem::port(
                            &inst.file,
                            &inst.id,
                            port.name,
                            format!(
                                "output {t} takes {} MiB; this device binds at most {} MiB per buffer",
                                t.bytes() >> 20,
                                self.caps.max_binding >> 20
                            ),
                        ));
                    }
                }
                self.scratch[n] = sig.scratch;
                self.node_types[n] = Some(Some(sig.outputs));
            }
            Err(e) => {
                self.problems
                    .push(Problem::port(&inst.file, &inst.id, &e.port, e.message));
                self.node_types[n] = Some(None);
            }
        }
    }

    /// Topological order of a node set; among ready nodes the one declared first runs
    /// first, so plans read in file order where the data allow.
    /// `extra[n]`: nodes `n` must follow besides its inputs' producers. Loop inputs
    /// (read after each iteration) impose no order.
    fn topo(&self, nodes: Vec<usize>, extra: &BTreeMap<usize, BTreeSet<usize>>) -> Vec<usize> {
        let set: BTreeSet<usize> = nodes.iter().copied().collect();
        let mut indeg: BTreeMap<usize, usize> = set.iter().map(|&n| (n, 0)).collect();
        let mut users: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
        for &n in &set {
            let mut deps = BTreeSet::new();
            let inst = &self.g.nodes[n];
            for (port, s) in inst.input_ports.iter().zip(&inst.inputs) {
                if let Source::Node { node, .. } = s
                    && set.contains(node)
                    && !port.iterate
                {
                    deps.insert(*node);
                }
            }
            for d in extra.get(&n).into_iter().flatten() {
                if set.contains(d) {
                    deps.insert(*d);
                }
            }
            for d in deps {
                *indeg.get_mut(&n).expect("in set") += 1;
                users.entry(d).or_default().push(n);
            }
        }
        let mut ready: BinaryHeap<Reverse<usize>> = indeg
            .iter()
            .filter(|(_, d)| **d == 0)
            .map(|(n, _)| Reverse(*n))
            .collect();
        let mut order = Vec::new();
        while let Some(Reverse(n)) = ready.pop() {
            order.push(n);
            for &u in users.get(&n).map(|v| v.as_slice()).unwrap_or(&[]) {
                let d = indeg.get_mut(&u).expect("in set");
                *d -= 1;
                if *d == 0 {
                    ready.push(Reverse(u));
                }
            }
        }
        debug_assert_eq!(order.len(), set.len(), "cycles are rejected at load time");
        order
    }

    fn build(
        self,
        requested: &[usize],
        needed_states: &BTreeSet<usize>,
        prologue_order: Vec<usize>,
        step_order: Vec<usize>,
        loops: &BTreeMap<usize, Vec<usize>>,
        pruned: Vec<usize>,
    ) -> Result<Plan, Problems> {
        let g = self.g;
        let mut b = Builder {
            values: Vec::new(),
            by_source: HashMap::new(),
        };

        // Graph inputs that are given.
        let inputs: Vec<(usize, ValueType)> = self
            .input_types
            .iter()
            .enumerate()
            .filter_map(|(i, t)| t.map(|t| (i, t)))
            .collect();
        for &(i, t) in &inputs {
            for phase in [Phase::Prologue, Phase::Step] {
                b.add(
                    Source::Input(i),
                    phase,
                    format!("inputs.{}", g.inputs[i].name),
                    t,
                    Storage::Input(i),
                );
            }
        }
        // States: the current value is a state buffer.
        let state_index: BTreeMap<usize, usize> = needed_states
            .iter()
            .enumerate()
            .map(|(k, &s)| (s, k))
            .collect();
        for (&s, &k) in &state_index {
            let ty = self.state_types[s].expect("checked above");
            b.add(
                Source::State(s),
                Phase::Step,
                format!("state.{}", g.states[s].name),
                ty,
                Storage::State {
                    state: k,
                    next: false,
                },
            );
        }

        // Launches per phase (fusion decides grouping and which values stay in registers).
        let output_sources: BTreeSet<Source> =
            requested.iter().map(|&o| g.outputs[o].source).collect();
        let mut next_claimed: BTreeMap<Source, usize> = BTreeMap::new();
        for (&s, &k) in &state_index {
            let next = g.states[s].next;
            if matches!(next, Source::Node { node, port } if !g.nodes[node].output_ports[port].persistent)
            {
                next_claimed.entry(next).or_insert(k);
            }
        }
        // What loop bodies read from outside them, and the results loops read back: both
        // must be stored, whatever fusion would otherwise keep in registers.
        let mut loop_reads: BTreeSet<Source> = BTreeSet::new();
        for (&l, body) in loops {
            for &n in body.iter().chain(std::iter::once(&l)) {
                loop_reads.extend(g.nodes[n].inputs.iter().copied());
            }
        }
        let input_types = |n: usize| -> Vec<Option<ValueType>> {
            g.nodes[n]
                .inputs
                .iter()
                .map(|s| self.source_type(*s))
                .collect()
        };
        let mut phases = Vec::new();
        for (phase, order) in [
            (Phase::Prologue, &prologue_order),
            (Phase::Step, &step_order),
        ] {
            let escapes = |src: Source| {
                phase == Phase::Step
                    && (output_sources.contains(&src)
                        || next_claimed.contains_key(&src)
                        || loop_reads.contains(&src))
                    || phase == Phase::Prologue
                        && needed_states.iter().any(|&s| g.states[s].init == src)
            };
            let ctx = fuse::FuseCtx {
                g,
                types: &self.node_types,
                order,
                fuse: self.opts.fuse,
                escapes: &escapes,
            };
            let units = fuse::group(&ctx);
            let units = fold::fold(&ctx, units, self.caps, &input_types);
            let mut launches = Vec::new();
            for unit in units {
                let launch = b.lower(
                    g,
                    &self,
                    phase,
                    unit.clone(),
                    &next_claimed,
                    &output_sources,
                );
                let (fuse::Unit::Single(l), Some(body)) = (&unit, loops.get(&unit_node(&unit)))
                else {
                    launches.push(launch);
                    continue;
                };
                // The node's outputs exist now; its body reads them, and the node then
                // reads the body's result.
                let body_ctx = fuse::FuseCtx {
                    g,
                    types: &self.node_types,
                    order: body,
                    fuse: self.opts.fuse,
                    escapes: &escapes,
                };
                let units = fuse::group(&body_ctx);
                let units = fold::fold(&body_ctx, units, self.caps, &input_types);
                let body_launches: Vec<Launch> = units
                    .into_iter()
                    .map(|u| b.lower(g, &self, phase, u, &next_claimed, &output_sources))
                    .collect();
                let Launch::Node {
                    node,
                    outputs,
                    scratch,
                    mut notes,
                    ..
                } = launch
                else {
                    unreachable!("an iterative node lowers as a single launch")
                };
                let inputs = g.nodes[*l]
                    .inputs
                    .iter()
                    .map(|s| b.try_get(*s, phase))
                    .collect();
                notes.push(format!(
                    "loop body: {} launch{} ({} node{})",
                    body_launches.len(),
                    if body_launches.len() == 1 { "" } else { "es" },
                    body.len(),
                    if body.len() == 1 { "" } else { "s" }
                ));
                launches.push(Launch::Loop {
                    node,
                    inputs,
                    outputs,
                    scratch,
                    notes,
                    body: body_launches,
                });
            }
            phases.push(launches);
        }
        let mut step = phases.pop().expect("two phases");
        let mut prologue = phases.pop().expect("two phases");

        // State plumbing: initial values are copied in before the first step; next
        // values not written in place are copied at the end of each step.
        let mut states = Vec::new();
        for (&s, &k) in &state_index {
            let def = &g.states[s];
            let ty = self.state_types[s].expect("checked");
            let init = b.get(def.init, Phase::Prologue);
            let slot0 = b.push(
                format!("state.{} (initial)", def.name),
                ty,
                Phase::Prologue,
                Storage::State {
                    state: k,
                    next: false,
                },
            );
            prologue.push(Launch::Copy {
                src: init,
                dst: slot0,
            });
            let current = b.get(Source::State(s), Phase::Step);
            if next_claimed.get(&def.next) != Some(&k) {
                let src = b.get(def.next, Phase::Step);
                let dst = b.push(
                    format!("state.{} (next)", def.name),
                    ty,
                    Phase::Step,
                    Storage::State {
                        state: k,
                        next: true,
                    },
                );
                step.push(Launch::Copy { src, dst });
            }
            states.push(StatePlan {
                name: def.name.clone(),
                ty,
                init,
                current,
            });
        }

        // Outputs read after the last step. An output naming `state.x` is the state after
        // the last step, i.e. the last next value.
        let mut outputs = Vec::new();
        for &o in requested {
            let out = &g.outputs[o];
            let v = match out.source {
                Source::State(s) => {
                    let k = state_index[&s];
                    b.push(
                        format!("state.{} (final)", g.states[s].name),
                        self.state_types[s].expect("checked"),
                        Phase::Step,
                        Storage::State {
                            state: k,
                            next: true,
                        },
                    )
                }
                src => b.get(src, Phase::Step),
            };
            outputs.push((out.name.clone(), v));
        }

        let mut plan = Plan {
            caps: self.caps.clone(),
            values: b.values,
            buffers: Vec::new(),
            inputs,
            states,
            prologue,
            step,
            outputs,
            memory: MemoryReport::default(),
            pruned,
            forwarded: Vec::new(),
        };
        memory::assign(&mut plan);
        Ok(plan)
    }
}

/// What `inspect` says of a transform's share in a fold.
fn fold_notes(g: &Graph, fold: &TransformFold) -> Vec<String> {
    match fold {
        TransformFold::Alone => Vec::new(),
        TransformFold::Hosts(f) => {
            let mut notes = vec![format!(
                "folds spectral node `{}` ({}) into its last pass",
                g.nodes[f.node].id, g.nodes[f.node].kind
            )];
            if let Some(c) = f.inverse {
                notes.push(format!(
                    "and after it the first pass of `{}` ({}): the lines go back before they are stored",
                    g.nodes[c].id, g.nodes[c].kind
                ));
            }
            notes
        }
        TransformFold::FirstPassElsewhere => {
            vec!["starts at its second pass: its first ran in the forward transform's last".into()]
        }
    }
}

fn unit_node(u: &fuse::Unit) -> usize {
    match u {
        fuse::Unit::Single(n) => *n,
        _ => usize::MAX,
    }
}

/// Creates plan values and lowers launch units.
struct Builder {
    values: Vec<PlanValue>,
    by_source: HashMap<(Source, Phase), ValueId>,
}

impl Builder {
    fn push(&mut self, name: String, ty: ValueType, phase: Phase, storage: Storage) -> ValueId {
        self.values.push(PlanValue {
            name,
            ty,
            phase,
            storage,
        });
        self.values.len() - 1
    }

    fn add(
        &mut self,
        src: Source,
        phase: Phase,
        name: String,
        ty: ValueType,
        storage: Storage,
    ) -> ValueId {
        let id = self.push(name, ty, phase, storage);
        self.by_source.insert((src, phase), id);
        id
    }

    fn get(&self, src: Source, phase: Phase) -> ValueId {
        self.try_get(src, phase)
            .unwrap_or_else(|| panic!("planner: no value for {src:?} in {phase:?}"))
    }

    /// The value of a source, or `None` when it is absent (an optional input not given,
    /// or the output of a node that dropped out because of one).
    fn try_get(&self, src: Source, phase: Phase) -> Option<ValueId> {
        self.by_source.get(&(src, phase)).copied()
    }

    fn lower(
        &mut self,
        g: &Graph,
        p: &Planner,
        phase: Phase,
        unit: fuse::Unit,
        next_claimed: &BTreeMap<Source, usize>,
        output_sources: &BTreeSet<Source>,
    ) -> Launch {
        let storage_for = |src: Source, escapes: bool| -> Storage {
            if phase == Phase::Step
                && let Some(&k) = next_claimed.get(&src)
            {
                return Storage::State {
                    state: k,
                    next: true,
                };
            }
            let Source::Node { node, port } = src else {
                unreachable!("node outputs only")
            };
            if g.nodes[node].output_ports[port].persistent {
                Storage::Pending(BufferRole::Persistent)
            } else if phase == Phase::Step && output_sources.contains(&src) {
                Storage::Pending(BufferRole::Output)
            } else if escapes {
                Storage::Pending(BufferRole::Pool)
            } else {
                Storage::Register
            }
        };
        match unit {
            fuse::Unit::Single(n)
            | fuse::Unit::AfterFold(n)
            | fuse::Unit::Folded { transform: n, .. } => {
                let inst = &g.nodes[n];
                let hosts = matches!(unit, fuse::Unit::Folded { .. });
                let types = p.node_types[n].clone().flatten().expect("present node");
                let inputs = inst
                    .inputs
                    .iter()
                    .map(|s| self.try_get(*s, phase))
                    .collect();
                let mut outputs = Vec::new();
                for (port, t) in types.iter().enumerate() {
                    let src = Source::Node { node: n, port };
                    // A transform that hosts a spectral node stores only the latter's output.
                    let st = if hosts {
                        Storage::Register
                    } else {
                        storage_for(src, true)
                    };
                    let name = g.source_name(src);
                    outputs.push(self.add(src, phase, name, *t, st));
                }
                let fold = match unit {
                    fuse::Unit::Folded {
                        spectral: b,
                        inverse,
                        ..
                    } => {
                        let src = Source::Node { node: b, port: 0 };
                        let t = p.node_types[b].clone().flatten().expect("present node")[0];
                        let st = storage_for(src, true);
                        TransformFold::Hosts(FoldedSpectral {
                            node: b,
                            output: self.add(src, phase, g.source_name(src), t, st),
                            inverse,
                        })
                    }
                    fuse::Unit::AfterFold(_) => TransformFold::FirstPassElsewhere,
                    _ => TransformFold::Alone,
                };
                let scratch = p.scratch[n]
                    .iter()
                    .enumerate()
                    .map(|(i, &bytes)| {
                        let ty = ValueType::Indices {
                            n: (bytes.div_ceil(4)) as u32,
                        };
                        self.push(
                            format!("{} (scratch {i})", inst.id),
                            ty,
                            phase,
                            Storage::Pending(BufferRole::Pool),
                        )
                    })
                    .collect();
                let input_types: Vec<Option<ValueType>> =
                    inst.inputs.iter().map(|s| p.source_type(*s)).collect();
                let mut notes = inst.node.notes(&input_types);
                match inst.node.lowering() {
                    Lowering::Transform(t) => {
                        notes.extend(t.device_notes(&input_types, p.caps, fold.folding()));
                        notes.extend(fold_notes(g, &fold));
                        Launch::Transform {
                            node: n,
                            inputs,
                            outputs,
                            scratch,
                            notes,
                            fold,
                        }
                    }
                    lowering => {
                        if let Lowering::Kernels(k) = lowering {
                            notes.extend(k.device_notes(&input_types, p.caps));
                        }
                        Launch::Node {
                            node: n,
                            inputs,
                            outputs,
                            scratch,
                            notes,
                        }
                    }
                }
            }
            fuse::Unit::Group(members) => {
                let mut member_outputs = Vec::new();
                for &(n, escapes) in &members {
                    let src = Source::Node { node: n, port: 0 };
                    let t = p.node_types[n].clone().flatten().expect("present node")[0];
                    let st = storage_for(src, escapes);
                    member_outputs.push(self.add(src, phase, g.source_name(src), t, st));
                }
                let get = |s: Source| self.try_get(s, phase);
                let kernel = fuse::generate(g, &members, &member_outputs, &get, &self.values);
                Launch::Fused(kernel)
            }
        }
    }
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
    pub fn nodes(&self) -> Vec<usize> {
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
