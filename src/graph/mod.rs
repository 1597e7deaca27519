//! Graph files and the validated graph they load into.
//!
//! `load` reads a JSON graph file, expands subgraph nodes (other graph files used as
//! nodes) inline, resolves params, builds every node through the registry and resolves
//! every edge. It reports all problems at once, each with file, node and port. The
//! result, [`Graph`], is flat: subgraph nodes are gone, their nodes carry ids like
//! `mobility/spread`.

mod data;
pub mod library;
mod load;
mod schema;

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::fmt;
use std::path::PathBuf;
use std::sync::Arc;

pub use data::InputDataError;
pub use load::{LoadOptions, MAX_EXPANDED_NODES, MAX_SUBGRAPH_DEPTH, load, load_text};
pub use schema::{SCHEMA_VERSION, check_unique_keys};

use crate::expr::ParamValue;
use crate::ids::IdVec;
use crate::node::{Node, Params, PortSpec};
use crate::value::ValueType;

crate::typed_id!(
    /// A node of a flattened graph: index into [`Graph::nodes`].
    NodeId
);

/// Where a value comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Source {
    /// A graph input (index into [`Graph::inputs`]).
    Input(usize),
    /// The current value of a state (index into [`Graph::states`]).
    State(usize),
    /// Output `port` of node `node`.
    Node { node: NodeId, port: usize },
    /// Nothing: an optional input left unconnected.
    Absent,
}

/// One problem in a graph file.
#[derive(Clone, Debug, PartialEq)]
pub struct Problem {
    pub file: PathBuf,
    pub node: Option<String>,
    pub port: Option<String>,
    pub message: String,
}

impl Problem {
    pub fn file(file: &std::path::Path, message: impl Into<String>) -> Self {
        Problem {
            file: file.to_path_buf(),
            node: None,
            port: None,
            message: message.into(),
        }
    }

    pub fn node(file: &std::path::Path, node: &str, message: impl Into<String>) -> Self {
        Problem {
            file: file.to_path_buf(),
            node: Some(node.to_string()),
            port: None,
            message: message.into(),
        }
    }

    pub fn port(
        file: &std::path::Path,
        node: &str,
        port: &str,
        message: impl Into<String>,
    ) -> Self {
        Problem {
            file: file.to_path_buf(),
            node: Some(node.to_string()),
            port: Some(port.to_string()),
            message: message.into(),
        }
    }
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if let Some(n) = &self.node {
            write!(f, ": node `{n}`")?;
        }
        if let Some(p) = &self.port {
            write!(f, ", port `{p}`")?;
        }
        write!(f, ": {}", self.message)
    }
}

/// All problems of a graph file, reported together.
#[derive(Debug, Clone, PartialEq)]
pub struct Problems(pub Vec<Problem>);

impl fmt::Display for Problems {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.0.len();
        writeln!(f, "{n} problem{}:", if n == 1 { "" } else { "s" })?;
        for p in &self.0 {
            writeln!(f, "  {p}")?;
        }
        Ok(())
    }
}

impl std::error::Error for Problems {}

/// A graph-level param with its resolved value.
#[derive(Clone, Debug)]
pub struct GraphParam {
    pub name: String,
    pub value: ParamValue,
    pub default: ParamValue,
    pub doc: String,
    pub constraint: String,
}

/// A named size with the default used when no data fixes it.
#[derive(Clone, Debug)]
pub struct SizeDef {
    pub name: String,
    pub default: u32,
    pub doc: String,
}

/// A count in an input declaration.
#[derive(Clone, Debug, PartialEq)]
pub enum Dim {
    Fixed(u32),
    /// A declared size; all inputs naming it must agree.
    Size(String),
    /// Any count.
    Free,
}

/// A value whose type is not the one an input declares.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("expected {expected}, got {got}")]
pub struct ShapeMismatch {
    /// The declaration, as users write it (`particles(nx3)`).
    pub expected: String,
    pub got: ValueType,
}

/// The declared shape of a graph input.
#[derive(Clone, Debug, PartialEq)]
pub enum InputShape {
    Particles {
        rows: Dim,
        cols: u32,
    },
    Indices {
        rows: Dim,
    },
    /// Grids and scalars: the declaration gives the whole type.
    Fixed(ValueType),
}

impl InputShape {
    /// Checks a concrete type against the declaration; sizes are checked by the caller.
    pub fn check(&self, t: &ValueType) -> Result<(), ShapeMismatch> {
        let ok = match (self, t) {
            (InputShape::Particles { rows, cols }, ValueType::Particles { n, k }) => {
                cols == k && !matches!(rows, Dim::Fixed(r) if r != n)
            }
            (InputShape::Indices { rows }, ValueType::Indices { n }) => {
                !matches!(rows, Dim::Fixed(r) if r != n)
            }
            (InputShape::Fixed(want), t) => want == t,
            _ => false,
        };
        if ok {
            Ok(())
        } else {
            Err(ShapeMismatch {
                expected: self.describe(),
                got: *t,
            })
        }
    }

