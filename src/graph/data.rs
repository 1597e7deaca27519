//! Host-side checks of the data given for graph inputs, by the nodes that read it
//! (`Node::check_input`): a particle outside a node's walls is refused before upload,
//! named by input, node, port and row, rather than run.

use crate::value::HostArray;

use super::{Graph, NodeId, Source};

/// A graph input's data refused by a node that reads it.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("refused by node `{node}` ({kind}), port `{port}`: row {row}: {message}")]
pub struct InputDataError {
    pub node: String,
    pub kind: &'static str,
    pub port: String,
    pub row: usize,
    pub message: String,
}

impl Graph {
    /// The node ports (node, input port) that read graph input `input` as given: wired to
    /// it, or reading a state whose initial value it is (the first step reads the data;
    /// later steps read what nodes computed).
    pub fn readers_of_input(&self, input: usize) -> Vec<(NodeId, usize)> {
        let reads = |s: &Source| match *s {
            Source::Input(i) => i == input,
            Source::State(k) => self.states[k].init == Source::Input(input),
            _ => false,
        };
        self.nodes
            .iter_enumerated()
            .flat_map(|(n, inst)| {
                inst.inputs
                    .iter()
                    .enumerate()
                    .filter(move |(_, s)| reads(s))
                    .map(move |(port, _)| (n, port))
            })
            .collect()
    }

    /// Checks the data given for graph input `input` with every node port that reads it
    /// ([`Graph::readers_of_input`]), except the nodes in `skip` (those a plan does not
    /// run); the first refusal, in node order.
    /// Whether some node reading `input` (outside `skip`) checks the data given for it.
    pub fn input_is_checked(&self, input: usize, skip: &[NodeId]) -> bool {
        self.readers_of_input(input).into_iter().any(|(n, _)| {
            !skip.contains(&n)
                && matches!(&self.nodes[n].built, Ok(built) if built.node.checks_input())
        })
    }

    pub fn check_input_data(
        &self,
        input: usize,
        data: &HostArray,
        skip: &[NodeId],
    ) -> Result<(), InputDataError> {
        for (n, port) in self.readers_of_input(input) {
            if skip.contains(&n) {
                continue;
            }
            let inst = &self.nodes[n];
            // A node that was not built has no plan that runs it (the planner refuses
            // such plans), so it never sees data.
            let Ok(built) = &inst.built else { continue };
            built
                .node
                .check_input(port, data)
                .map_err(|e| InputDataError {
                    node: inst.id.clone(),
                    kind: inst.kind,
                    port: inst.input_ports[port].name.to_string(),
                    row: e.row,
                    message: e.message,
                })?;
        }
        Ok(())
    }
}
