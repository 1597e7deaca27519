//! Loading: file -> schema types -> flattened, validated [`Graph`].

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};

use indexmap::IndexMap;

use super::schema::{GraphFile, InputDecl, NodeDecl, ParamDecl, SCHEMA_VERSION};
use super::{
    BuiltNode, Dim, Graph, GraphParam, InputDef, InputShape, NodeId, NodeInst, OutputDef, Problem,
    Problems, SizeDef, Source, StateDef,
};
use crate::expr::fmt_number;
use crate::expr::{self, ExprError, Origin, ParamValue, Scope};
use crate::ids::Id;
use crate::node::{Registry, check_param_names, check_params, edit_distance, nearest};
use crate::value::ValueType;

/// Names every graph sees without declaring them.
pub const BUILTIN_PARAMS: [&str; 2] = ["steps", "seed"];

/// What the caller fixes before loading.
#[derive(Clone, Debug)]
pub struct LoadOptions {
    /// Values for the top-level graph params (`--set`).
    pub overrides: BTreeMap<String, ParamValue>,
    /// Number of time steps the run will take (the built-in param `steps`).
    pub steps: u64,
    /// The run's random seed (the built-in param `seed`).
    pub seed: u64,
}

impl Default for LoadOptions {
    fn default() -> Self {
        LoadOptions {
            overrides: BTreeMap::new(),
            steps: 1,
            seed: 0,
        }
    }
}

/// Loads a graph file and everything it uses, reporting all problems together.
pub fn load(path: &Path, registry: &Registry, opts: &LoadOptions) -> Result<Graph, Problems> {
    load_from(path, None, registry, opts)
}

/// Loads a graph given as text (one a scene built), as if it were the file `path`: its
/// subgraphs are found from `path`'s folder and the library, and problems name `path`.
pub fn load_text(
    path: &Path,
    text: &str,
    registry: &Registry,
    opts: &LoadOptions,
) -> Result<Graph, Problems> {
    load_from(path, Some(text.to_string()), registry, opts)
}

fn load_from(
    path: &Path,
    text: Option<String>,
    registry: &Registry,
    opts: &LoadOptions,
) -> Result<Graph, Problems> {
    let mut builtins = Scope::new(registry.functions());
    builtins.insert("steps".into(), ParamValue::Number(opts.steps as f64));
    builtins.insert("seed".into(), ParamValue::Number(opts.seed as f64));
    let mut l = Loader {
        registry,
        builtins,
        problems: Vec::new(),
        pending_nodes: Vec::new(),
        disabled_scopes: Vec::new(),
        node_ids: HashMap::new(),
        input_alias: HashMap::new(),
        sub_outputs: HashMap::new(),
        stack: Vec::new(),
        expanded_nodes: 0,
        folders: SubgraphFolders::new(path),
        root: RootParts::default(),
        param_roots: HashMap::new(),
        consequences: BTreeMap::new(),
        graph_params: HashMap::new(),
        root_text: text,
    };
    let overrides: IndexMap<String, ParamValue> = opts.overrides.clone().into_iter().collect();
    l.load_file(path, "", &overrides, None);
    l.finish(path)
}

/// An unresolved `node.port` reference and where it was written.
#[derive(Clone, Debug)]
struct PendingRef {
    scope: String,
    text: String,
    file: PathBuf,
    node: Option<String>,
    port: Option<String>,
    /// Says where the reference was written when it is not a node's input port
    /// (an output or a state).
    place: String,
}

impl PendingRef {
    fn problem(&self, message: String) -> Problem {
        Problem {
            file: self.file.clone(),
            node: self.node.clone(),
            port: self.port.clone(),
            message: format!("{}{message}", self.place),
        }
    }
}

enum Alias {
    Root(usize),
    Parent(PendingRef),
    Absent,
}

enum NodeEntry {
    Kind(usize),
    Sub(String),
    /// A node whose own problems are already reported; references to it add none.
    Failed,
}

struct PendingNode {
    inst: NodeInst,
    refs: Vec<Option<PendingRef>>,
}

#[derive(Default)]
struct RootParts {
    doc: String,
    params: Vec<GraphParam>,
    sizes: Vec<SizeDef>,
    inputs: Vec<InputDef>,
    states: Vec<(String, PendingRef, PendingRef, String)>,
    outputs: Vec<(String, PendingRef, String)>,
}

/// How a subgraph is connected by its parent.
struct Binding<'a> {
    file: &'a Path,
    node: &'a str,
    scope: &'a str,
    inputs: &'a IndexMap<String, String>,
    /// Where each param the node sets comes from, in the parent's scope.
    param_origins: &'a BTreeMap<String, Origin>,
    /// The params a graph param's bindings set (`radius` from `mobility.radius`), with
    /// where they were written.
    bound: &'a BTreeMap<String, String>,
    /// Inputs bound through graph params, as references in the scope that wrote them:
    /// those of the graph param the node uses, and dotted ones (`forces.charges`) that
    /// a forwarded graph param carries.
    bound_inputs: &'a IndexMap<String, PendingRef>,
}

/// A kind node's param values as its file gives them, resolved in the node's scope.
struct NodeParamValues {
    values: BTreeMap<String, ParamValue>,
    /// Values a host function refused (a planner outside its domain), for the planner to
    /// report where the node runs.
    value_problems: Vec<String>,
    /// Where each value comes from (the top-level params it is computed from).
    origins: BTreeMap<String, Origin>,
}

struct Loader<'r> {
    registry: &'r Registry,
    builtins: Scope<'r>,
    problems: Vec<Problem>,
    pending_nodes: Vec<PendingNode>,
    /// Subgraph scopes (`parent/`) whose node is disabled, with why: every node loaded
    /// inside is disabled too.
    disabled_scopes: Vec<(String, String)>,
    node_ids: HashMap<(String, String), NodeEntry>,
    input_alias: HashMap<(String, String), Alias>,
    sub_outputs: HashMap<(String, String), PendingRef>,
    stack: Vec<PathBuf>,
    /// Nodes declared by every file loaded so far, subgraph nodes included: past
    /// [`MAX_EXPANDED_NODES`] loading stops (`load_file` refuses every further file).
    expanded_nodes: usize,
    folders: SubgraphFolders,
    root: RootParts,
    /// Params left without a value, by (file scope, name): the problem (an index into
    /// `problems`) that leaves them so, their own or that of a param they read.
    param_roots: HashMap<(String, String), usize>,
    /// What each such problem leaves unresolved (params, nodes, inputs), reported with
    /// it once rather than as a problem each.
    consequences: BTreeMap<usize, Vec<(&'static str, String)>>,
    /// Graph-valued params by (file scope, name): the file each names and the params
    /// its parent bound for it (`mobility.radius` given as `radius`).
    graph_params: HashMap<(String, String), GraphParamValue>,
    /// The top-level graph's text where it was given rather than read (`load_text`).
    root_text: Option<String>,
}

/// The file a subgraph node uses, with what graph params bind for it.
struct SubgraphFile {
    file: PathBuf,
    params: IndexMap<String, ParamValue>,
    /// Where each bound param was bound, for messages.
    params_at: BTreeMap<String, String>,
    inputs: IndexMap<String, PendingRef>,
}

/// The value of a graph-valued param: the file it names and the params bound for it.
#[derive(Clone, Debug)]
struct GraphParamValue {
    file: PathBuf,
    bound: IndexMap<String, ParamValue>,
    /// The inputs bound for it (`forces.charges`: input `charges` of every node using
    /// it), as references in the scope that wrote them.
    bound_inputs: IndexMap<String, PendingRef>,
    /// Where the bindings were written, for messages.
    bound_at: String,
}

/// The largest graph file read (a graph of the 20,000 nodes [`MAX_EXPANDED_NODES`]
/// allows takes a few MiB).
pub const MAX_GRAPH_FILE_BYTES: u64 = 64 << 20;

