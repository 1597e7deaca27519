//! Graph files for tests: writing and loading them, `graphs/` files with `--set` values,
//! graphs of one node, and the errors of loading and validating.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use mesoflow::expr::ParamValue;
use mesoflow::graph::{self, Graph, LoadOptions};
use mesoflow::node::Registry;
use mesoflow::value::ValueType;

use super::{registry, root, tmpdir};

/// Writes a graph file and returns its path.
pub fn write_graph(dir: &Path, name: &str, json: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, json).unwrap();
    p
}

/// Loads a graph file with the default options (one step, seed 0), panicking with the
/// loader's report.
pub fn load(path: &Path) -> Graph {
    load_with_registry(path, registry())
}

/// Loads a graph file with the kinds of `reg` (the standard ones and test kinds beside
/// them) and the default options, panicking with the loader's report.
pub fn load_with_registry(path: &Path, reg: &Registry) -> Graph {
    graph::load(path, reg, &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}"))
}

/// Loads a graph file for a run of `steps` steps with this seed, panicking with the
/// loader's report.
pub fn load_for(path: &Path, steps: u64, seed: u64) -> Graph {
    let opts = LoadOptions {
        steps,
        seed,
        ..Default::default()
    };
    graph::load(path, registry(), &opts).unwrap_or_else(|e| panic!("{e}"))
}

/// `--set` values given as JSON literals, as the loader takes them.
fn overrides(sets: &[(&str, &str)]) -> BTreeMap<String, ParamValue> {
    sets.iter()
        .map(|(k, v)| {
            let json: serde_json::Value = serde_json::from_str(v).unwrap();
            (k.to_string(), ParamValue::from_json(&json).unwrap())
        })
        .collect()
}

/// `graphs/<name>` loaded with these `--set` values (JSON literals) for a run of `steps`
/// steps with this seed.
pub fn load_with(name: &str, sets: &[(&str, &str)], steps: u64, seed: u64) -> Graph {
    let opts = LoadOptions {
        overrides: overrides(sets),
        steps,
        seed,
    };
    graph::load(&root().join("graphs").join(name), registry(), &opts)
        .unwrap_or_else(|e| panic!("{e}"))
}

/// The report of loading `graphs/<name>` with these `--set` values and planning every
/// output for the declared inputs, as `mesoflow validate` plans (a node's param values
/// are checked where it runs, so their problems come from planning); one of the two
/// must fail.
pub fn load_error(name: &str, sets: &[(&str, &str)]) -> String {
    load_or_plan_error(&root().join("graphs").join(name), overrides(sets))
        .unwrap_or_else(|| panic!("{name} with {sets:?} loaded and planned"))
}

/// The problems of loading a graph file with these param values and planning every
/// output for its declared inputs, on device-independent capabilities; `None` when it
/// loads and plans.
pub fn load_or_plan_error(path: &Path, overrides: BTreeMap<String, ParamValue>) -> Option<String> {
    let opts = LoadOptions {
        overrides,
        ..Default::default()
    };
    let g = match graph::load(path, registry(), &opts) {
        Ok(g) => g,
        Err(e) => return Some(e.to_string()),
    };
    let caps = mesoflow::gpu::DeviceCaps {
        max_binding: u64::MAX,
        max_buffer: u64::MAX,
        ..mesoflow::gpu::DeviceCaps::baseline()
    };
    let opts = mesoflow::plan::PlanOptions {
        outputs: None,
        inputs: g.declared_input_types(),
        fuse: true,
        in_place: true,
    };
    mesoflow::plan::plan(&g, &opts, &caps)
        .err()
        .map(|e| e.to_string())
}

