//! Pass 3, type inference: every demanded node's output types from its inputs', in
//! dependency order (prologue first, then the states, then the step), with the checks
//! that need types (ports, states, outputs that an absent input makes impossible).
//! An absent optional input makes the nodes that require it absent, and so on downstream.

use super::demand::Demand;
use super::too_large_for;
use crate::gpu::{DeviceCaps, NodePlan};
use crate::graph::{Graph, NodeId, Problem, Problems, Source};
use crate::ids::IdVec;
use crate::value::ValueType;

/// What inference found for one node.
#[derive(Clone, Debug, Default)]
pub(super) enum Inferred {
    /// Not demanded (or not reached yet).
    #[default]
    Unknown,
    /// It needs a value that is absent: it drops out, with what depends on it.
    Absent,
    /// It would run, but a problem was reported for it or for a value it needs: what
    /// depends on it reports its own problems only, none that follow from this one.
    Failed,
    Present {
        outputs: Vec<ValueType>,
        /// Scratch buffers in bytes.
        scratch: Vec<u64>,
        /// The node's decision for these inputs (`Signature::plan`).
        plan: Option<NodePlan>,
    },
}

impl Inferred {
    pub fn outputs(&self) -> Option<&[ValueType]> {
        match self {
            Inferred::Present { outputs, .. } => Some(outputs),
            _ => None,
        }
    }

    pub fn is_present(&self) -> bool {
        matches!(self, Inferred::Present { .. })
    }
}

/// The types of everything demanded.
pub(super) struct Types {
    pub nodes: IdVec<NodeId, Inferred>,
    pub inputs: Vec<Option<ValueType>>,
    pub states: Vec<Option<ValueType>>,
    /// States whose initial value failed (reported where it failed).
    pub failed_states: Vec<bool>,
}

impl Types {
    /// Whether a value is missing because of a problem already reported (not because an
    /// optional input was not given).
    pub fn failed(&self, s: Source) -> bool {
        match s {
            Source::Node { node, .. } => matches!(self.nodes[node], Inferred::Failed),
            Source::State(i) => self.failed_states[i],
            Source::Input(_) | Source::Absent => false,
        }
    }

    pub fn of(&self, s: Source) -> Option<ValueType> {
        match s {
            Source::Input(i) => self.inputs[i],
            Source::State(i) => self.states[i],
            Source::Node { node, port } => self.nodes[node].outputs()?.get(port).copied(),
            Source::Absent => None,
        }
    }

    /// The types a node's inputs have (`None`: absent).
    pub fn inputs_of(&self, g: &Graph, n: NodeId) -> Vec<Option<ValueType>> {
        g.nodes[n].inputs.iter().map(|s| self.of(*s)).collect()
    }

    pub fn scratch(&self, n: NodeId) -> &[u64] {
        match &self.nodes[n] {
            Inferred::Present { scratch, .. } => scratch,
            _ => &[],
        }
    }

    /// A node's decision for its inputs, where it takes one.
    pub fn plan(&self, n: NodeId) -> Option<&NodePlan> {
        match &self.nodes[n] {
            Inferred::Present { plan, .. } => plan.as_ref(),
            _ => None,
        }
    }
}

pub(super) fn infer(
    g: &Graph,
    demand: &Demand,
    input_types: &[Option<ValueType>],
    outputs: &[usize],
    caps: &DeviceCaps,
) -> Result<Types, Problems> {
    let mut cx = Inference {
        g,
        caps,
        problems: Vec::new(),
        types: Types {
            nodes: g.nodes.iter().map(|_| Inferred::Unknown).collect(),
            inputs: input_types.to_vec(),
            states: vec![None; g.states.len()],
            failed_states: vec![false; g.states.len()],
        },
    };
    for &n in &demand.prologue {
        cx.node(n);
    }
    for &s in &demand.states {
        let init = g.states[s].init;
        let t = cx.types.of(init);
        if cx.types.failed(init) {
            cx.types.failed_states[s] = true;
        } else if t.is_none() {
            cx.fail(format!(
                "state `{}` has no initial value: `{}` is absent (an optional input not given?)",
                g.states[s].name,
                g.source_name(init)
            ));
        }
        cx.types.states[s] = t;
    }
    for &n in &demand.step {
        cx.node(n);
    }
    cx.done()?;
    cx.check_states(demand);
    cx.check_outputs(outputs);
    cx.done()?;
    Ok(cx.types)
}

struct Inference<'g> {
    g: &'g Graph,
    caps: &'g DeviceCaps,
    problems: Vec<Problem>,
    types: Types,
}