/// Where subgraph files may come from: the top-level graph's folder and the library
/// (`MESOFLOW_GRAPH_LIB`, a list of folders as PATH is; by default the `graphs/` folder
/// mesoflow ships, which holds `lib/`), each with what lies below it. A subgraph path
/// is relative; it is looked up from the including file's folder, then from each library
/// folder, and must lead (`..` and symbolic links followed) to a regular file inside one
/// of them: no absolute paths, no escapes, no FIFOs or devices.
struct SubgraphFolders {
    /// Canonical folders a subgraph file must lie in.
    allowed: Vec<PathBuf>,
    /// The library folders, where a path not found beside the including file is looked up.
    library: Vec<PathBuf>,
}

impl SubgraphFolders {
    fn new(top: &Path) -> Self {
        let library: Vec<PathBuf> = super::library::library_folders()
            .iter()
            .filter_map(|d| d.canonicalize().ok())
            .collect();
        let top_folder = match top.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let allowed = top_folder
            .canonicalize()
            .into_iter()
            .chain(library.iter().cloned())
            .collect();
        SubgraphFolders { allowed, library }
    }

    fn describe(&self) -> String {
        let folders: Vec<String> = self
            .allowed
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        folders.join(", ")
    }

    /// An absolute path a graph-valued param carries from its parent: accepted where it
    /// leads inside the folders subgraphs may come from.
    fn resolve_canonical(&self, text: &str) -> Result<PathBuf, String> {
        let found = Path::new(text)
            .canonicalize()
            .map_err(|e| format!("cannot read graph file {text}: {e}"))?;
        if self.allowed.iter().any(|f| found.starts_with(f)) {
            Ok(found)
        } else {
            Err(format!(
                "{} lies outside the folders subgraphs may come from ({})",
                found.display(),
                self.describe()
            ))
        }
    }

    /// The file a subgraph node's `graph` path names, included from `including`.
    fn resolve(&self, including: &Path, sub: &str) -> Result<PathBuf, String> {
        let rel = Path::new(sub);
        if rel.has_root() || rel.is_absolute() {
            return Err(format!(
                "subgraph path `{sub}` is absolute; give it relative to the graph's folder or to a library folder ({})",
                self.describe()
            ));
        }
        let here = including.parent().unwrap_or(Path::new("."));
        for base in std::iter::once(here).chain(self.library.iter().map(PathBuf::as_path)) {
            let Ok(found) = base.join(rel).canonicalize() else {
                continue;
            };
            if !self.allowed.iter().any(|f| found.starts_with(f)) {
                return Err(format!(
                    "subgraph path `{sub}` leads to {}, outside the folders subgraphs may come from ({})",
                    found.display(),
                    self.describe()
                ));
            }
            return Ok(found);
        }
        Err(format!(
            "cannot read subgraph file {}: no such file (nor in the library: {})",
            here.join(rel).display(),
            self.describe()
        ))
    }
}

/// How deeply subgraphs may include subgraphs: each level is a recursion of the loader,
/// and a chain of 20,000 files overflowed its stack; 32 levels leave room for the
/// expressions evaluated at the deepest one on a 2 MiB thread.
pub const MAX_SUBGRAPH_DEPTH: usize = 32;

/// How many nodes a graph may expand to, subgraph nodes and every copy of a subgraph
/// counted: 23 small files that each use the next twice expand to 2^22 graphs, so the
/// depth bound alone does not bound the memory and time of loading.
pub const MAX_EXPANDED_NODES: usize = 20_000;

fn valid_id(id: &str) -> bool {
    let mut c = id.chars();
    matches!(c.next(), Some(ch) if ch.is_ascii_alphabetic() || ch == '_')
        && c.all(|ch| ch.is_ascii_alphanumeric() || ch == '_')
}

impl<'r> Loader<'r> {
    /// Loads one file into the scope `scope` ("" for the top level, "a/b/" inside
    /// subgraphs). `overrides` are param values from the command line or the parent.
    /// Returns false when the file could not be read or parsed at all.
    fn load_file(
        &mut self,
        path: &Path,
        scope: &str,
        overrides: &IndexMap<String, ParamValue>,
        parent: Option<Binding>,
    ) -> bool {
        let is_root = parent.is_none();
        let problem_here = |msg: String| match &parent {
            Some(b) => Problem::node(b.file, b.node, msg),
            None => Problem::file(path, msg),
        };
        if self.expanded_nodes > MAX_EXPANDED_NODES {
            return false; // Reported once, where the budget ran out.
        }
        if self.stack.len() >= MAX_SUBGRAPH_DEPTH {
            self.problems.push(problem_here(format!(
                "subgraphs nest deeper than {MAX_SUBGRAPH_DEPTH} levels (MAX_SUBGRAPH_DEPTH), from {} to {}",
                self.stack[0].display(),
                path.display()
            )));
            return false;
        }
        let canonical = path.canonicalize().unwrap_or_else(|_| path.to_path_buf());
        if self.stack.contains(&canonical) {
            let chain: Vec<String> = self.stack.iter().map(|p| p.display().to_string()).collect();
            self.problems.push(problem_here(format!(
                "subgraph cycle: {} -> {}",
                chain.join(" -> "),
                canonical.display()
            )));
            return false;
        }
        let given = if is_root { self.root_text.take() } else { None };
        // Only regular files of a bounded size: a FIFO or /dev/zero would block or never end.
        match std::fs::metadata(path) {
            _ if given.is_some() => {}
            Ok(m) if !m.is_file() => {
                self.problems.push(problem_here(format!(
                    "{} is not a regular file",
                    path.display()
                )));
                return false;
            }
            Ok(m) if m.len() > MAX_GRAPH_FILE_BYTES => {
                self.problems.push(problem_here(format!(
                    "{} takes {} bytes, more than the {MAX_GRAPH_FILE_BYTES} (MAX_GRAPH_FILE_BYTES) a graph file may",
                    path.display(),
                    m.len()
                )));
                return false;
            }
            _ => {}
        }
        let text = match given.map_or_else(|| std::fs::read_to_string(path), Ok) {
            Ok(t) => t,
            Err(e) => {
                let what = if is_root {
                    "cannot read graph file"
                } else {
                    "cannot read subgraph file"
                };
                self.problems
                    .push(problem_here(format!("{what} {}: {e}", path.display())));
                return false;
            }
        };
        if let Err(e) = super::schema::check_unique_keys(&text) {
            self.problems.push(Problem::file(path, e.to_string()));
            return false;
        }
        let file: GraphFile = match serde_json::from_str(&text) {
            Ok(f) => f,
            Err(e) => {
                self.problems.push(Problem::file(path, e.to_string()));
                return false;
            }
        };
        if file.mesoflow != SCHEMA_VERSION {
            self.problems.push(Problem::file(
                path,
                format!(
                    "schema version {} is not supported (this mesoflow reads version {SCHEMA_VERSION}; set \"mesoflow\": {SCHEMA_VERSION})",
                    file.mesoflow
                ),
            ));
            return false;
        }
        self.expanded_nodes += file.nodes.len();
        if self.expanded_nodes > MAX_EXPANDED_NODES {
            self.problems.push(problem_here(format!(
                "the graph expands to more than {MAX_EXPANDED_NODES} nodes (MAX_EXPANDED_NODES), subgraphs and every use of one counted; reached loading {}",
                path.display()
            )));
            return false;
        }
        self.stack.push(canonical);

        let scope_values = self.params(path, scope, &file.params, overrides, &parent);
        let size_names = self.sizes(path, &file, is_root);
        self.inputs(
            path,
            scope,
            &file.inputs,
            &size_names,
            &scope_values,
            &parent,
        );
        if is_root {
            self.root.doc = file.doc.clone();
        }
        self.nodes(path, scope, &file.nodes, &scope_values);
        if is_root && file.outputs.is_empty() {
            self.problems.push(Problem::file(
                path,
                "the graph declares no outputs, so running it would compute nothing (name what it gives under \"outputs\")",
            ));
        }
        for (name, decl) in &file.outputs {
            let r = PendingRef {
                scope: scope.into(),
                text: decl.from().into(),
                file: path.into(),
                node: None,
                port: None,
                place: format!("output `{name}`: "),
            };
            if is_root {
                self.root.outputs.push((name.clone(), r, decl.doc().into()));
            } else {
                self.sub_outputs.insert((scope.into(), name.clone()), r);
            }
        }
        // States of a subgraph belong to its instance: named by its scope (`step/x` for
        // state `x` of the node `step`), their references resolved in it, so a parent may
        // use one stateful subgraph several times, each with state of its own.
        for (name, s) in &file.state {
            let full = format!("{scope}{name}");
            let mk = |text: &str, what: &str| PendingRef {
                scope: scope.into(),
                text: text.into(),
                file: path.into(),
                node: None,
                port: None,
                place: format!("state `{full}`, {what}: "),
            };
            self.root.states.push((
                full.clone(),
                mk(&s.init, "init"),
                mk(&s.next, "next"),
                s.doc.clone(),
            ));
        }
        self.stack.pop();
        true
    }