    /// The type this input has when its sizes take the given values.
    pub fn with_sizes(&self, size: impl Fn(&str) -> Option<u32>) -> Option<ValueType> {
        let dim = |d: &Dim| match d {
            Dim::Fixed(n) => Some(*n),
            Dim::Size(s) => size(s),
            Dim::Free => None,
        };
        Some(match self {
            InputShape::Particles { rows, cols } => ValueType::Particles {
                n: dim(rows)?,
                k: *cols,
            },
            InputShape::Indices { rows } => ValueType::Indices { n: dim(rows)? },
            InputShape::Fixed(t) => *t,
        })
    }

    pub fn describe(&self) -> String {
        let dim = |d: &Dim| match d {
            Dim::Fixed(n) => n.to_string(),
            Dim::Size(s) => s.clone(),
            Dim::Free => "N".into(),
        };
        match self {
            InputShape::Particles { rows, cols } => format!("particles({}x{cols})", dim(rows)),
            InputShape::Indices { rows } => format!("indices({})", dim(rows)),
            InputShape::Fixed(t) => t.to_string(),
        }
    }
}

#[derive(Clone, Debug)]
pub struct InputDef {
    pub name: String,
    pub shape: InputShape,
    pub optional: bool,
    pub doc: String,
}

#[derive(Clone, Debug)]
pub struct StateDef {
    pub name: String,
    pub init: Source,
    pub next: Source,
    pub doc: String,
}

#[derive(Clone, Debug)]
pub struct OutputDef {
    pub name: String,
    pub source: Source,
    pub doc: String,
}

/// A node of the flattened graph. Cloning shares the built node.
#[derive(Clone)]
pub struct NodeInst {
    /// Full id: `parent/child` for nodes that came from subgraphs.
    pub id: String,
    pub kind: &'static str,
    /// The graph file that declared it.
    pub file: PathBuf,
    pub input_ports: Vec<PortSpec>,
    pub output_ports: Vec<PortSpec>,
    /// One source per input port; [`Source::Absent`] for an unconnected optional port.
    pub inputs: Vec<Source>,
    /// The node built from its checked params, or what is wrong with its params (out of
    /// range, refused by the kind's build): a graph file may hold nodes its requested
    /// outputs never run (fcm.json's torque path when no torques are given), so these
    /// problems are the planner's to report, for the nodes it would run (`plan::infer`).
    pub built: Result<BuiltNode, Vec<String>>,
    /// Why the file leaves this node out (its `enabled`, or its subgraph node's, is
    /// false, with where the value came from): the planner treats it as absent.
    pub disabled: Option<String>,
}

/// A node built from params its kind accepted.
#[derive(Clone)]
pub struct BuiltNode {
    pub params: Params,
    pub node: Arc<dyn Node>,
}

impl NodeInst {
    /// The built node. Only the nodes a plan runs are asked for it, and planning stops
    /// at any of them that could not be built, with its problems.
    pub fn node(&self) -> &dyn Node {
        match &self.built {
            Ok(b) => b.node.as_ref(),
            Err(_) => panic!(
                "node `{}` was not built; the planner reports its problems before anything uses it",
                self.id
            ),
        }
    }
}

/// A loaded, validated, flattened graph.
#[derive(Clone)]
pub struct Graph {
    pub file: PathBuf,
    pub doc: String,
    pub params: Vec<GraphParam>,
    pub sizes: Vec<SizeDef>,
    pub inputs: Vec<InputDef>,
    pub states: Vec<StateDef>,
    pub nodes: IdVec<NodeId, NodeInst>,
    pub outputs: Vec<OutputDef>,
}

impl Graph {
    pub fn input(&self, name: &str) -> Option<usize> {
        self.inputs.iter().position(|i| i.name == name)
    }

    pub fn output(&self, name: &str) -> Option<usize> {
        self.outputs.iter().position(|o| o.name == name)
    }

    /// A top-level param's value (its default, --set or expression resolved).
    pub fn param(&self, name: &str) -> Option<&ParamValue> {
        self.params
            .iter()
            .find(|p| p.name == name)
            .map(|p| &p.value)
    }

