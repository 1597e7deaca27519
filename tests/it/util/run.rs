//! Planning, compiling and running graphs in-process; compile errors; altered device
//! capabilities.

use std::collections::BTreeMap;
use std::sync::{Mutex, MutexGuard, OnceLock};

use mesoflow::exec::{Profile, Program, RunOptions};
use mesoflow::gpu::{DeviceCaps, GpuContext, KernelCache};
use mesoflow::graph::Graph;
use mesoflow::plan::{self, Plan, PlanOptions};
use mesoflow::value::{HostArray, RefArray, ValueType};

use super::{gpu, load_single_node, reference};

/// One kernel cache for the tests that build the same pipelines many times (lavapipe
/// compiles slowly). Not for runs under [`with_caps`]: the cache is keyed by a kernel's
/// source before the device's capabilities specialise it.
pub fn kernel_cache() -> MutexGuard<'static, KernelCache> {
    static CACHE: OnceLock<Mutex<KernelCache>> = OnceLock::new();
    CACHE
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|p| p.into_inner())
}

/// The types of named arrays, as the planner takes them.
pub fn types_of(inputs: &BTreeMap<String, HostArray>) -> BTreeMap<String, ValueType> {
    inputs.iter().map(|(k, v)| (k.clone(), v.ty)).collect()
}

/// Named arrays, as runs take their inputs.
pub fn named(arrays: &[(&str, HostArray)]) -> BTreeMap<String, HostArray> {
    arrays
        .iter()
        .map(|(n, a)| (n.to_string(), a.clone()))
        .collect()
}

/// The plan of `g` on a device with `caps` for inputs of these types and the named
/// outputs (every output for `None`); panics with the planner's message.
pub fn plan_graph(
    caps: &DeviceCaps,
    g: &Graph,
    inputs: BTreeMap<String, ValueType>,
    outputs: Option<&[&str]>,
    fuse: bool,
) -> Plan {
    let opts = PlanOptions {
        outputs: outputs.map(|o| o.iter().map(|s| s.to_string()).collect()),
        inputs,
        fuse,
        in_place: true,
    };
    plan::plan(g, &opts, caps).unwrap_or_else(|e| panic!("{e}"))
}

/// Compiles a plan with the shared [`kernel_cache`].
pub fn compile_cached<'a>(gpu: &'a GpuContext, g: &'a Graph, plan: &'a Plan) -> Program<'a> {
    Program::compile(gpu, g, plan, &mut kernel_cache()).unwrap_or_else(|e| panic!("{e}"))
}

/// Uploads `inputs`, runs `steps` steps (timed as `profile` says) and reads every output
/// back by name; or the first error, as text.
pub fn try_run_program(
    program: &mut Program,
    inputs: &BTreeMap<String, HostArray>,
    steps: u64,
    profile: Profile,
) -> Result<BTreeMap<String, HostArray>, String> {
    program.upload(inputs).map_err(|e| e.to_string())?;
    program
        .run(&RunOptions {
            steps,
            profile,
            progress: false,
        })
        .map_err(|e| e.to_string())?;
    let out = program.read_outputs().map_err(|e| e.to_string())?;
    Ok(out.into_iter().collect())
}

/// [`try_run_program`] unprofiled, panicking with the error.
pub fn run_program(
    program: &mut Program,
    inputs: &BTreeMap<String, HostArray>,
    steps: u64,
) -> BTreeMap<String, HostArray> {
    try_run_program(program, inputs, steps, Profile::Off).unwrap_or_else(|e| panic!("{e}"))
}

/// Plans, compiles (with pipelines from `cache`) and runs a loaded graph: the named
/// outputs (all for `None`) by name, and the plan they ran.
fn run_with_cache(
    gpu: &GpuContext,
    g: &Graph,
    inputs: &BTreeMap<String, HostArray>,
    outputs: Option<&[&str]>,
    steps: u64,
    fuse: bool,
    cache: &mut KernelCache,
) -> (BTreeMap<String, HostArray>, Plan) {
    let p = plan_graph(&gpu.caps, g, types_of(inputs), outputs, fuse);
    let out = {
        let mut program = Program::compile(gpu, g, &p, cache).unwrap_or_else(|e| panic!("{e}"));
        run_program(&mut program, inputs, steps)
    };
    (out, p)
}