    /// Resolves graph params: defaults in order (a default may be an expression over the
    /// params above it), then overrides. Returns the expression scope of the file. A
    /// param with a problem (a bad value, a default that does not evaluate) is left
    /// without a value: what is computed from it follows from that problem
    /// ([`Loader::follows`]) instead of being one more.
    fn params(
        &mut self,
        path: &Path,
        file_scope: &str,
        decls: &IndexMap<String, ParamDecl>,
        overrides: &IndexMap<String, ParamValue>,
        parent: &Option<Binding>,
    ) -> Scope<'r> {
        let mut scope = self.builtins.clone();
        let is_root = parent.is_none();
        // Dotted names bind params of the graph a graph-valued param names.
        let mut bound: IndexMap<String, IndexMap<String, ParamValue>> = IndexMap::new();
        for (name, v) in overrides {
            let Some((head, rest)) = name.split_once('.') else {
                continue;
            };
            if decls.get(head).is_some_and(|d| d.graph) && !rest.is_empty() {
                bound
                    .entry(head.to_string())
                    .or_default()
                    .insert(rest.to_string(), v.clone());
                continue;
            }
            let graph_params: Vec<&str> = decls
                .iter()
                .filter(|(_, d)| d.graph)
                .map(|(n, _)| n.as_str())
                .collect();
            let msg = format!(
                "`{name}` binds param `{rest}` of graph param `{head}`, but this graph has no graph param `{head}` (its graph params: {})",
                if graph_params.is_empty() {
                    "none".to_string()
                } else {
                    graph_params.join(", ")
                }
            );
            self.problems.push(match parent {
                Some(b) => Problem::port(b.file, b.node, name, msg),
                None => Problem::file(path, msg),
            });
        }
        for name in overrides.keys() {
            if name.contains('.') {
                continue;
            }
            if !(decls.contains_key(name) || is_root && BUILTIN_PARAMS.contains(&name.as_str())) {
                let known: Vec<&str> = decls.keys().map(|s| s.as_str()).collect();
                let hint = nearest(name, known.iter().copied())
                    .map(|n| format!(" (did you mean `{n}`?)"))
                    .unwrap_or_default();
                let msg = format!(
                    "unknown param `{name}`{hint} (this graph's params: {})",
                    if known.is_empty() {
                        "none".to_string()
                    } else {
                        known.join(", ")
                    }
                );
                let msg = match parent.as_ref().and_then(|b| b.bound.get(name)) {
                    Some(at) => format!("{msg}; bound as {at}"),
                    None => msg,
                };
                self.problems.push(match parent {
                    Some(b) => Problem::port(b.file, b.node, name, msg),
                    None => Problem::file(path, msg),
                });
            }
        }
        for (name, decl) in decls {
            if BUILTIN_PARAMS.contains(&name.as_str()) {
                self.problems.push(Problem::file(
                    path,
                    format!("param `{name}` is built in (set it with --{name}); do not declare it"),
                ));
                continue;
            }
            if !valid_id(name) {
                self.problems.push(Problem::file(
                    path,
                    format!("param name `{name}` is not a valid identifier"),
                ));
                continue;
            }
            match self.param_value(
                path,
                file_scope,
                name,
                decl,
                &scope,
                overrides.get(name),
                parent,
            ) {
                Ok((default, value)) => {
                    let value = if decl.graph {
                        let given = overrides.contains_key(name);
                        match self.graph_param(path, name, &value, given, parent) {
                            Ok(file) => {
                                let canonical = ParamValue::Text(file.display().to_string());
                                self.graph_params.insert(
                                    (file_scope.to_string(), name.clone()),
                                    GraphParamValue {
                                        file,
                                        bound: bound.shift_remove(name).unwrap_or_default(),
                                        bound_inputs: IndexMap::new(),
                                        bound_at: match parent {
                                            Some(b) => {
                                                format!("node `{}` of {}", b.node, b.file.display())
                                            }
                                            None => format!("the settings of {}", path.display()),
                                        },
                                    },
                                );
                                canonical
                            }
                            Err(root) => {
                                self.param_roots
                                    .insert((file_scope.to_string(), name.clone()), root);
                                scope.insert_unresolved(name.clone());
                                continue;
                            }
                        }
                    } else {
                        value
                    };
                    let origin = self.param_origin(name, decl, &scope, &value, overrides, parent);
                    if is_root {
                        self.root.params.push(GraphParam {
                            name: name.clone(),
                            value: value.clone(),
                            default,
                            doc: decl.doc.clone(),
                            constraint: describe_constraint(decl),
                        });
                    }
                    scope.insert_with_origin(name.clone(), value, origin);
                }
                Err(root) => {
                    if let Some(root) = root {
                        self.param_roots
                            .insert((file_scope.to_string(), name.clone()), root);
                    }
                    scope.insert_unresolved(name.clone());
                }
            }
        }
        if is_root {
            if let Some(v) = overrides.get("seed") {
                match v {
                    ParamValue::Number(x) if *x >= 0.0 && x.fract() == 0.0 && *x < 9.007e15 => {
                        scope.insert("seed".into(), v.clone());
                    }
                    _ => self.problems.push(Problem::file(
                        path,
                        format!("bad value {v} for param `seed`: expected a non-negative integer"),
                    )),
                }
            }
            if overrides.contains_key("steps") {
                self.problems.push(Problem::file(
                    path,
                    "set the number of steps with --steps, not --set steps",
                ));
            }
        }
        scope
    }

    /// A graph param's default and value (the override when given), or the problem that
    /// leaves it without one: an index into `self.problems`, `None` for none of its own
    /// (the param it reads has the problem).
    #[allow(clippy::too_many_arguments)]
    fn param_value(
        &mut self,
        path: &Path,
        file_scope: &str,
        name: &str,
        decl: &ParamDecl,
        scope: &Scope,
        given: Option<&ParamValue>,
        parent: &Option<Binding>,
    ) -> Result<(ParamValue, ParamValue), Option<usize>> {
        let default = match expr::resolve(&decl.default, scope) {
            Ok(v) => v,
            Err(ExprError::Unresolved { name: from }) => {
                self.follows(file_scope, &from, ("param", format!("{file_scope}{name}")));
                return Err(self.root_of(file_scope, &from));
            }
            // A planner refusing the values its default computes from does not matter
            // where the param is set: setting it is how a user gets past such a refusal
            // (`support` where `fcm_support` finds none). The value given is checked
            // against the declared range on its own, and stands in for the default.
            Err(e) if e.depends_on_values() && given.is_some() => given.unwrap().clone(),
            // Inside a subgraph the file leaves out (`enabled` false), a planner refusing
            // the values is no problem: nothing there runs. What reads the param reads
            // as absent, as the disabled nodes do (a scene without charges in a box too
            // small for the electrostatics' planner loads).
            Err(e)
                if e.depends_on_values()
                    && self
                        .disabled_scopes
                        .iter()
                        .any(|(prefix, _)| file_scope.starts_with(prefix.as_str())) =>
            {
                return Err(None);
            }
            Err(e) => {
                let msg = scope
                    .origin_of(&decl.default)
                    .explain(format!("param `{name}`: default: {e}"));
                return Err(Some(self.push(Problem::file(path, msg))));
            }
        };
        if let Err(e) = check_param(decl, &default, &default) {
            let msg = scope
                .origin_of(&decl.default)
                .explain(format!("param `{name}`: default {default}: {e}"));
            return Err(Some(self.push(Problem::file(path, msg))));
        }
        let Some(v) = given else {
            return Ok((default.clone(), default));
        };
        if let Err(e) = check_param(decl, &default, v) {
            let msg = format!("bad value {v} for param `{name}`: {e}");
            return Err(Some(
                self.push(match parent {
                    Some(b) => Problem::port(
                        b.file,
                        b.node,
                        name,
                        b.param_origins
                            .get(name)
                            .map_or(msg.clone(), |o| o.explain(msg)),
                    ),
                    None => Problem::file(path, msg),
                }),
            ));
        }
        Ok((default, v.clone()))
    }

    /// Where graph param `name` takes its value from: at the top level, the param itself
    /// when set or a literal default, else what its default expression reads; in a
    /// subgraph, the origin of the parent's value, else what its default reads.
    fn param_origin(
        &self,
        name: &str,
        decl: &ParamDecl,
        scope: &Scope,
        value: &ParamValue,
        overrides: &IndexMap<String, ParamValue>,
        parent: &Option<Binding>,
    ) -> Origin {
        let given = overrides.contains_key(name);
        match parent {
            None if given => Origin::param(name, value, true),
            None => {
                let read = scope.origin_of(&decl.default);
                if read.sources.is_empty() {
                    Origin::param(name, value, false)
                } else {
                    read
                }
            }
            Some(b) if given => b.param_origins.get(name).cloned().unwrap_or_default(),
            Some(_) => scope.origin_of(&decl.default),
        }
    }

    /// The file a graph-valued param names: a text found as a subgraph path is, from the
    /// folder of the file that wrote it (the parent's when the parent sets it) and then
    /// the library. A value forwarded from a parent's graph param arrives as that param's
    /// canonical path, accepted where a subgraph may come from.
    fn graph_param(
        &mut self,
        path: &Path,
        name: &str,
        value: &ParamValue,
        given: bool,
        parent: &Option<Binding>,
    ) -> Result<PathBuf, usize> {
        let place = |msg: String| match (parent, given) {
            (Some(b), true) => Problem::port(b.file, b.node, name, msg),
            _ => Problem::file(path, msg),
        };
        let ParamValue::Text(text) = value else {
            let msg = format!("graph param `{name}` must name a graph file, got {value}");
            return Err(self.push(place(msg)));
        };
        let written_in = match parent {
            Some(b) if given => b.file,
            _ => path,
        };
        let found = if Path::new(text).is_absolute() {
            self.folders.resolve_canonical(text)
        } else {
            self.folders.resolve(written_in, text)
        };
        found.map_err(|e| self.push(place(format!("graph param `{name}`: {e}"))))
    }

    /// Adds a problem; returns its index.
    fn push(&mut self, p: Problem) -> usize {
        self.problems.push(p);
        self.problems.len() - 1
    }

    /// The problem that leaves param `name` of the file loaded as `file_scope` without a
    /// value.
    fn root_of(&self, file_scope: &str, name: &str) -> Option<usize> {
        self.param_roots
            .get(&(file_scope.to_string(), name.to_string()))
            .copied()
    }

    /// Records `what` (a `param`, `node` or `input`, by its full name) as following from
    /// the problem of param `name` (which has no value): reported once, with that problem.
    fn follows(&mut self, file_scope: &str, name: &str, what: (&'static str, String)) {
        if let Some(root) = self.root_of(file_scope, name) {
            let list = self.consequences.entry(root).or_default();
            if !list.contains(&what) {
                list.push(what);
            }
        }
    }

    fn sizes(&mut self, path: &Path, file: &GraphFile, is_root: bool) -> Vec<String> {
        let mut names = Vec::new();
        for (name, decl) in &file.sizes {
            if !valid_id(name) {
                self.problems.push(Problem::file(
                    path,
                    format!("size name `{name}` is not a valid identifier"),
                ));
                continue;
            }
            names.push(name.clone());
            if is_root {
                self.root.sizes.push(SizeDef {
                    name: name.clone(),
                    default: decl.default,
                    doc: decl.doc.clone(),
                });
            }
        }
        names
    }

    fn inputs(
        &mut self,
        path: &Path,
        scope: &str,
        decls: &IndexMap<String, InputDecl>,
        size_names: &[String],
        values: &Scope,
        parent: &Option<Binding>,
    ) {
        if let Some(b) = parent {
            // Dotted inputs bind inputs of the graph a graph param names.
            let dotted = b
                .inputs
                .iter()
                .filter(|(n, _)| n.contains('.'))
                .map(|(n, text)| {
                    let r = PendingRef {
                        scope: b.scope.into(),
                        text: text.clone(),
                        file: b.file.into(),
                        node: Some(b.node.into()),
                        port: Some(n.clone()),
                        place: String::new(),
                    };
                    (n.clone(), r)
                })
                .chain(
                    b.bound_inputs
                        .iter()
                        .filter(|(n, _)| n.contains('.'))
                        .map(|(n, r)| (n.clone(), r.clone())),
                );
            for (name, r) in dotted.collect::<Vec<_>>() {
                let (head, rest) = name.split_once('.').expect("dotted");
                let unresolved = self.root_of(scope, head).is_some();
                match self
                    .graph_params
                    .get_mut(&(scope.to_string(), head.to_string()))
                {
                    Some(g) => {
                        g.bound_inputs.insert(rest.to_string(), r);
                    }
                    None if unresolved => {}
                    None => self.problems.push(Problem::port(
                        b.file,
                        b.node,
                        &name,
                        format!(
                            "`{name}` binds input `{rest}` of graph param `{head}`, but subgraph {} has no graph param `{head}`",
                            path.display()
                        ),
                    )),
                }
            }
            for name in b.inputs.keys().filter(|n| !n.contains('.')) {
                if !decls.contains_key(name) {
                    let known: Vec<&str> = decls.keys().map(|s| s.as_str()).collect();
                    self.problems.push(Problem::port(
                        b.file,
                        b.node,
                        name,
                        format!(
                            "subgraph {} has no input `{name}` (inputs: {})",
                            path.display(),
                            known.join(", ")
                        ),
                    ));
                }
            }
        }
        for (name, decl) in decls {
            let key = (scope.to_string(), name.clone());
            // Counts read from a param without a value follow from that param's problem.
            let unresolved = [&decl.rows, &decl.dims]
                .into_iter()
                .flatten()
                .find_map(|v| match expr::resolve(v, values) {
                    Err(ExprError::Unresolved { name }) => Some(name),
                    _ => None,
                });
            let shape = match unresolved {
                Some(from) => {
                    self.follows(scope, &from, ("input", format!("{scope}{name}")));
                    None
                }
                None => match input_shape(decl, size_names, values) {
                    Ok(shape) => Some(shape),
                    Err(e) => {
                        self.problems
                            .push(Problem::node(path, &format!("inputs.{name}"), e));
                        None
                    }
                },
            };
            let Some(shape) = shape else {
                // Reported; what reads it adds no problem of its own.
                self.input_alias.insert(key, Alias::Absent);
                continue;
            };
            match parent {
                None => {
                    self.input_alias
                        .insert(key, Alias::Root(self.root.inputs.len()));
                    self.root.inputs.push(InputDef {
                        name: name.clone(),
                        shape,
                        optional: decl.optional,
                        doc: decl.doc.clone(),
                    });
                }
                Some(b) => match b.inputs.get(name) {
                    Some(text) => {
                        if b.bound_inputs.contains_key(name) {
                            self.problems.push(Problem::port(
                                b.file,
                                b.node,
                                name,
                                "input is connected here and bound by the parent through a graph param: connect it in one place",
                            ));
                        }
                        let r = PendingRef {
                            scope: b.scope.into(),
                            text: text.clone(),
                            file: b.file.into(),
                            node: Some(b.node.into()),
                            port: Some(name.clone()),
                            place: String::new(),
                        };
                        self.input_alias.insert(key, Alias::Parent(r));
                    }
                    None if b.bound_inputs.contains_key(name) => {
                        let r = b.bound_inputs[name].clone();
                        self.input_alias.insert(key, Alias::Parent(r));
                    }
                    None if decl.optional => {
                        self.input_alias.insert(key, Alias::Absent);
                    }
                    None => {
                        // Reported once here; inside the subgraph it reads as absent.
                        self.input_alias.insert(key, Alias::Absent);
                        self.problems.push(Problem::port(
                            b.file,
                            b.node,
                            name,
                            format!(
                                "input is not connected (subgraph {} requires it)",
                                path.display()
                            ),
                        ))
                    }
                },
            }
        }
    }

    fn nodes(&mut self, path: &Path, scope: &str, decls: &[serde_json::Value], values: &Scope) {
        for (i, raw) in decls.iter().enumerate() {
            let decl: NodeDecl = match serde_json::from_value(raw.clone()) {
                Ok(d) => d,
                Err(e) => {
                    let id = raw
                        .get("id")
                        .and_then(|v| v.as_str())
                        .map(String::from)
                        .unwrap_or(format!("#{}", i + 1));
                    self.problems.push(Problem::node(path, &id, e.to_string()));
                    continue;
                }
            };
            let id = decl.id.as_str();
            if !valid_id(id) || id == "inputs" || id == "state" || id == "outputs" {
                self.problems.push(Problem::node(
                    path,
                    id,
                    "invalid node id (letters, digits and _, not starting with a digit; `inputs`, `state` and `outputs` are reserved)",
                ));
                continue;
            }
            let key = (scope.to_string(), id.to_string());
            if self.node_ids.contains_key(&key) {
                self.problems
                    .push(Problem::node(path, id, "duplicate node id"));
                continue;
            }
            // Param values: literals, `$name` references or `= expressions`. A value a
            // host function refuses for these params (a planner's domain) is a problem of
            // the value, like one out of range: a kind node keeps it for the planner to
            // report where the node runs. Anything else wrong with an expression is wrong
            // with the file.
            let mut raw_params = BTreeMap::new();
            let mut value_problems = Vec::new();
            let param_origins: BTreeMap<String, Origin> = decl
                .params
                .iter()
                .map(|(pname, v)| (pname.clone(), values.origin_of(v)))
                .collect();
            let mut bad = false;
            for (pname, v) in &decl.params {
                match expr::resolve(v, values) {
                    Ok(pv) => {
                        raw_params.insert(pname.clone(), pv);
                    }
                    Err(ExprError::Unresolved { name }) => {
                        bad = true;
                        self.follows(scope, &name, ("node", format!("{scope}{id}")));
                    }
                    Err(e) if decl.kind.is_some() && e.depends_on_values() => {
                        value_problems
                            .push(param_origins[pname].explain(format!("param `{pname}`: {e}")));
                    }
                    Err(e) => {
                        bad = true;
                        self.problems.push(Problem::node(
                            path,
                            id,
                            param_origins[pname].explain(format!("param `{pname}`: {e}")),
                        ));
                    }
                }
            }
            let disabled = match &decl.enabled {
                None => None,
                Some(v) => match expr::resolve(v, values) {
                    // A number reads as a flag, as the nodes' own `enabled` params do: a
                    // graph writes `"enabled": "$split"` for "where there is a split".
                    Ok(ParamValue::Bool(true)) => None,
                    Ok(ParamValue::Number(x)) if x != 0.0 && !x.is_nan() => None,
                    Ok(off @ (ParamValue::Bool(false) | ParamValue::Number(_))) => {
                        Some(values.origin_of(v).explain(format!("`enabled` is {off}")))
                    }
                    Ok(other) => {
                        bad = true;
                        self.problems.push(Problem::node(
                            path,
                            id,
                            values
                                .origin_of(v)
                                .explain(format!("`enabled` must be true or false, got {other}")),
                        ));
                        None
                    }
                    Err(ExprError::Unresolved { name }) => {
                        bad = true;
                        self.follows(scope, &name, ("node", format!("{scope}{id}")));
                        None
                    }
                    Err(e) => {
                        bad = true;
                        self.problems.push(Problem::node(
                            path,
                            id,
                            values.origin_of(v).explain(format!("`enabled`: {e}")),
                        ));
                        None
                    }
                },
            }
            .or_else(|| {
                self.disabled_scopes
                    .iter()
                    .find(|(prefix, _)| scope.starts_with(prefix.as_str()))
                    .map(|(prefix, why)| {
                        format!(
                            "its subgraph node `{}` is disabled: {why}",
                            prefix.trim_end_matches('/')
                        )
                    })
            });
            match (&decl.kind, &decl.graph) {
                (Some(kind), None) => {
                    let built = !bad
                        && self.kind_node(
                            path,
                            scope,
                            &decl,
                            kind,
                            NodeParamValues {
                                values: raw_params,
                                value_problems,
                                origins: param_origins,
                            },
                            disabled,
                        );
                    if !built {
                        self.node_ids.insert(key, NodeEntry::Failed);
                    }
                }
                (None, Some(sub)) => {
                    let child_scope = format!("{scope}{id}/");
                    if let Some(why) = disabled {
                        self.disabled_scopes.push((child_scope.clone(), why));
                    }
                    let child = if bad {
                        None
                    } else {
                        self.subgraph_file(path, scope, id, sub, &decl, &raw_params)
                    };
                    let loaded = match child {
                        None => false,
                        Some(SubgraphFile {
                            file: child_path,
                            params: bound,
                            params_at: bound_at,
                            inputs: bound_inputs,
                        }) => {
                            let mut overrides: IndexMap<String, ParamValue> =
                                raw_params.into_iter().collect();
                            overrides.extend(bound);
                            let binding = Binding {
                                file: path,
                                node: id,
                                scope,
                                inputs: &decl.inputs,
                                param_origins: &param_origins,
                                bound: &bound_at,
                                bound_inputs: &bound_inputs,
                            };
                            self.load_file(&child_path, &child_scope, &overrides, Some(binding))
                        }
                    };
                    let entry = if loaded {
                        NodeEntry::Sub(child_scope)
                    } else {
                        NodeEntry::Failed
                    };
                    self.node_ids.insert(key, entry);
                }
                (Some(_), Some(_)) => {
                    self.node_ids.insert(key, NodeEntry::Failed);
                    self.problems.push(Problem::node(
                        path,
                        id,
                        "give either `kind` or `graph`, not both",
                    ))
                }
                (None, None) => {
                    self.node_ids.insert(key, NodeEntry::Failed);
                    self.problems.push(Problem::node(
                        path,
                        id,
                        "missing `kind` (a node kind; `mesoflow nodes` lists them) or `graph` (a graph file used as a node)",
                    ))
                }
            }
        }
    }

    /// The file a subgraph node uses and the params bound for it by graph params: a
    /// path, or `$name` for the file graph param `name` names, with the params the
    /// parent bound for it; and for each of the node's params that forwards a graph
    /// param (`"mobility": "$mobility"`), that param's bindings under the child's name.
    fn subgraph_file(
        &mut self,
        path: &Path,
        scope: &str,
        id: &str,
        sub: &str,
        decl: &NodeDecl,
        own: &BTreeMap<String, ParamValue>,
    ) -> Option<SubgraphFile> {
        let mut bound = IndexMap::new();
        let mut bound_at = BTreeMap::new();
        let mut bound_inputs = IndexMap::new();
        for (pname, raw) in &decl.params {
            let Some(from) = raw.as_str().and_then(|t| t.strip_prefix('$')) else {
                continue;
            };
            if let Some(g) = self
                .graph_params
                .get(&(scope.to_string(), from.to_string()))
            {
                for (k, v) in &g.bound {
                    bound.insert(format!("{pname}.{k}"), v.clone());
                }
                for (k, r) in &g.bound_inputs {
                    bound_inputs.insert(format!("{pname}.{k}"), r.clone());
                }
            }
        }
        let Some(name) = sub.strip_prefix('$') else {
            return self
                .folders
                .resolve(path, sub)
                .map_err(|e| self.problems.push(Problem::node(path, id, e)))
                .ok()
                .map(|file| SubgraphFile {
                    file,
                    params: bound,
                    params_at: bound_at,
                    inputs: bound_inputs,
                });
        };
        let key = (scope.to_string(), name.to_string());
        let Some(g) = self.graph_params.get(&key).cloned() else {
            if self.root_of(scope, name).is_some() {
                self.follows(scope, name, ("node", format!("{scope}{id}")));
            } else {
                self.problems.push(Problem::node(
                    path,
                    id,
                    format!(
                        "`graph`: `{sub}` is not a graph param of this file (declare it with \"graph\": true)"
                    ),
                ));
            }
            return None;
        };
        let mut clash = false;
        for (k, v) in g.bound {
            if own.contains_key(&k) || decl.params.contains_key(&k) {
                clash = true;
                self.problems.push(Problem::port(
                    path,
                    id,
                    &k,
                    format!(
                        "param `{k}` is set here and bound by the parent as `{name}.{k}`: set it in one place"
                    ),
                ));
            } else {
                bound_at.insert(k.clone(), format!("`{name}.{k}` in {}", g.bound_at));
                bound.insert(k, v);
            }
        }
        for (k, r) in g.bound_inputs {
            bound_inputs.insert(k, r);
        }
        (!clash).then_some(SubgraphFile {
            file: g.file,
            params: bound,
            params_at: bound_at,
            inputs: bound_inputs,
        })
    }

    fn kind_node(
        &mut self,
        path: &Path,
        scope: &str,
        decl: &NodeDecl,
        kind_name: &str,
        params: NodeParamValues,
        disabled: Option<String>,
    ) -> bool {
        let NodeParamValues {
            values: raw_params,
            value_problems,
            origins: param_origins,
        } = params;
        let id = decl.id.as_str();
        let Some(kind) = self.registry.get(kind_name) else {
            let hint = self
                .registry
                .suggest(kind_name)
                .map(|s| format!(" (did you mean `{s}`?)"))
                .unwrap_or_default();
            self.problems.push(Problem::node(
                path,
                id,
                format!("unknown kind `{kind_name}`{hint}; `mesoflow nodes` lists the kinds"),
            ));
            return false;
        };
        let input_ports = kind.inputs().to_vec();
        let output_ports = kind.outputs().to_vec();
        for name in decl.inputs.keys() {
            if !input_ports.iter().any(|p| p.name == name) {
                let known: Vec<&str> = input_ports.iter().map(|p| p.name).collect();
                self.problems.push(Problem::port(
                    path,
                    id,
                    name,
                    format!(
                        "unknown input port (kind `{kind_name}` has inputs: {})",
                        known.join(", ")
                    ),
                ));
            }
        }
        let mut refs = Vec::new();
        for p in &input_ports {
            match decl.inputs.get(p.name) {
                Some(text) => refs.push(Some(PendingRef {
                    scope: scope.into(),
                    text: text.clone(),
                    file: path.into(),
                    node: Some(id.into()),
                    port: Some(p.name.into()),
                    place: String::new(),
                })),
                None if p.optional => refs.push(None),
                None => {
                    self.problems
                        .push(Problem::port(path, id, p.name, "input is not connected"));
                    refs.push(None);
                }
            }
        }
        // Param names the kind does not take, or required ones not given, are wrong with
        // the file. Whether the values suit the kind is checked here and reported by the
        // planner, for the nodes the requested outputs run (`NodeInst::built`).
        let misnamed = check_param_names(kind.params(), &raw_params);
        if !misnamed.is_empty() {
            for (pname, msg) in misnamed {
                self.problems
                    .push(Problem::node(path, id, format!("param `{pname}`: {msg}")));
            }
            return false;
        }
        let built = if value_problems.is_empty() {
            match check_params(kind.params(), &raw_params) {
                Ok(params) => kind
                    .build(&params)
                    .map(|node| BuiltNode {
                        params,
                        node: node.into(),
                    })
                    .map_err(|e| {
                        // The params the message names, with where they came from.
                        let named = param_origins
                            .iter()
                            .filter(|(pname, _)| names_word(&e, pname))
                            .map(|(_, o)| o);
                        vec![Origin::union(named).explain(e)]
                    }),
                Err(errs) => Err(errs
                    .into_iter()
                    .map(|(pname, msg)| {
                        let msg = format!("param `{pname}`: {msg}");
                        match param_origins.get(&pname) {
                            Some(o) => o.explain(msg),
                            None => msg,
                        }
                    })
                    .collect()),
            }
        } else {
            Err(value_problems)
        };
        let index = self.pending_nodes.len();
        self.node_ids
            .insert((scope.into(), id.into()), NodeEntry::Kind(index));
        self.pending_nodes.push(PendingNode {
            inst: NodeInst {
                id: format!("{scope}{id}"),
                kind: kind.name(),
                file: path.into(),
                input_ports,
                output_ports,
                inputs: Vec::new(),
                built,
                disabled,
            },
            refs,
        });
        true
    }

    fn resolve(&self, r: &PendingRef, depth: usize) -> Result<Source, Problem> {
        if depth > 64 {
            return Err(r.problem(format!(
                "reference `{}` loops through subgraph inputs and outputs",
                r.text
            )));
        }
        let Some((head, port)) = r.text.split_once('.') else {
            return Err(r.problem(format!(
                "reference `{}` should be `node.port`, `inputs.NAME` or `state.NAME`",
                r.text
            )));
        };
        match head {
            "inputs" => match self.input_alias.get(&(r.scope.clone(), port.to_string())) {
                Some(Alias::Root(i)) => Ok(Source::Input(*i)),
                Some(Alias::Parent(p)) => self.resolve(p, depth + 1),
                Some(Alias::Absent) => Ok(Source::Absent),
                None => Err(r.problem(format!("no graph input `{port}`"))),
            },
            "state" => {
                // A file's own states only: a subgraph's are namespaced by its scope.
                let full = format!("{}{port}", r.scope);
                match self.root.states.iter().position(|s| s.0 == full) {
                    Some(i) => Ok(Source::State(i)),
                    None => Err(r.problem(format!("no state `{port}`"))),
                }
            }
            id => match self.node_ids.get(&(r.scope.clone(), id.to_string())) {
                Some(NodeEntry::Kind(n)) => {
                    let ports = &self.pending_nodes[*n].inst.output_ports;
                    match ports.iter().position(|p| p.name == port) {
                        Some(i) => Ok(Source::Node {
                            node: NodeId::from_index(*n),
                            port: i,
                        }),
                        None => {
                            let known: Vec<&str> = ports.iter().map(|p| p.name).collect();
                            Err(r.problem(format!(
                                "node `{id}` has no output `{port}` (outputs: {})",
                                known.join(", ")
                            )))
                        }
                    }
                }
                Some(NodeEntry::Failed) => Ok(Source::Absent),
                Some(NodeEntry::Sub(child)) => match self
                    .sub_outputs
                    .get(&(child.clone(), port.to_string()))
                {
                    Some(inner) => self.resolve(inner, depth + 1),
                    None => Err(r.problem(format!("subgraph node `{id}` has no output `{port}`"))),
                },
                None => {
                    let hint = self
                        .node_ids
                        .keys()
                        .filter(|(s, _)| *s == r.scope)
                        .map(|(_, n)| n.as_str())
                        .min_by_key(|n| edit_distance(n, id))
                        .filter(|n| edit_distance(n, id) <= 2)
                        .map(|n| format!(" (did you mean `{n}`?)"))
                        .unwrap_or_default();
                    Err(r.problem(format!("no node `{id}`{hint}")))
                }
            },
        }
    }

    fn finish(mut self, path: &Path) -> Result<Graph, Problems> {
        let mut failed = Vec::new();
        let mut resolved_refs = Vec::new();
        for p in &self.pending_nodes {
            let srcs: Vec<Source> = p
                .refs
                .iter()
                .map(|r| match r {
                    None => Source::Absent,
                    Some(r) => self.resolve(r, 0).unwrap_or_else(|e| {
                        failed.push(e);
                        Source::Absent
                    }),
                })
                .collect();
            resolved_refs.push(srcs);
        }
        let mut resolve = |r: &PendingRef| {
            self.resolve(r, 0).unwrap_or_else(|e| {
                failed.push(e);
                Source::Absent
            })
        };
        let states: Vec<StateDef> = self
            .root
            .states
            .iter()
            .map(|(name, init, next, doc)| StateDef {
                name: name.clone(),
                init: resolve(init),
                next: resolve(next),
                doc: doc.clone(),
            })
            .collect();
        let outputs: Vec<OutputDef> = self
            .root
            .outputs
            .iter()
            .map(|(name, r, doc)| OutputDef {
                name: name.clone(),
                source: resolve(r),
                doc: doc.clone(),
            })
            .collect();
        self.problems.extend(failed);
        let pending = std::mem::take(&mut self.pending_nodes);
        let nodes: Vec<NodeInst> = pending
            .into_iter()
            .zip(resolved_refs)
            .map(|(p, srcs)| NodeInst {
                inputs: srcs,
                ..p.inst
            })
            .collect();
        let root = std::mem::take(&mut self.root);
        self.check_cycles(&nodes);
        if !self.problems.is_empty() {
            return Err(self.report());
        }
        let graph = Graph {
            file: path.to_path_buf(),
            doc: root.doc,
            params: root.params,
            sizes: root.sizes,
            inputs: root.inputs,
            states,
            nodes: nodes.into(),
            outputs,
        };
        self.check_state_inits(&graph);
        self.check_loops(&graph);
        if !self.problems.is_empty() {
            return Err(self.report());
        }
        Ok(graph)
    }

    /// The problems, each with what follows from it said once, after it: one bad value
    /// is one problem, however much is computed from it.
    fn report(&mut self) -> Problems {
        let mut problems = std::mem::take(&mut self.problems);
        for (&root, follows) in &self.consequences {
            let n = follows.len();
            let groups: Vec<String> = ["param", "input", "node"]
                .iter()
                .filter_map(|&kind| {
                    let names: Vec<String> = follows
                        .iter()
                        .filter(|(k, _)| *k == kind)
                        .map(|(_, name)| format!("`{name}`"))
                        .collect();
                    match names.len() {
                        0 => None,
                        1 => Some(format!("{kind} {}", names[0])),
                        _ => Some(format!("{kind}s {}", names.join(", "))),
                    }
                })
                .collect();
            problems[root].message.push_str(&format!(
                "; {n} problem{} follow{} from it, reported here once: {}",
                if n == 1 { "" } else { "s" },
                if n == 1 { "s" } else { "" },
                groups.join("; ")
            ));
        }
        Problems(problems)
    }

    /// A state's initial value is computed once, before the first step: from inputs and
    /// from nodes that read no state (a state has no value yet then). Checked here, for
    /// every state, rather than only for the states a plan needs, so that `validate`
    /// (which accepts a file some of whose outputs plan) and `run` agree.
    fn check_state_inits(&mut self, g: &Graph) {
        for st in &g.states {
            let mut seen = BTreeSet::new();
            let mut stack = vec![st.init];
            let mut read = None;
            let mut iterative = None;
            while let Some(s) = stack.pop() {
                match s {
                    Source::State(i) => {
                        read = Some(i);
                        break;
                    }
                    Source::Node { node, .. } if seen.insert(node) => {
                        let inst = &g.nodes[node];
                        if inst.input_ports.iter().any(|p| p.iterate) {
                            iterative.get_or_insert(node);
                        }
                        stack.extend(inst.inputs.iter().copied());
                    }
                    _ => {}
                }
            }
            if let (None, Some(n)) = (read, iterative) {
                self.problems.push(Problem::file(
                    &g.file,
                    format!(
                        "state `{}`, init: `{}` needs the iterative node `{}`, which runs in the steps only (an initial value is computed before them)",
                        st.name,
                        g.source_name(st.init),
                        g.nodes[n].id
                    ),
                ));
            }
            if let Some(i) = read {
                self.problems.push(Problem::file(
                    &g.file,
                    format!(
                        "state `{}`, init: `{}` depends on state `{}`; an initial value must come from inputs or from nodes that read no state",
                        st.name,
                        g.source_name(st.init),
                        g.states[i].name
                    ),
                ));
            }
        }
    }

    /// An iterative node's loop body (the nodes that depend on its `iterate` outputs) may
    /// be read only by itself, through its `iterate` input, and by the body: anything else
    /// would see a value that changes every iteration. Loops do not nest.
    fn check_loops(&mut self, g: &Graph) {
        for (l, inst) in g.nodes.iter_enumerated() {
            if !inst.output_ports.iter().any(|p| p.iterate) {
                continue;
            }
            let body = g.loop_body(l);
            let inside = |s: &Source| matches!(s, Source::Node { node, .. } if *node == l || body.contains(node));
            for (port, s) in inst.input_ports.iter().zip(&inst.inputs) {
                if port.iterate && matches!(s, Source::Node { node, .. } if *node == l) {
                    self.problems.push(Problem::port(
                        &inst.file,
                        &inst.id,
                        port.name,
                        format!(
                            "reads `{}` directly: the loop body is empty (put the operator's nodes between them)",
                            g.source_name(*s)
                        ),
                    ));
                } else if port.iterate && !matches!(s, Source::Absent) && !inside(s) {
                    self.problems.push(Problem::port(
                        &inst.file,
                        &inst.id,
                        port.name,
                        format!(
                            "`{}` does not depend on `{}`: the loop input must be the body's result for the current iteration",
                            g.source_name(*s),
                            inst.id
                        ),
                    ));
                }
            }
            // A body node that does not lead to the loop's result (a force law's energy
            // beside its forces) is left alone: nothing outside may read it (below), so no
            // plan demands it and it never runs.
            for (n, reader) in g.nodes.iter_enumerated() {
                if body.contains(&n) {
                    if reader
                        .output_ports
                        .iter()
                        .any(|p| p.iterate || p.persistent)
                    {
                        self.problems.push(Problem::node(
                            &reader.file,
                            &reader.id,
                            format!(
                                "is in the loop body of `{}` but iterates or keeps state itself; loops do not nest",
                                inst.id
                            ),
                        ));
                    }
                    continue;
                }
                for (port, s) in reader.input_ports.iter().zip(&reader.inputs) {
                    let from_body = matches!(s, Source::Node { node, .. } if body.contains(node));
                    if from_body && !(n == l && port.iterate) {
                        self.problems.push(Problem::port(
                            &reader.file,
                            &reader.id,
                            port.name,
                            format!(
                                "reads `{}`, which is inside the loop of `{}` and changes every iteration; only the loop's result `{}` leaves it",
                                g.source_name(*s),
                                inst.id,
                                inst.id
                            ),
                        ));
                    }
                }
            }
            let leaks = g
                .states
                .iter()
                .map(|st| (st.next, format!("state `{}`", st.name)))
                .chain(
                    g.outputs
                        .iter()
                        .map(|o| (o.source, format!("output `{}`", o.name))),
                );
            for (s, what) in leaks {
                if matches!(s, Source::Node { node, .. } if body.contains(&node))
                    || matches!(s, Source::Node { node, port } if node == l && inst.output_ports[port].iterate)
                {
                    self.problems.push(Problem::node(
                        &inst.file,
                        &inst.id,
                        format!(
                            "{what} reads `{}`, which changes every iteration of this loop",
                            g.source_name(s)
                        ),
                    ));
                }
            }
        }
    }

    fn check_cycles(&mut self, nodes: &[NodeInst]) {
        use petgraph::graph::DiGraph;
        let mut g = DiGraph::<usize, ()>::with_capacity(nodes.len(), 0);
        let idx: Vec<_> = (0..nodes.len()).map(|i| g.add_node(i)).collect();
        for (i, n) in nodes.iter().enumerate() {
            for (port, s) in n.input_ports.iter().zip(&n.inputs) {
                // The input that closes an iterative node's loop is read after each
                // iteration, not before the node: no cycle.
                if let Source::Node { node, .. } = s
                    && !port.iterate
                {
                    g.add_edge(idx[node.index()], idx[i], ());
                }
            }
        }
        // Kosaraju's search keeps its stack on the heap; petgraph's Tarjan recurses once
        // per node of a path and overflowed the stack on a chain of 10,000 nodes.
        for scc in petgraph::algo::kosaraju_scc(&g) {
            let cyclic = scc.len() > 1 || g.contains_edge(scc[0], scc[0]);
            if cyclic {
                let mut ids: Vec<&str> = scc.iter().map(|&ix| nodes[g[ix]].id.as_str()).collect();
                ids.sort();
                let first = &nodes[g[scc[0]]];
                self.problems.push(Problem::node(
                    &first.file,
                    &first.id,
                    format!(
                        "cycle through nodes {}; a value that feeds back into the next step must go through `state`",
                        ids.join(", ")
                    ),
                ));
            }
        }
    }
}