/// How a graph-file input declares a value type.
pub fn input_decl(t: &ValueType) -> String {
    match *t {
        ValueType::Particles { n, k } => {
            format!(r#"{{"type": "particles", "rows": {n}, "cols": {k}}}"#)
        }
        ValueType::Indices { n } => format!(r#"{{"type": "indices", "rows": {n}}}"#),
        ValueType::RealGrid { dims, comps } => {
            format!(
                r#"{{"type": "real_grid", "dims": [{}, {}, {}], "comps": {comps}}}"#,
                dims[0], dims[1], dims[2]
            )
        }
        ValueType::HalfComplexGrid { dims, comps } => format!(
            r#"{{"type": "half_complex_grid", "dims": [{}, {}, {}], "comps": {comps}}}"#,
            dims[0], dims[1], dims[2]
        ),
        ValueType::ComplexGrid { dims, comps } => {
            format!(
                r#"{{"type": "complex_grid", "dims": [{}, {}, {}], "comps": {comps}}}"#,
                dims[0], dims[1], dims[2]
            )
        }
        ValueType::Scalar => r#"{"type": "scalar"}"#.into(),
        ValueType::Frames { .. } => panic!("frames are outputs only, not graph inputs"),
    }
}

/// A graph of one node: its inputs are graph inputs of the same names, its outputs are
/// graph outputs of the same names.
pub fn single_node_graph(kind: &str, params: &str, inputs: &[(&str, ValueType)]) -> String {
    let k = registry()
        .get(kind)
        .unwrap_or_else(|| panic!("no kind {kind}"));
    let decls: Vec<String> = inputs
        .iter()
        .map(|(n, t)| format!(r#""{n}": {}"#, input_decl(t)))
        .collect();
    let wires: Vec<String> = inputs
        .iter()
        .map(|(n, _)| format!(r#""{n}": "inputs.{n}""#))
        .collect();
    let outs: Vec<String> = k
        .outputs()
        .iter()
        .map(|p| format!(r#""{0}": "n.{0}""#, p.name))
        .collect();
    format!(
        r#"{{"mesoflow": 1, "inputs": {{{}}}, "nodes": [{{"id": "n", "kind": "{kind}", "params": {params}, "inputs": {{{}}}}}], "outputs": {{{}}}}}"#,
        decls.join(", "),
        wires.join(", "),
        outs.join(", ")
    )
}

/// A fresh folder of its own for each one-node graph (tests run in parallel).
fn single_node_dir(kind: &str) -> PathBuf {
    static GRAPHS: AtomicUsize = AtomicUsize::new(0);
    tmpdir(&format!(
        "{kind}-{}",
        GRAPHS.fetch_add(1, Ordering::Relaxed)
    ))
}

/// Writes [`single_node_graph`] into a fresh folder and loads it: the folder (for the
/// caller to remove) and the graph.
pub fn load_single_node(
    kind: &str,
    params: &str,
    inputs: &[(&str, ValueType)],
) -> (PathBuf, Graph) {
    let dir = single_node_dir(kind);
    let path = write_graph(&dir, "g.json", &single_node_graph(kind, params, inputs));
    (dir, load(&path))
}

/// The problems `mesoflow validate` reports for a one-`kind`-node graph, which must have
/// some.
pub fn validation_error(kind: &str, params: &str, inputs: &[(&str, ValueType)]) -> String {
    let dir = single_node_dir(kind);
    let path = write_graph(&dir, "g.json", &single_node_graph(kind, params, inputs));
    let report = mesoflow::plan::validate_file(registry(), &path);
    let _ = std::fs::remove_dir_all(&dir);
    match report {
        Ok(_) => panic!("{kind} {params} validated"),
        Err(e) => e.to_string(),
    }
}

/// A graph of `n` scale nodes in a chain (x -> s0 -> ... -> s{n-1} -> y), each scaling
/// by 1.0001.
pub fn chain_graph(n: usize) -> String {
    let nodes: Vec<String> = (0..n)
        .map(|i| {
            let src = match i {
                0 => "inputs.x".to_string(),
                _ => format!("s{}.out", i - 1),
            };
            format!(
                r#"{{"id": "s{i}", "kind": "scale", "params": {{"factor": 1.0001}}, "inputs": {{"x": "{src}"}}}}"#
            )
        })
        .collect();
    format!(
        r#"{{"mesoflow": 1, "inputs": {{"x": {{"type": "particles", "cols": 1}}}}, "nodes": [{}], "outputs": {{"y": "s{}.out"}}}}"#,
        nodes.join(", "),
        n - 1
    )
}

/// A wrapper graph around the mobility graph `graphs/<mobility>` (params `sets`, a JSON
/// object; zero forces) for n positions, recording each of its outputs in `record` every
/// step for `steps` steps, with this seed: the folder it was written in and the graph.
pub fn mobility_recorder(
    mobility: &str,
    sets: &str,
    n: usize,
    steps: u64,
    record: &[&str],
    seed: u64,
) -> (PathBuf, Graph) {
    let dir = tmpdir("mobility-stats");
    let records: String = record
        .iter()
        .map(|o| {
            format!(
                r#",
    {{"id": "{o}", "kind": "record", "params": {{"frames": {steps}}}, "inputs": {{"x": "m.{o}"}}}}"#
            )
        })
        .collect();
    let outputs: Vec<String> = record
        .iter()
        .map(|o| format!(r#""{o}": "{o}.out""#))
        .collect();
    let json = format!(
        r#"{{"mesoflow": 1,
  "inputs": {{"positions": {{"type": "particles", "rows": {n}, "cols": 3}}}},
  "nodes": [
    {{"id": "zero", "kind": "constant", "params": {{"value": 0}}, "inputs": {{"like": "inputs.positions"}}}},
    {{"id": "m", "graph": "{mobility}", "params": {sets}, "inputs": {{"positions": "inputs.positions", "forces": "zero.out"}}}}{records}
  ],
  "outputs": {{{}}}}}"#,
        outputs.join(", ")
    );
    let g = load_for(&write_graph(&dir, "stats.json", &json), steps, seed);
    (dir, g)
}
