//! Pass 4, forwarding: a node whose output is, for its input types, one of its inputs
//! unchanged (`Node::forwards`: an `add` whose optional term is absent, a disabled
//! `gather`) is read through. Its readers are rewired to that input; the node stays in
//! the graph, unread, so every index keeps its meaning and the types inferred before
//! stay valid (a forwarded output has its input's type). Demand is then recomputed on
//! the rewired graph: what only a forwarded node read drops out.

use std::borrow::Cow;
use std::collections::HashMap;

use super::demand::Demand;
use super::infer::Types;
use crate::graph::{Graph, NodeId, Source};

/// The graph with forwarded nodes read through, and those nodes (ascending).
pub(super) fn read_through<'g>(
    g: &'g Graph,
    demand: &Demand,
    types: &Types,
) -> (Cow<'g, Graph>, Vec<NodeId>) {
    let forwards: HashMap<NodeId, Source> = demand
        .step
        .iter()
        .chain(&demand.prologue)
        .filter_map(|&n| {
            if !types.nodes[n].is_present() {
                return None;
            }
            let inputs = types.inputs_of(g, n);
            let i = g.nodes[n].node().forwards(&inputs)?;
            debug_assert_eq!(
                types.nodes[n].outputs().and_then(|o| o.first().copied()),
                inputs[i],
                "node `{}` forwards an input of another type",
                g.nodes[n].id
            );
            Some((n, g.nodes[n].inputs[i]))
        })
        .collect();
    if forwards.is_empty() {
        return (Cow::Borrowed(g), Vec::new());
    }
    let mut forwarded: Vec<NodeId> = forwards.keys().copied().collect();
    forwarded.sort_unstable();
    (Cow::Owned(g.forwarding(&forwards)), forwarded)
}
