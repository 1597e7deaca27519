//! Pass 6, lowering: scheduled nodes become launches over plan values. Per phase, the
//! element-wise nodes are grouped into fused kernels (`fuse.rs`) and spectral nodes
//! folded into transforms (`fold.rs`); every unit then lowers through the function of
//! its launch kind, and a value gets its storage: registers where fusion keeps it inside
//! a kernel, state buffers for a state's next value, buffers to be assigned (`memory.rs`)
//! otherwise. State plumbing (initial and next values) and the outputs read after the
//! last step come last.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use super::demand::Demand;
use super::fuse::{self, FuseCtx, Unit};
use super::infer::Types;
use super::request::Request;
use super::schedule::Schedule;
use super::{
    BufferRole, FoldedSpectral, Launch, MemoryReport, Phase, Plan, PlanOptions, PlanValue,
    StatePlan, Storage, TransformFold, ValueId,
};
use crate::gpu::DeviceCaps;
use crate::graph::{Graph, NodeId, Source};
use crate::ids::IdVec;
use crate::node::Lowering;
use crate::value::ValueType;

/// The plan of a scheduled graph, buffers not yet assigned.
pub(super) fn lower(
    g: &Graph,
    opts: &PlanOptions,
    caps: &DeviceCaps,
    request: &Request,
    demand: &Demand,
    types: &Types,
    schedule: &Schedule,
) -> Plan {
    let state_slot: BTreeMap<usize, usize> = demand
        .states
        .iter()
        .enumerate()
        .map(|(k, &s)| (s, k))
        .collect();
    let mut next_claimed: BTreeMap<Source, usize> = BTreeMap::new();
    for (&s, &k) in &state_slot {
        let next = g.states[s].next;
        if matches!(next, Source::Node { node, port } if !g.nodes[node].output_ports[port].persistent)
        {
            next_claimed.entry(next).or_insert(k);
        }
    }
    let mut lw = Lowerer {
        g,
        opts,
        caps,
        types,
        demand,
        output_sources: request
            .outputs
            .iter()
            .map(|&o| g.outputs[o].source)
            .collect(),
        next_claimed,
        loop_reads: loop_reads(g, &schedule.loops),
        values: IdVec::new(),
        by_source: HashMap::new(),
    };
    let inputs = lw.graph_inputs();
    lw.state_values(&state_slot);
    let mut prologue = lw.phase(Phase::Prologue, &schedule.prologue, &schedule.loops);
    let mut step = lw.phase(Phase::Step, &schedule.step, &schedule.loops);
    let states = lw.state_plumbing(&state_slot, &mut prologue, &mut step);
    let outputs = lw.final_outputs(&request.outputs, &state_slot);
    let last_step_only = only_for_outputs(&step, &lw.values);
    Plan {
        caps: caps.clone(),
        values: lw.values,
        buffers: IdVec::new(),
        inputs,
        states,
        prologue,
        step,
        last_step_only,
        outputs,
        memory: MemoryReport::default(),
        pruned: schedule.pruned.clone(),
        forwarded: Vec::new(),
        in_place: Vec::new(),
    }
}

/// The step launches (indices into `step`) whose values only the requested outputs read:
/// nothing a later step sees depends on them (no state's next value, no persistent value,
/// no loop and nothing a kept launch reads), so the executor runs them on the last step
/// of each run only (an output is the value of the last step). Found backwards from the
/// launches every step needs: loops (their host decisions and halts), state copies,
/// launches writing a state's next value or a persistent value, and whatever those read.
/// A plan that carries nothing from a step to the next (no state, no persistent value)
/// keeps every launch in every step: its steps repeat one computation (a mobility timed
/// by a benchmark), each step the whole of it.
fn only_for_outputs(step: &[Launch], values: &IdVec<ValueId, PlanValue>) -> BTreeSet<usize> {
    let carried = |v: &PlanValue| {
        matches!(
            v.storage,
            Storage::State { .. } | Storage::Pending(BufferRole::Persistent)
        )
    };
    if !values.iter().any(carried) {
        return BTreeSet::new();
    }
    let mut needed: BTreeSet<ValueId> = BTreeSet::new();
    let mut only = BTreeSet::new();
    for (i, l) in step.iter().enumerate().rev() {
        let kept = matches!(l, Launch::Loop { .. } | Launch::Copy { .. })
            || l.writes()
                .iter()
                .any(|v| needed.contains(v) || carried(&values[*v]));
        if kept {
            needed.extend(l.reads());
        } else {
            only.insert(i);
        }
    }
    only
}

