//! Pass 5, scheduling: the order in which present nodes run, per phase, with each
//! iterative node's loop body set apart (it runs inside the node's launch, and the node
//! after everything its body reads from outside), and the nodes the plan does not run.

use std::cmp::Reverse;
use std::collections::{BTreeMap, BTreeSet, BinaryHeap};

use super::demand::Demand;
use super::infer::Types;
use crate::graph::{Graph, NodeId, Problem, Problems, Source};

pub(super) struct Schedule {
    pub prologue: Vec<NodeId>,
    pub step: Vec<NodeId>,
    /// Each iterative node of the step with its loop body in order.
    pub loops: BTreeMap<NodeId, Vec<NodeId>>,
    /// Nodes the graph has but the plan does not run (not demanded, or absent).
    pub pruned: Vec<NodeId>,
}

pub(super) fn schedule(
    g: &Graph,
    demand: &Demand,
    types: &Types,
    forwarded: &[NodeId],
) -> Result<Schedule, Problems> {
    let present = |n: &NodeId| types.nodes[*n].is_present();
    let iterative = |n: NodeId| g.nodes[n].input_ports.iter().any(|p| p.iterate);
    let problems: Vec<Problem> = demand
        .prologue
        .iter()
        .filter(|&&n| iterative(n))
        .map(|&n| {
            let inst = &g.nodes[n];
            Problem::node(
                &inst.file,
                &inst.id,
                "an iterative node cannot compute a state's initial value (it runs in the steps only)",
            )
        })
        .collect();
    if !problems.is_empty() {
        return Err(Problems(problems));
    }
    let prologue = topo(
        g,
        demand.prologue.iter().copied().filter(present).collect(),
        &BTreeMap::new(),
    );
    let step_present: BTreeSet<NodeId> = demand.step.iter().copied().filter(present).collect();
    let mut loops = BTreeMap::new();
    let mut after_outside_reads: BTreeMap<NodeId, BTreeSet<NodeId>> = BTreeMap::new();
    let mut in_body = BTreeSet::new();
    for &l in step_present.iter().filter(|&&n| iterative(n)) {
        let body: BTreeSet<NodeId> = g
            .loop_body(l)
            .into_iter()
            .filter(|b| step_present.contains(b))
            .collect();
        let outside: BTreeSet<NodeId> = body
            .iter()
            .flat_map(|&b| g.nodes[b].inputs.iter().copied())
            .filter_map(|s| match s {
                Source::Node { node, .. } if node != l && !body.contains(&node) => Some(node),
                _ => None,
            })
            .collect();
        after_outside_reads.insert(l, outside);
        in_body.extend(body.iter().copied());
        loops.insert(l, topo(g, body, &BTreeMap::new()));
    }
    let step = topo(
        g,
        step_present.difference(&in_body).copied().collect(),
        &after_outside_reads,
    );
    let pruned = g
        .nodes
        .ids()
        .filter(|n| !(demand.step.contains(n) || demand.prologue.contains(n)) || !present(n))
        .filter(|n| !forwarded.contains(n))
        .collect();
    Ok(Schedule {
        prologue,
        step,
        loops,
        pruned,
    })
}

/// Topological order of a node set; among ready nodes the one declared first runs
/// first, so plans read in file order where the data allow. `extra[n]`: nodes `n` must
/// follow besides its inputs' producers. Loop inputs (read after each iteration) impose
/// no order.
fn topo(
    g: &Graph,
    set: BTreeSet<NodeId>,
    extra: &BTreeMap<NodeId, BTreeSet<NodeId>>,
) -> Vec<NodeId> {
    let mut indeg: BTreeMap<NodeId, usize> = set.iter().map(|&n| (n, 0)).collect();
    let mut users: BTreeMap<NodeId, Vec<NodeId>> = BTreeMap::new();
    for &n in &set {
        let inst = &g.nodes[n];
        let mut deps: BTreeSet<NodeId> = inst
            .input_ports
            .iter()
            .zip(&inst.inputs)
            .filter_map(|(port, s)| match s {
                Source::Node { node, .. } if set.contains(node) && !port.iterate => Some(*node),
                _ => None,
            })
            .collect();
        deps.extend(
            extra
                .get(&n)
                .into_iter()
                .flatten()
                .filter(|d| set.contains(d)),
        );
        for d in deps {
            *indeg.get_mut(&n).expect("in set") += 1;
            users.entry(d).or_default().push(n);
        }
    }
    let mut ready: BinaryHeap<Reverse<NodeId>> = indeg
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
