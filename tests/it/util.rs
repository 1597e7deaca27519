//! Shared helpers: one GPU context for the whole test binary, graph building, running
//! graphs in-process, CPU references, comparisons.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard, OnceLock};

use mesoflow::exec::{Profile, Program, RunOptions};
use mesoflow::gpu::{DeviceCaps, GpuContext, KernelCache};
use mesoflow::graph::{self, Graph, LoadOptions};
use mesoflow::node::{RefCtx, Registry, check_params};
use mesoflow::plan::{self, PlanOptions};
use mesoflow::value::{HostArray, RefArray, ValueType};

static GPU: OnceLock<Option<Mutex<GpuContext>>> = OnceLock::new();

/// The shared GPU context, locked for the caller (tests submit from one thread at a time),
/// or `None` when there is no adapter and MESOFLOW_REQUIRE_GPU is not set.
pub fn gpu() -> Option<MutexGuard<'static, GpuContext>> {
    let slot = GPU.get_or_init(|| match GpuContext::new() {
        Ok(g) => Some(Mutex::new(g)),
        Err(e) => {
            if std::env::var_os("MESOFLOW_REQUIRE_GPU").is_some() {
                panic!("MESOFLOW_REQUIRE_GPU is set but no GPU context: {e}");
            }
            eprintln!("skipping GPU tests: {e}");
            None
        }
    });
    slot.as_ref()
        .map(|m| m.lock().unwrap_or_else(|p| p.into_inner()))
}

pub fn registry() -> &'static Registry {
    static R: OnceLock<Registry> = OnceLock::new();
    R.get_or_init(Registry::standard)
}

/// The repository root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A fresh temporary folder for one test.
pub fn tmpdir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("mesoflow-it-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Writes a graph file and returns its path.
pub fn write_graph(dir: &Path, name: &str, json: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, json).unwrap();
    p
}

pub fn load(path: &Path) -> Graph {
    graph::load(path, registry(), &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}"))
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

/// Runs a loaded graph on the GPU and returns its outputs by name.
pub fn run_graph(
    gpu: &GpuContext,
    g: &Graph,
    inputs: &BTreeMap<String, HostArray>,
    outputs: Option<Vec<String>>,
    steps: u64,
    fuse: bool,
) -> BTreeMap<String, HostArray> {
    let opts = PlanOptions {
        outputs,
        inputs: inputs.iter().map(|(k, v)| (k.clone(), v.ty)).collect(),
        fuse,
    };
    let p = plan::plan(g, &opts, &gpu.caps).unwrap_or_else(|e| panic!("{e}"));
    let mut cache = KernelCache::default();
    let mut program = Program::compile(gpu, g, &p, &mut cache).unwrap_or_else(|e| panic!("{e}"));
    program.upload(inputs).unwrap();
    program
        .run(&RunOptions {
            steps,
            profile: Profile::Off,
            progress: false,
        })
        .unwrap_or_else(|e| panic!("{e}"));
    program.read_outputs().unwrap().into_iter().collect()
}

/// Writes and loads a graph of one `kind` node whose inputs are `inputs` (graph inputs
/// named after its input ports), in a folder of its own.
fn load_single_node(
    kind: &str,
    params: &str,
    inputs: &BTreeMap<String, HostArray>,
) -> (PathBuf, Graph) {
    static GRAPHS: AtomicUsize = AtomicUsize::new(0);
    let types: Vec<(&str, ValueType)> = inputs.iter().map(|(n, a)| (n.as_str(), a.ty)).collect();
    let dir = tmpdir(&format!(
        "{kind}-{}",
        GRAPHS.fetch_add(1, Ordering::Relaxed)
    ));
    let path = write_graph(&dir, "g.json", &single_node_graph(kind, params, &types));
    (dir, load(&path))
}

/// Runs a graph of one `kind` node whose inputs are `inputs` (named after its input
/// ports) and returns its outputs by port name.
pub fn run_node(
    gpu: &GpuContext,
    kind: &str,
    params: &str,
    inputs: &BTreeMap<String, HostArray>,
) -> BTreeMap<String, HostArray> {
    let (dir, g) = load_single_node(kind, params, inputs);
    let out = run_graph(gpu, &g, inputs, None, 1, true);
    let _ = std::fs::remove_dir_all(&dir);
    out
}

/// [`run_node`] on the shared GPU, with the node's f64 reference for the same inputs (in
/// output-port order).
pub fn run_node_and_reference(
    kind: &str,
    params: &str,
    inputs: &[(&str, HostArray)],
) -> (BTreeMap<String, HostArray>, Vec<RefArray>) {
    let gpu = gpu().expect("checked by the caller");
    let data: BTreeMap<String, HostArray> = inputs
        .iter()
        .map(|(n, a)| (n.to_string(), a.clone()))
        .collect();
    let (dir, g) = load_single_node(kind, params, &data);
    let out = run_graph(&gpu, &g, &data, None, 1, true);
    let _ = std::fs::remove_dir_all(&dir);
    let args: Vec<Option<&HostArray>> = g.nodes[0]
        .input_ports
        .iter()
        .map(|p| data.get(p.name))
        .collect();
    (out, reference(kind, params, &args))
}

/// The error of compiling a one-`kind`-node graph for `gpu` (which must fail).
pub fn compile_error(
    gpu: &GpuContext,
    kind: &str,
    params: &str,
    inputs: &BTreeMap<String, HostArray>,
) -> String {
    let (dir, g) = load_single_node(kind, params, inputs);
    let opts = PlanOptions {
        outputs: None,
        inputs: inputs.iter().map(|(n, a)| (n.clone(), a.ty)).collect(),
        fuse: true,
    };
    let p = plan::plan(&g, &opts, &gpu.caps).unwrap_or_else(|e| panic!("{e}"));
    let mut cache = KernelCache::default();
    let err = match Program::compile(gpu, &g, &p, &mut cache) {
        Ok(_) => panic!("{kind} {params} compiled"),
        Err(e) => e.to_string(),
    };
    let _ = std::fs::remove_dir_all(&dir);
    err
}

/// Runs `f` with the device's capabilities altered by `change` (restored afterwards, also
/// when `f` panics): a lower workgroup cap makes small inputs take the folded (x, y)
/// dispatches of huge ones; hiding subgroups takes the paths of devices without them.
pub fn with_caps<R>(
    gpu: &mut GpuContext,
    change: impl FnOnce(&mut DeviceCaps),
    f: impl FnOnce(&GpuContext) -> R,
) -> R {
    struct Restore<'a>(&'a mut GpuContext, DeviceCaps);
    impl Drop for Restore<'_> {
        fn drop(&mut self) {
            self.0.caps = self.1.clone();
        }
    }
    let saved = gpu.caps.clone();
    change(&mut gpu.caps);
    let r = Restore(gpu, saved);
    f(&*r.0)
}

