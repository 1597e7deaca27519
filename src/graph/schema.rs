//! The graph-file format (JSON, schema version 1) as serde types. These types never leave
//! the `graph` module: the loader turns them into a validated [`super::Graph`].

use indexmap::IndexMap;
use serde::Deserialize;

/// The schema version this build reads.
pub const SCHEMA_VERSION: u32 = 1;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GraphFile {
    /// Schema version; must be [`SCHEMA_VERSION`].
    pub mesoflow: u32,
    #[serde(default)]
    pub doc: String,
    #[serde(default)]
    pub params: IndexMap<String, ParamDecl>,
    #[serde(default)]
    pub sizes: IndexMap<String, SizeDecl>,
    #[serde(default)]
    pub inputs: IndexMap<String, InputDecl>,
    #[serde(default)]
    pub state: IndexMap<String, StateDecl>,
    /// Parsed one by one so that every node's problems are reported.
    #[serde(default)]
    pub nodes: Vec<serde_json::Value>,
    #[serde(default)]
    pub outputs: IndexMap<String, OutputDecl>,
}

/// A graph-level param: settable from the command line or by a parent graph.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParamDecl {
    pub default: serde_json::Value,
    #[serde(default)]
    pub doc: String,
    pub min: Option<f64>,
    pub max: Option<f64>,
    #[serde(default)]
    pub integer: bool,
    pub choices: Option<Vec<String>>,
}

/// A named size (a particle count, say) shared by inputs; its default is used when no
/// data fixes it (by `validate` and `inspect`).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SizeDecl {
    pub default: u32,
    #[serde(default)]
    pub doc: String,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InputDecl {
    /// `particles`, `real_grid`, `complex_grid`, `indices` or `scalar`.
    #[serde(rename = "type")]
    pub ty: String,
    /// Particles and indices: a fixed count or the name of a declared size.
    pub rows: Option<serde_json::Value>,
    /// Particles: values per particle.
    pub cols: Option<u32>,
    /// Grids: cells per axis (a param reference allowed).
    pub dims: Option<serde_json::Value>,
    /// Grids: components.
    pub comps: Option<u32>,
    #[serde(default)]
    pub optional: bool,
    #[serde(default)]
    pub doc: String,
}

/// State carried from one time step to the next.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StateDecl {
    /// Where the first step's value comes from (a graph input or a node output that does
    /// not depend on state).
    pub init: String,
    /// The value the state takes for the next step.
    pub next: String,
    #[serde(default)]
    pub doc: String,
}

#[derive(Debug, Deserialize)]
#[serde(untagged)]
pub enum OutputDecl {
    Ref(String),
    Full(OutputFull),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputFull {
    pub from: String,
    #[serde(default)]
    pub doc: String,
}

impl OutputDecl {
    pub fn from(&self) -> &str {
        match self {
            OutputDecl::Ref(s) => s,
            OutputDecl::Full(f) => &f.from,
        }
    }

    pub fn doc(&self) -> &str {
        match self {
            OutputDecl::Ref(_) => "",
            OutputDecl::Full(f) => &f.doc,
        }
    }
}

/// One node: a registered `kind`, or another graph file used as a node (`graph`).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NodeDecl {
    pub id: String,
    pub kind: Option<String>,
    pub graph: Option<String>,
    #[serde(default)]
    pub params: IndexMap<String, serde_json::Value>,
    #[serde(default)]
    pub inputs: IndexMap<String, String>,
    /// For readers of the file; the engine does not use it.
    #[serde(default)]
    #[allow(dead_code)]
    pub doc: String,
}