impl Inference<'_> {
    fn fail(&mut self, msg: String) {
        self.problems.push(Problem::file(&self.g.file, msg));
    }

    fn done(&mut self) -> Result<(), Problems> {
        if self.problems.is_empty() {
            Ok(())
        } else {
            Err(Problems(std::mem::take(&mut self.problems)))
        }
    }

    /// Infers a node's output types, its producers' first (the graph is acyclic apart
    /// from state, whose type is known before the step is inferred).
    fn node(&mut self, n: NodeId) {
        if !matches!(self.types.nodes[n], Inferred::Unknown) {
            return;
        }
        let g = self.g;
        let inst = &g.nodes[n];
        for (port, s) in inst.input_ports.iter().zip(&inst.inputs) {
            if let Source::Node { node, .. } = s
                && !port.iterate
            {
                self.node(*node);
            }
        }
        if inst.input_ports.iter().any(|p| p.iterate) {
            // An iterative node's loop body reads the node's own outputs: type the node
            // without its loop input first, then the body, then the node again in full.
            let reported = self.problems.len();
            self.signature(n, true);
            if !self.types.nodes[n].is_present() {
                // Failing (its params refused, its inputs wrong) or dropping out without its
                // loop: so it would with it, and these are its problems.
                return;
            }
            self.problems.truncate(reported);
            for (port, s) in inst.input_ports.iter().zip(&inst.inputs) {
                if let Source::Node { node, .. } = s
                    && port.iterate
                {
                    self.node(*node);
                }
            }
        }
        self.signature(n, false);
    }

    /// A node's output types from its inputs' (already inferred); with
    /// `without_loop_input`, the input closing an iterative node's loop counts as absent.
    fn signature(&mut self, n: NodeId, without_loop_input: bool) {
        let g = self.g;
        let inst = &g.nodes[n];
        if inst.disabled.is_some() {
            self.types.nodes[n] = Inferred::Absent;
            return;
        }
        let mut types = Vec::new();
        let mut absent = false;
        let mut upstream_failed = false;
        let mut ok = true;
        for (port, src) in inst.input_ports.iter().zip(&inst.inputs) {
            if without_loop_input && port.iterate {
                types.push(None);
                continue;
            }
            let t = self.types.of(*src);
            match t {
                None if self.types.failed(*src) => upstream_failed = true,
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
        if absent {
            self.types.nodes[n] = Inferred::Absent;
            return;
        }
        // A node whose params its kind refused is a problem only here, where it would run
        // (also when a value it needs failed: it would run once that is fixed).
        if let Err(problems) = &inst.built {
            for message in problems {
                self.problems
                    .push(Problem::node(&inst.file, &inst.id, message.clone()));
            }
            self.types.nodes[n] = Inferred::Failed;
            return;
        }
        if upstream_failed || !ok {
            self.types.nodes[n] = Inferred::Failed;
            return;
        }
        match inst.node().infer(&types, self.caps) {
            Ok(sig) => {
                assert_eq!(
                    sig.outputs.len(),
                    inst.output_ports.len(),
                    "node kind `{}` inferred a type per output port",
                    inst.kind
                );
                for (port, t) in inst.output_ports.iter().zip(&sig.outputs) {
                    if let Some(why) = too_large_for(self.caps, t.bytes()) {
                        self.problems.push(Problem::port(
                            &inst.file,
                            &inst.id,
                            port.name,
                            format!("output {t} takes {why}"),
                        ));
                    }
                }
                for (i, &bytes) in sig.scratch.iter().enumerate() {
                    if let Some(why) = too_large_for(self.caps, bytes) {
                        self.problems.push(Problem::node(
                            &inst.file,
                            &inst.id,
                            format!("its working buffer {i} takes {why}"),
                        ));
                    }
                }
                self.types.nodes[n] = Inferred::Present {
                    outputs: sig.outputs,
                    scratch: sig.scratch,
                    plan: sig.plan,
                };
            }
            Err(e) => {
                self.problems
                    .push(Problem::port(&inst.file, &inst.id, &e.port, e.message));
                self.types.nodes[n] = Inferred::Failed;
            }
        }
    }

    /// A state's next value has the state's type and exists.
    fn check_states(&mut self, demand: &Demand) {
        let g = self.g;
        for &s in &demand.states {
            let st = &g.states[s];
            match (self.types.states[s], self.types.of(st.next)) {
                (Some(a), Some(b)) if a != b => self.fail(format!(
                    "state `{}` is {a} but its next value `{}` is {b}",
                    st.name,
                    g.source_name(st.next)
                )),
                (Some(_), None) if !self.types.failed(st.next) => self.fail(format!(
                    "state `{}`: next value `{}` is absent",
                    st.name,
                    g.source_name(st.next)
                )),
                _ => {}
            }
        }
    }

    /// A requested output exists (an absent optional input may make it impossible).
    fn check_outputs(&mut self, outputs: &[usize]) {
        let g = self.g;
        for &o in outputs {
            let out = &g.outputs[o];
            if self.types.of(out.source).is_some() || self.types.failed(out.source) {
                continue;
            }
            if let Some((node, why)) = disabled_upstream(g, out.source) {
                self.fail(format!(
                    "output `{}` cannot be computed: it needs node `{node}`, which the graph leaves out ({why})",
                    out.name
                ));
                continue;
            }
            let missing: Vec<&str> = g
                .inputs
                .iter()
                .zip(&self.types.inputs)
                .filter(|(d, t)| d.optional && t.is_none())
                .map(|(d, _)| d.name.as_str())
                .collect();
            self.fail(format!(
                "output `{}` cannot be computed: it needs an optional input that was not given ({})",
                out.name,
                missing.join(", ")
            ));
        }
    }
}

/// The first disabled node a value depends on (`NodeInst::disabled`), with why, walking
/// its required inputs upstream.
fn disabled_upstream(g: &Graph, source: Source) -> Option<(String, String)> {
    let mut stack = vec![source];
    let mut seen = std::collections::HashSet::new();
    while let Some(s) = stack.pop() {
        let Source::Node { node, .. } = s else {
            continue;
        };
        if !seen.insert(node) {
            continue;
        }
        let inst = &g.nodes[node];
        if let Some(why) = &inst.disabled {
            return Some((inst.id.clone(), why.clone()));
        }
        for (port, src) in inst.input_ports.iter().zip(&inst.inputs) {
            if !port.optional {
                stack.push(*src);
            }
        }
    }
    None
}
