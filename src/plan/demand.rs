//! Pass 2, demand: the nodes and states the requested outputs need, per phase. Nothing
//! else is planned (a graph models only what its outputs need).

use std::collections::BTreeSet;

use crate::graph::{Graph, NodeId, Problem, Problems, Source};

/// What the requested outputs need.
pub(super) struct Demand {
    /// Nodes run every step.
    pub step: BTreeSet<NodeId>,
    /// Nodes run once before the first step: the initial values of the needed states.
    pub prologue: BTreeSet<NodeId>,
    /// States read by the step (indices into `Graph::states`).
    pub states: BTreeSet<usize>,
}

pub(super) fn of(g: &Graph, outputs: &[usize]) -> Result<Demand, Problems> {
    let mut step = BTreeSet::new();
    let mut states = BTreeSet::new();
    let mut stack: Vec<Source> = outputs.iter().map(|&o| g.outputs[o].source).collect();
    while let Some(s) = stack.pop() {
        match s {
            Source::Node { node, .. } => {
                if step.insert(node) {
                    stack.extend(g.nodes[node].inputs.iter().copied());
                }
            }
            Source::State(i) => {
                if states.insert(i) {
                    stack.push(g.states[i].next);
                }
            }
            Source::Input(_) | Source::Absent => {}
        }
    }
    let mut prologue = BTreeSet::new();
    let mut problems = Vec::new();
    let mut stack: Vec<Source> = states.iter().map(|&s| g.states[s].init).collect();
    while let Some(s) = stack.pop() {
        match s {
            Source::Node { node, .. } if prologue.insert(node) => {
                stack.extend(g.nodes[node].inputs.iter().copied());
            }
            Source::State(i) => problems.push(Problem::file(
                &g.file,
                format!(
                    "the initial value of a state depends on state `{}`; initial values must come from inputs or from nodes that read no state",
                    g.states[i].name
                ),
            )),
            _ => {}
        }
    }
    if problems.is_empty() {
        Ok(Demand {
            step,
            prologue,
            states,
        })
    } else {
        Err(Problems(problems))
    }
}