/// Whether `text` has `word` as a whole word (not inside a longer name).
fn names_word(text: &str, word: &str) -> bool {
    let is_name = |c: char| c.is_alphanumeric() || c == '_';
    text.match_indices(word).any(|(i, _)| {
        let before = text[..i].chars().next_back();
        let after = text[i + word.len()..].chars().next();
        !before.is_some_and(is_name) && !after.is_some_and(is_name)
    })
}

fn check_param(decl: &ParamDecl, default: &ParamValue, v: &ParamValue) -> Result<(), String> {
    if std::mem::discriminant(default) != std::mem::discriminant(v) {
        return Err(format!(
            "expected {} like the default, got {}",
            default.type_name(),
            v.type_name()
        ));
    }
    let nums: Vec<f64> = match v {
        ParamValue::Number(x) => vec![*x],
        ParamValue::Numbers(xs) => xs.clone(),
        _ => vec![],
    };
    for x in nums {
        if decl.integer && x.fract() != 0.0 {
            return Err(format!("{x} is not an integer"));
        }
        if let Some(m) = decl.min
            && x < m
        {
            return Err(format!(
                "{} is below the minimum {}",
                fmt_number(x),
                fmt_number(m)
            ));
        }
        if let Some(m) = decl.max
            && x > m
        {
            return Err(format!(
                "{} is above the maximum {}",
                fmt_number(x),
                fmt_number(m)
            ));
        }
    }
    if let (Some(c), ParamValue::Text(s)) = (&decl.choices, v)
        && !c.contains(s)
    {
        let hint = nearest(s, c.iter().map(|c| c.as_str()))
            .map(|c| format!(" (did you mean \"{c}\"?)"))
            .unwrap_or_default();
        return Err(format!("\"{s}\" is not one of {}{hint}", c.join(", ")));
    }
    if let (ParamValue::Numbers(d), ParamValue::Numbers(x)) = (default, v)
        && d.len() != x.len()
    {
        return Err(format!(
            "expected {} numbers like the default, got {}",
            d.len(),
            x.len()
        ));
    }
    Ok(())
}

