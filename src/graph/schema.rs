//! The graph-file format (JSON, schema version 1) as serde types. These types never leave
//! the `graph` module: the loader turns them into a validated [`super::Graph`].

use std::collections::HashSet;
use std::fmt;

use indexmap::IndexMap;
use serde::Deserialize;
use serde::de::{self, DeserializeSeed, MapAccess, SeqAccess, Visitor};

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
    /// A graph-valued param: its value names a graph file (found as a subgraph path is),
    /// which a node uses with `"graph": "$name"`; a parent binds that graph's params
    /// with dotted names, `name.param`.
    #[serde(default)]
    pub graph: bool,
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
    /// `false` or 0 (a literal, `$param` or `= expression`) leaves the node out: it and what
    /// needs it are absent, as if an optional input were not given. A subgraph node's
    /// value applies to every node inside.
    #[serde(default)]
    pub enabled: Option<serde_json::Value>,
    /// For readers of the file; the engine does not use it.
    #[serde(default)]
    #[allow(dead_code)]
    pub doc: String,
}

/// Checks that no object of a JSON text repeats a key, at any depth: serde keeps the
/// last value of a repeated key in maps and `serde_json::Value`s without a word, so a
/// graph file with `"factor": 2, "factor": 3` would silently mean 3. The error names the
/// first repeated key with where it is (`duplicate key `factor` in `nodes[0].params``) and
/// serde_json adds its line and column. A text that is not JSON passes: its syntax error
/// is the parser's to report.
pub fn check_unique_keys(text: &str) -> Result<(), serde_json::Error> {
    let mut de = serde_json::Deserializer::from_str(text);
    let root = UniqueKeys {
        path: String::new(),
    };
    match root.deserialize(&mut de) {
        Err(e) if e.classify() == serde_json::error::Category::Data => Err(e),
        _ => Ok(()),
    }
}

/// A JSON value checked for repeated keys; `path` is where it is in the file (`nodes[0]`).
struct UniqueKeys {
    path: String,
}

impl UniqueKeys {
    fn child(&self, step: &str) -> UniqueKeys {
        let path = if self.path.is_empty() || step.starts_with('[') {
            format!("{}{step}", self.path)
        } else {
            format!("{}.{step}", self.path)
        };
        UniqueKeys { path }
    }
}

impl<'de> DeserializeSeed<'de> for UniqueKeys {
    type Value = ();

    fn deserialize<D: de::Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for UniqueKeys {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("any JSON value")
    }

    fn visit_bool<E>(self, _: bool) -> Result<(), E> {
        Ok(())
    }

    fn visit_i64<E>(self, _: i64) -> Result<(), E> {
        Ok(())
    }

    fn visit_u64<E>(self, _: u64) -> Result<(), E> {
        Ok(())
    }

    fn visit_f64<E>(self, _: f64) -> Result<(), E> {
        Ok(())
    }

    fn visit_str<E>(self, _: &str) -> Result<(), E> {
        Ok(())
    }

    fn visit_unit<E>(self) -> Result<(), E> {
        Ok(())
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let mut i = 0;
        while seq
            .next_element_seed(self.child(&format!("[{i}]")))?
            .is_some()
        {
            i += 1;
        }
        Ok(())
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<(), A::Error> {
        let mut seen = HashSet::new();
        while let Some(key) = map.next_key::<String>()? {
            if !seen.insert(key.clone()) {
                let place = if self.path.is_empty() {
                    "the top level".to_string()
                } else {
                    format!("`{}`", self.path)
                };
                return Err(de::Error::custom(format!(
                    "duplicate key `{key}` in {place} (a key may appear once in an object)"
                )));
            }
            map.next_value_seed(self.child(&key))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::check_unique_keys;

    #[test]
    fn repeated_keys_are_found_at_any_depth_with_their_place() {
        assert!(check_unique_keys(r#"{"a": {"b": [1, {"c": 2}]}, "d": "a"}"#).is_ok());
        let e = check_unique_keys("{\"a\": [{\"b\": 1},\n {\"c\": 2, \"c\": 3}]}").unwrap_err();
        let e = e.to_string();
        assert!(
            e.contains("duplicate key `c` in `a[1]`") && e.contains("line 2"),
            "{e}"
        );
        let e = check_unique_keys(r#"{"a": 1, "a": 1}"#)
            .unwrap_err()
            .to_string();
        assert!(e.contains("duplicate key `a` in the top level"), "{e}");
        // Syntax errors are left to the parser.
        assert!(check_unique_keys(r#"{"a": "#).is_ok());
    }
}
