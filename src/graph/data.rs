//! Host-side checks of the data given for graph inputs, by the nodes that read it
//! (`Node::check_input`): a particle outside a node's walls is refused before upload,
//! named by input, node, port and row, rather than run.

use crate::ids::Id;
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
    /// later steps read what nodes computed), directly or through nodes that pass its
    /// rows on (`Node::passes_rows`: a gather that sorts particles, its output read by
    /// nodes or the initial value of a state they read).
    pub fn readers_of_input(&self, input: usize) -> Vec<(NodeId, usize)> {
        let direct = |s: &Source| match *s {
            Source::Input(i) => i == input,
            Source::State(k) => self.states[k].init == Source::Input(input),
            _ => false,
        };
        let mut readers: Vec<(NodeId, usize)> = self.readers_where(direct);
        // Follow pass-through nodes; each (node, port) is added once, so this ends.
        let mut next = 0;
        while next < readers.len() {
            let (n, port) = readers[next];
            next += 1;
            let Ok(built) = &self.nodes[n].built else {
                continue;
            };
            let Some(out) = built.node.passes_rows(port) else {
                continue;
            };
            let passed = Source::Node { node: n, port: out };
            let through = |s: &Source| match *s {
                Source::State(k) => self.states[k].init == passed,
                other => other == passed,
            };
            for reader in self.readers_where(through) {
                if !readers.contains(&reader) {
                    readers.push(reader);
                }
            }
        }
        readers
    }

    /// The node ports whose source satisfies `reads`, in node order.
    fn readers_where(&self, reads: impl Fn(&Source) -> bool + Copy) -> Vec<(NodeId, usize)> {
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

    /// Whether some node reading `input` (outside `skip`) checks the data given for it.
    pub fn input_is_checked(&self, input: usize, skip: &[NodeId]) -> bool {
        self.readers_of_input(input).into_iter().any(|(n, _)| {
            !skip.contains(&n)
                && matches!(&self.nodes[n].built, Ok(built) if built.node.checks_input())
        })
    }

    /// Checks the data given for graph input `input` with every node port that reads it
    /// ([`Graph::readers_of_input`]), except the nodes in `skip` (those a plan does not
    /// run); the first refusal, in the order of `readers_of_input` (direct readers in
    /// node order, then those behind pass-through nodes).
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

    /// The graph inputs read by the nodes that check data together
    /// (`Node::checks_inputs_together`), outside `skip`: the program keeps host copies of
    /// them.
    pub fn jointly_checked_inputs(&self, skip: &[NodeId]) -> Vec<usize> {
        (0..self.inputs.len())
            .filter(|&i| {
                self.readers_of_input(i).into_iter().any(|(n, _)| {
                    !skip.contains(&n)
                        && matches!(&self.nodes[n].built,
                            Ok(built) if built.node.checks_inputs_together())
                })
            })
            .collect()
    }

    /// Runs every `Node::check_inputs_together` (nodes outside `skip`) on the data
    /// `data(input)` gives for the graph inputs their ports read: the first refusal, with
    /// the name of the input feeding the port it blames.
    pub fn check_joint_input_data<'d>(
        &self,
        data: impl Fn(usize) -> Option<&'d HostArray>,
        skip: &[NodeId],
    ) -> Result<(), (String, InputDataError)> {
        let mut feeding: Vec<Vec<Option<usize>>> = self
            .nodes
            .iter()
            .map(|inst| vec![None; inst.inputs.len()])
            .collect();
        for i in 0..self.inputs.len() {
            for (n, port) in self.readers_of_input(i) {
                feeding[n.index()][port].get_or_insert(i);
            }
        }
        for (n, inst) in self.nodes.iter_enumerated() {
            let Ok(built) = &inst.built else { continue };
            if skip.contains(&n) || !built.node.checks_inputs_together() {
                continue;
            }
            let ports: Vec<Option<&HostArray>> = feeding[n.index()]
                .iter()
                .map(|i| i.and_then(&data))
                .collect();
            built.node.check_inputs_together(&ports).map_err(|e| {
                let input = feeding[n.index()][e.port]
                    .map_or_else(String::new, |i| self.inputs[i].name.clone());
                (
                    input,
                    InputDataError {
                        node: inst.id.clone(),
                        kind: inst.kind,
                        port: inst.input_ports[e.port].name.to_string(),
                        row: e.row,
                        message: e.message,
                    },
                )
            })?;
        }
        Ok(())
    }
}