fn describe_constraint(decl: &ParamDecl) -> String {
    let mut parts = Vec::new();
    if decl.integer {
        parts.push("integer".to_string());
    }
    match (decl.min.map(fmt_number), decl.max.map(fmt_number)) {
        (Some(a), Some(b)) => parts.push(format!("in [{a}, {b}]")),
        (Some(a), None) => parts.push(format!(">= {a}")),
        (None, Some(b)) => parts.push(format!("<= {b}")),
        (None, None) => {}
    }
    if let Some(c) = &decl.choices {
        parts.push(format!("one of {}", c.join(" | ")));
    }
    parts.join(", ")
}

fn input_shape(decl: &InputDecl, sizes: &[String], values: &Scope) -> Result<InputShape, String> {
    let rows = || -> Result<Dim, String> {
        match &decl.rows {
            None => Ok(Dim::Free),
            Some(serde_json::Value::String(s)) if !s.starts_with('$') && !s.starts_with('=') => {
                if sizes.contains(s) {
                    Ok(Dim::Size(s.clone()))
                } else {
                    Err(format!(
                        "rows names size `{s}`, which is not declared under \"sizes\""
                    ))
                }
            }
            Some(v) => match expr::resolve(v, values).map_err(|e| e.to_string())? {
                ParamValue::Number(x) if x >= 0.0 && x.fract() == 0.0 && x <= u32::MAX as f64 => {
                    Ok(Dim::Fixed(x as u32))
                }
                other => Err(format!("rows must be a count or a size name, got {other}")),
            },
        }
    };
    let grid = || -> Result<([u32; 3], u32), String> {
        let dims = match &decl.dims {
            Some(v) => match expr::resolve(v, values).map_err(|e| e.to_string())? {
                ParamValue::Numbers(x) if (1..=3).contains(&x.len()) => {
                    let mut d = [1u32; 3];
                    for (i, v) in x.iter().enumerate() {
                        if *v < 1.0 || v.fract() != 0.0 {
                            return Err(format!("grid dims must be positive integers, got {v}"));
                        }
                        d[i] = *v as u32;
                    }
                    d
                }
                other => {
                    return Err(format!(
                        "dims must be an array of 1 to 3 counts, got {other}"
                    ));
                }
            },
            None => return Err("a grid input needs `dims`".into()),
        };
        Ok((dims, decl.comps.unwrap_or(1)))
    };
    match decl.ty.as_str() {
        "particles" => Ok(InputShape::Particles {
            rows: rows()?,
            cols: decl.cols.unwrap_or(1),
        }),
        "indices" => Ok(InputShape::Indices { rows: rows()? }),
        "real_grid" => {
            let (dims, comps) = grid()?;
            Ok(InputShape::Fixed(ValueType::RealGrid { dims, comps }))
        }
        "complex_grid" => {
            let (dims, comps) = grid()?;
            Ok(InputShape::Fixed(ValueType::ComplexGrid { dims, comps }))
        }
        "half_complex_grid" => {
            let (dims, comps) = grid()?;
            Ok(InputShape::Fixed(ValueType::HalfComplexGrid {
                dims,
                comps,
            }))
        }
        "scalar" => Ok(InputShape::Fixed(ValueType::Scalar)),
        other => Err(format!(
            "unknown input type `{other}` (types: particles, real_grid, complex_grid, half_complex_grid, indices, scalar)"
        )),
    }
}