/// Runs a loaded graph on the GPU (pipelines built afresh) and returns the named outputs
/// (all for `None`) by name.
pub fn run_graph(
    gpu: &GpuContext,
    g: &Graph,
    inputs: &BTreeMap<String, HostArray>,
    outputs: Option<&[&str]>,
    steps: u64,
    fuse: bool,
) -> BTreeMap<String, HostArray> {
    let mut cache = KernelCache::default();
    run_with_cache(gpu, g, inputs, outputs, steps, fuse, &mut cache).0
}

/// [`run_graph`] with the shared [`kernel_cache`]: the outputs, and the plan they ran.
pub fn run_cached(
    gpu: &GpuContext,
    g: &Graph,
    inputs: &BTreeMap<String, HostArray>,
    outputs: Option<&[&str]>,
    steps: u64,
    fuse: bool,
) -> (BTreeMap<String, HostArray>, Plan) {
    run_with_cache(gpu, g, inputs, outputs, steps, fuse, &mut kernel_cache())
}

/// The single-node graph of `kind` with these inputs (named after its input ports),
/// loaded in a folder of its own: the folder and the graph.
fn load_node(
    kind: &str,
    params: &str,
    inputs: &BTreeMap<String, HostArray>,
) -> (std::path::PathBuf, Graph) {
    let types: Vec<(&str, ValueType)> = inputs.iter().map(|(n, a)| (n.as_str(), a.ty)).collect();
    load_single_node(kind, params, &types)
}

/// Runs a graph of one `kind` node whose inputs are `inputs` (named after its input
/// ports) and returns its outputs by port name.
pub fn run_node(
    gpu: &GpuContext,
    kind: &str,
    params: &str,
    inputs: &BTreeMap<String, HostArray>,
) -> BTreeMap<String, HostArray> {
    let (dir, g) = load_node(kind, params, inputs);
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
    let data = named(inputs);
    let (dir, g) = load_node(kind, params, &data);
    let out = run_graph(&gpu, &g, &data, None, 1, true);
    let _ = std::fs::remove_dir_all(&dir);
    let args: Vec<Option<&HostArray>> = g
        .nodes
        .first()
        .expect("one node")
        .input_ports
        .iter()
        .map(|p| data.get(p.name))
        .collect();
    (out, reference(kind, params, &args))
}

/// [`run_node_and_reference`] for the output `out`: the GPU's array and the reference's.
pub fn run_out(kind: &str, params: &str, inputs: &[(&str, HostArray)]) -> (HostArray, RefArray) {
    let (mut out, mut refs) = run_node_and_reference(kind, params, inputs);
    (out.remove("out").expect("output `out`"), refs.remove(0))
}

/// The error of compiling `g` for `gpu` with inputs of these types (planning must
/// succeed, compiling fail).
pub fn graph_compile_error(
    gpu: &GpuContext,
    g: &Graph,
    inputs: BTreeMap<String, ValueType>,
) -> String {
    let p = plan_graph(&gpu.caps, g, inputs, None, true);
    let mut cache = KernelCache::default();
    match Program::compile(gpu, g, &p, &mut cache) {
        Ok(_) => panic!("the graph compiled"),
        Err(e) => e.to_string(),
    }
}

/// The error of compiling a one-`kind`-node graph for `gpu` (which must fail).
pub fn compile_error(
    gpu: &GpuContext,
    kind: &str,
    params: &str,
    inputs: &BTreeMap<String, HostArray>,
) -> String {
    let (dir, g) = load_node(kind, params, inputs);
    let err = graph_compile_error(gpu, &g, types_of(inputs));
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