/// A small deterministic generator for test data (xorshift), so tests need no seed plumbing.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }

    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        self.0 = x;
        x
    }

    /// Uniform in [lo, hi).
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * ((self.next_u64() >> 11) as f64 / (1u64 << 53) as f64)
    }

    pub fn array(&mut self, ty: ValueType, lo: f64, hi: f64) -> HostArray {
        match ty.elem() {
            mesoflow::value::Elem::F32 => HostArray::f32(
                ty,
                (0..ty.words())
                    .map(|_| self.uniform(lo, hi) as f32)
                    .collect(),
            ),
            mesoflow::value::Elem::U32 => HostArray::u32(
                ty,
                (0..ty.words())
                    .map(|_| self.uniform(lo, hi) as u32)
                    .collect(),
            ),
        }
    }
}

/// Evaluates a kind's f64 CPU reference on the given inputs (one evaluation, no state).
pub fn reference(kind: &str, params: &str, inputs: &[Option<&HostArray>]) -> Vec<RefArray> {
    let k = registry().get(kind).unwrap();
    let raw: BTreeMap<String, serde_json::Value> = serde_json::from_str(params).unwrap();
    let raw = raw
        .into_iter()
        .map(|(n, v)| (n, mesoflow::expr::ParamValue::from_json(&v).unwrap()))
        .collect();
    let p = check_params(&k.params(), &raw).unwrap();
    let node = k.build(&p).unwrap();
    let types: Vec<Option<ValueType>> = inputs.iter().map(|a| a.map(|a| a.ty)).collect();
    let sig = node.infer(&types).unwrap();
    let refs: Vec<Option<RefArray>> = inputs.iter().map(|a| a.map(|a| a.to_ref())).collect();
    let mut outs: Vec<RefArray> = sig
        .outputs
        .iter()
        .map(|t| RefArray::new(*t, vec![0.0; t.words() as usize]))
        .collect();
    node.cpu_reference(&refs, &mut outs, RefCtx::default());
    outs
}

/// Largest |gpu - ref| over max(|ref|), with the index where it occurs.
pub fn rel_max_err(gpu: &HostArray, reference: &RefArray) -> (f64, usize) {
    assert_eq!(gpu.ty, reference.ty, "types differ");
    let g = gpu.data.to_f64();
    let scale = reference
        .data
        .iter()
        .fold(0.0f64, |m, x| m.max(x.abs()))
        .max(f64::MIN_POSITIVE);
    let mut worst = (0.0, 0);
    for (i, (a, b)) in g.iter().zip(&reference.data).enumerate() {
        // Equal values (infinities included) are no error.
        let e = if a == b { 0.0 } else { (a - b).abs() / scale };
        if e > worst.0 || e.is_nan() {
            worst = (e, i);
        }
    }
    worst
}