    /// The required inputs' types from their declarations, with the declared sizes'
    /// defaults and one row where the count is free: the inputs a plan assumes when no
    /// data is given (`validate`, `inspect`). Optional inputs are absent, as in a run that
    /// does not give them.
    pub fn declared_input_types(&self) -> BTreeMap<String, ValueType> {
        self.assumed_input_types(&BTreeMap::new(), &[])
    }

    /// [`Graph::declared_input_types`] with the optional inputs given too.
    pub fn declared_input_types_with_optional(&self) -> BTreeMap<String, ValueType> {
        let optional: Vec<&str> = self
            .inputs
            .iter()
            .filter(|i| i.optional)
            .map(|i| i.name.as_str())
            .collect();
        self.assumed_input_types(&BTreeMap::new(), &optional)
    }

    /// The inputs a plan assumes when only some are given (`inspect`): those `given`, and
    /// every other required input, and the optional inputs named in `optional`, at their
    /// declared shapes, a size taken from a given input that fixes it, else from its
    /// default (one row where the count is free). Other optional inputs are absent, as
    /// in a run that does not give them.
    pub fn assumed_input_types(
        &self,
        given: &BTreeMap<String, ValueType>,
        optional: &[&str],
    ) -> BTreeMap<String, ValueType> {
        let mut fixed: BTreeMap<&str, u32> = BTreeMap::new();
        for decl in &self.inputs {
            let rows = match (&decl.shape, given.get(&decl.name)) {
                (InputShape::Particles { rows, .. }, Some(ValueType::Particles { n, .. }))
                | (InputShape::Indices { rows }, Some(ValueType::Indices { n })) => {
                    Some((rows, *n))
                }
                _ => None,
            };
            if let Some((Dim::Size(s), n)) = rows {
                fixed.entry(s.as_str()).or_insert(n);
            }
        }
        let size = |s: &str| {
            fixed
                .get(s)
                .copied()
                .or_else(|| self.sizes.iter().find(|d| d.name == s).map(|d| d.default))
        };
        let mut types = given.clone();
        for i in &self.inputs {
            if types.contains_key(&i.name) || (i.optional && !optional.contains(&i.name.as_str())) {
                continue;
            }
            let shape = match &i.shape {
                InputShape::Particles {
                    rows: Dim::Free,
                    cols,
                } => InputShape::Particles {
                    rows: Dim::Fixed(1),
                    cols: *cols,
                },
                InputShape::Indices { rows: Dim::Free } => InputShape::Indices {
                    rows: Dim::Fixed(1),
                },
                other => other.clone(),
            };
            if let Some(t) = shape.with_sizes(size) {
                types.insert(i.name.clone(), t);
            }
        }
        types
    }

    /// A value's name as users write it: `inputs.x`, `state.x`, `node.port`.
    pub fn source_name(&self, s: Source) -> String {
        match s {
            Source::Input(i) => format!("inputs.{}", self.inputs[i].name),
            Source::State(i) => format!("state.{}", self.states[i].name),
            Source::Node { node, port } => {
                let n = &self.nodes[node];
                format!("{}.{}", n.id, n.output_ports[port].name)
            }
            Source::Absent => "(absent)".into(),
        }
    }

    /// The loop body of an iterative node: every node that depends, directly or through
    /// others, on one of its `iterate` outputs (the node itself excluded), ascending.
    pub fn loop_body(&self, node: NodeId) -> BTreeSet<NodeId> {
        let mut body = BTreeSet::new();
        let mut changed = true;
        while changed {
            changed = false;
            for (n, inst) in self.nodes.iter_enumerated() {
                if n == node || body.contains(&n) {
                    continue;
                }
                let reads = inst.inputs.iter().any(|s| match s {
                    Source::Node { node: m, port } => {
                        (*m == node && self.nodes[node].output_ports[*port].iterate)
                            || body.contains(m)
                    }
                    _ => false,
                });
                if reads {
                    body.insert(n);
                    changed = true;
                }
            }
        }
        body
    }

    /// The graph with every read of a forwarded node's output replaced by what it
    /// forwards (`forwards[node]`: the source its output equals), through chains of them.
    /// The forwarded nodes stay, unread, so node indices keep their meaning.
    pub fn forwarding(&self, forwards: &HashMap<NodeId, Source>) -> Graph {
        let resolve = |mut s: Source| {
            while let Source::Node { node, port: 0 } = s {
                match forwards.get(&node) {
                    Some(&to) => s = to,
                    None => break,
                }
            }
            s
        };
        let mut g = self.clone();
        for n in &mut g.nodes {
            for s in &mut n.inputs {
                *s = resolve(*s);
            }
        }
        for st in &mut g.states {
            st.init = resolve(st.init);
            st.next = resolve(st.next);
        }
        for o in &mut g.outputs {
            o.source = resolve(o.source);
        }
        g
    }
}