/// What loop bodies read from outside them, and the results loops read back: both must
/// be stored, whatever fusion would otherwise keep in registers.
fn loop_reads(g: &Graph, loops: &BTreeMap<NodeId, Vec<NodeId>>) -> BTreeSet<Source> {
    loops
        .iter()
        .flat_map(|(l, body)| body.iter().chain(std::iter::once(l)))
        .flat_map(|&n| g.nodes[n].inputs.iter().copied())
        .collect()
}

struct Lowerer<'a> {
    g: &'a Graph,
    opts: &'a PlanOptions,
    caps: &'a DeviceCaps,
    types: &'a Types,
    demand: &'a Demand,
    output_sources: BTreeSet<Source>,
    /// Node outputs written straight into a state's next buffer (state slot).
    next_claimed: BTreeMap<Source, usize>,
    loop_reads: BTreeSet<Source>,
    values: IdVec<ValueId, PlanValue>,
    by_source: HashMap<(Source, Phase), ValueId>,
}

impl Lowerer<'_> {
    fn push(&mut self, name: String, ty: ValueType, phase: Phase, storage: Storage) -> ValueId {
        self.values.push(PlanValue {
            name,
            ty,
            phase,
            storage,
        })
    }

    /// A value for a source in a phase, found again by [`Lowerer::get`].
    fn add(&mut self, src: Source, phase: Phase, ty: ValueType, storage: Storage) -> ValueId {
        let id = self.push(self.g.source_name(src), ty, phase, storage);
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

    fn output_type(&self, n: NodeId, port: usize) -> ValueType {
        self.types.nodes[n].outputs().expect("present node")[port]
    }

    /// Graph inputs that are given: one value per phase on the input's upload buffer.
    fn graph_inputs(&mut self) -> Vec<(usize, ValueType)> {
        let given: Vec<(usize, ValueType)> = self
            .types
            .inputs
            .iter()
            .enumerate()
            .filter_map(|(i, t)| t.map(|t| (i, t)))
            .collect();
        for &(i, t) in &given {
            for phase in [Phase::Prologue, Phase::Step] {
                self.add(Source::Input(i), phase, t, Storage::Input(i));
            }
        }
        given
    }

    /// A state's current value during a step lives in its state buffer.
    fn state_values(&mut self, state_slot: &BTreeMap<usize, usize>) {
        for (&s, &k) in state_slot {
            let ty = self.types.states[s].expect("checked by inference");
            self.add(
                Source::State(s),
                Phase::Step,
                ty,
                Storage::State {
                    state: k,
                    next: false,
                },
            );
        }
    }

    /// Whether a node output is needed after the phase, so fusion must store it.
    fn escapes(&self, phase: Phase, src: Source) -> bool {
        match phase {
            Phase::Step => {
                self.output_sources.contains(&src)
                    || self.next_claimed.contains_key(&src)
                    || self.loop_reads.contains(&src)
            }
            Phase::Prologue => self
                .demand
                .states
                .iter()
                .any(|&s| self.g.states[s].init == src),
        }
    }

    /// Where a node output lives when it is stored (`escapes`) or may stay in registers.
    fn storage_for(&self, phase: Phase, src: Source, escapes: bool) -> Storage {
        if phase == Phase::Step
            && let Some(&k) = self.next_claimed.get(&src)
        {
            return Storage::State {
                state: k,
                next: true,
            };
        }
        let Source::Node { node, port } = src else {
            unreachable!("node outputs only")
        };
        if self.g.nodes[node].output_ports[port].persistent {
            Storage::Pending(BufferRole::Persistent)
        } else if phase == Phase::Step && self.output_sources.contains(&src) {
            Storage::Pending(BufferRole::Output)
        } else if escapes {
            Storage::Pending(BufferRole::Pool)
        } else {
            Storage::Register
        }
    }

    /// The units of a node order (fused groups, folded transforms, single nodes).
    fn units(&self, phase: Phase, order: &[NodeId]) -> Vec<Unit> {
        let escapes = |src: Source| self.escapes(phase, src);
        let ctx = FuseCtx {
            g: self.g,
            types: &self.types.nodes,
            order,
            fuse: self.opts.fuse,
            escapes: &escapes,
        };
        let units = fuse::group(&ctx);
        let input_types = |n: NodeId| self.types.inputs_of(self.g, n);
        super::fold::fold(&ctx, units, self.caps, &input_types)
    }

    /// The launches of one phase.
    fn phase(
        &mut self,
        phase: Phase,
        order: &[NodeId],
        loops: &BTreeMap<NodeId, Vec<NodeId>>,
    ) -> Vec<Launch> {
        let mut launches = Vec::new();
        for unit in self.units(phase, order) {
            let launch = match unit {
                Unit::Single(n) if loops.contains_key(&n) => self.loop_launch(phase, n, &loops[&n]),
                Unit::Group(members) => self.fused(phase, &members),
                unit => self.single(phase, unit),
            };
            launches.push(launch);
        }
        launches
    }

    /// The output values of a node's launch; a transform that hosts a spectral node
    /// stores only the latter's output, so its own stay in registers.
    fn node_outputs(&mut self, phase: Phase, n: NodeId, stored: bool) -> Vec<ValueId> {
        let ports = self.types.nodes[n].outputs().expect("present node").len();
        (0..ports)
            .map(|port| {
                let src = Source::Node { node: n, port };
                let st = if stored {
                    self.storage_for(phase, src, true)
                } else {
                    Storage::Register
                };
                self.add(src, phase, self.output_type(n, port), st)
            })
            .collect()
    }

    fn scratch(&mut self, phase: Phase, n: NodeId) -> Vec<ValueId> {
        let id = self.g.nodes[n].id.clone();
        self.types
            .scratch(n)
            .to_vec()
            .into_iter()
            .enumerate()
            .map(|(i, bytes)| {
                let ty = ValueType::Indices {
                    n: bytes.div_ceil(4) as u32,
                };
                self.push(
                    format!("{id} (scratch {i})"),
                    ty,
                    phase,
                    Storage::Pending(BufferRole::Pool),
                )
            })
            .collect()
    }

    fn node_inputs(&self, phase: Phase, n: NodeId) -> Vec<Option<ValueId>> {
        self.g.nodes[n]
            .inputs
            .iter()
            .map(|s| self.try_get(*s, phase))
            .collect()
    }

    /// A node that runs alone: its own kernels, a spectral node's kernel, or a transform
    /// with what it folds.
    fn single(&mut self, phase: Phase, unit: Unit) -> Launch {
        let (n, hosted) = match unit {
            Unit::Single(n) | Unit::AfterFold(n) => (n, None),
            Unit::Folded {
                transform,
                spectral,
                inverse,
            } => (transform, Some((spectral, inverse))),
            Unit::Group(_) => unreachable!("groups lower as fused kernels"),
        };
        let g = self.g;
        let inputs = self.node_inputs(phase, n);
        let outputs = self.node_outputs(phase, n, hosted.is_none());
        let fold = match (hosted, &unit) {
            (Some((b, inverse)), _) => {
                let src = Source::Node { node: b, port: 0 };
                let st = self.storage_for(phase, src, true);
                TransformFold::Hosts(FoldedSpectral {
                    node: b,
                    output: self.add(src, phase, self.output_type(b, 0), st),
                    inverse,
                })
            }
            (None, Unit::AfterFold(_)) => TransformFold::FirstPassElsewhere,
            _ => TransformFold::Alone,
        };
        let scratch = self.scratch(phase, n);
        let input_types = self.types.inputs_of(g, n);
        let inst = &g.nodes[n];
        let mut notes = inst.node().notes(&input_types);
        let plan = self.types.plan(n).cloned();
        notes.extend(plan.as_ref().map(|p| p.to_string()));
        match inst.node().lowering() {
            Lowering::Transform(t) => {
                notes.extend(t.device_notes(&input_types, self.caps, fold.folding()));
                notes.extend(fold_notes(g, &fold));
                Launch::Transform {
                    node: n,
                    inputs,
                    outputs,
                    scratch,
                    notes,
                    plan,
                    fold,
                }
            }
            lowering => Launch::Node {
                node: n,
                inputs,
                outputs,
                scratch,
                notes,
                plan,
                // Only a node that binds its own buffers can tell an aliased output.
                in_place: match lowering {
                    Lowering::Kernels(_) => port_pairs(inst, |p| p.in_place_of),
                    _ => Vec::new(),
                },
            },
        }
    }

    /// A group of element-wise nodes as one generated kernel.
    fn fused(&mut self, phase: Phase, members: &[(NodeId, bool)]) -> Launch {
        let member_outputs: Vec<ValueId> = members
            .iter()
            .map(|&(n, escapes)| {
                let src = Source::Node { node: n, port: 0 };
                let st = self.storage_for(phase, src, escapes);
                self.add(src, phase, self.output_type(n, 0), st)
            })
            .collect();
        let get = |s: Source| self.try_get(s, phase);
        Launch::Fused(fuse::generate(
            self.g,
            members,
            &member_outputs,
            &get,
            &self.values,
        ))
    }

    /// An iterative node and its loop body, planned and fused on its own.
    fn loop_launch(&mut self, phase: Phase, n: NodeId, body: &[NodeId]) -> Launch {
        // The node's outputs exist first; its body reads them, and the node then reads
        // the body's result.
        let Launch::Node {
            node,
            outputs,
            scratch,
            mut notes,
            plan,
            ..
        } = self.single(phase, Unit::Single(n))
        else {
            unreachable!("an iterative node lowers as a node launch")
        };
        let body_launches: Vec<Launch> = self
            .units(phase, body)
            .into_iter()
            .map(|u| match u {
                Unit::Group(members) => self.fused(phase, &members),
                u => self.single(phase, u),
            })
            .collect();
        let inputs = self.node_inputs(phase, n);
        notes.push(format!(
            "loop body: {} launch{} ({} node{})",
            body_launches.len(),
            if body_launches.len() == 1 { "" } else { "es" },
            body.len(),
            if body.len() == 1 { "" } else { "s" }
        ));
        Launch::Loop {
            node,
            inputs,
            outputs,
            scratch,
            notes,
            plan,
            body: body_launches,
            refills: port_pairs(&self.g.nodes[n], |p| p.refilled_from),
            starts: port_pairs(&self.g.nodes[n], |p| p.started_from),
            finals: output_pairs(&self.g.nodes[n], |p| p.final_of),
        }
    }

    /// Initial values are copied into the states before the first step; next values not
    /// written in place are copied at the end of each step. A state whose next value is
    /// itself (`"next": "state.NAME"`: a value kept unchanged, a permutation taken once)
    /// gets its initial value in both of its buffers and no copy in the steps.
    fn state_plumbing(
        &mut self,
        state_slot: &BTreeMap<usize, usize>,
        prologue: &mut Vec<Launch>,
        step: &mut Vec<Launch>,
    ) -> Vec<StatePlan> {
        let g = self.g;
        let mut states = Vec::new();
        for (&s, &k) in state_slot {
            let def = &g.states[s];
            let ty = self.types.states[s].expect("checked by inference");
            let init = self.get(def.init, Phase::Prologue);
            let slot0 = self.push(
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
            let current = self.get(Source::State(s), Phase::Step);
            if def.next == Source::State(s) {
                let slot1 = self.push(
                    format!("state.{} (initial, both buffers)", def.name),
                    ty,
                    Phase::Prologue,
                    Storage::State {
                        state: k,
                        next: true,
                    },
                );
                prologue.push(Launch::Copy {
                    src: init,
                    dst: slot1,
                });
            } else if self.next_claimed.get(&def.next) != Some(&k) {
                let src = self.get(def.next, Phase::Step);
                let dst = self.push(
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
        states
    }

    /// Outputs read after the last step. An output naming `state.x` is the state after
    /// the last step, i.e. the last next value.
    fn final_outputs(
        &mut self,
        requested: &[usize],
        state_slot: &BTreeMap<usize, usize>,
    ) -> Vec<(String, ValueId)> {
        let g = self.g;
        requested
            .iter()
            .map(|&o| {
                let out = &g.outputs[o];
                let v = match out.source {
                    Source::State(s) => self.push(
                        format!("state.{} (final)", g.states[s].name),
                        self.types.states[s].expect("checked by inference"),
                        Phase::Step,
                        Storage::State {
                            state: state_slot[&s],
                            next: true,
                        },
                    ),
                    src => self.get(src, Phase::Step),
                };
                (out.name.clone(), v)
            })
            .collect()
    }
}

/// The (output port, input port) pairs of a node whose outputs name an input by `link`
/// (in place of it, refilled from it, started from it).
fn port_pairs(
    inst: &crate::graph::NodeInst,
    link: impl Fn(&crate::node::PortSpec) -> Option<&'static str>,
) -> Vec<(usize, usize)> {
    linked_ports(&inst.output_ports, &inst.input_ports, link)
}

/// The (output port, output port) pairs of a node whose outputs name another output by
/// `link` (the final value of it).
fn output_pairs(
    inst: &crate::graph::NodeInst,
    link: impl Fn(&crate::node::PortSpec) -> Option<&'static str>,
) -> Vec<(usize, usize)> {
    linked_ports(&inst.output_ports, &inst.output_ports, link)
}

/// (index in `outputs`, index in `targets`) of every output that names a target port by
/// `link`.
fn linked_ports(
    outputs: &[crate::node::PortSpec],
    targets: &[crate::node::PortSpec],
    link: impl Fn(&crate::node::PortSpec) -> Option<&'static str>,
) -> Vec<(usize, usize)> {
    outputs
        .iter()
        .enumerate()
        .filter_map(|(o, p)| {
            let name = link(p)?;
            let t = targets.iter().position(|q| q.name == name)?;
            Some((o, t))
        })
        .collect()
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
