//! `mesoflow._mesoflow`: the engine from Python (the package `python/mesoflow` wraps it).
//!
//! A `Graph` is a loaded graph file (by path, or by name from the library the binary
//! carries); `Graph.compile` plans it for the outputs and input shapes asked for and
//! returns a `Program`, which keeps its GPU buffers, pipelines and state between calls:
//! `Program.run(steps, **arrays)` uploads the arrays given, runs on from the last step
//! (random draws fresh, state carried) with the GIL released, and returns the outputs as
//! numpy arrays. New array sizes replan and recompile, reusing every pipeline that the
//! sizes do not change (one kernel cache per program).
//!
//! Lifetimes: the engine's `Program` borrows its device, graph and plan. The device is
//! opened once per adapter and kept for the process (`device`); a `Program` here owns its
//! graph and plan in boxes that never move and drops the engine program first (field
//! order), which is what makes the borrow it holds valid (`Compiled`).

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

use mesoflow::exec::{Profile, Program as EngineProgram, RunOptions};
use mesoflow::expr::ParamValue;
use mesoflow::gpu::{GpuContext, KernelCache};
use mesoflow::graph::{self, Graph as EngineGraph, InputShape, LoadOptions};
use mesoflow::plan::{self, Plan, PlanOptions};
use mesoflow::value::{HostArray, HostData, HostWords, ValueType};
use numpy::{IntoPyArray, PyArrayDyn, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};

// Both are RuntimeErrors, as libMobility's errors are.
pyo3::create_exception!(
    _mesoflow,
    GraphError,
    PyRuntimeError,
    "A graph file or its params, inputs or outputs have problems (the messages of `mesoflow validate`)."
);
pyo3::create_exception!(
    _mesoflow,
    RunError,
    PyRuntimeError,
    "The GPU could not run a program, or given data was refused (named by input, node and row)."
);

/// Devices opened so far, by the adapter name asked for ("" for the default), kept for
/// the life of the process.
fn device(name: Option<&str>) -> PyResult<&'static GpuContext> {
    static OPEN: Mutex<Vec<(String, &'static GpuContext)>> = Mutex::new(Vec::new());
    let key = name.unwrap_or("").to_string();
    let mut open = OPEN.lock().unwrap_or_else(|p| p.into_inner());
    if let Some((_, gpu)) = open.iter().find(|(k, _)| *k == key) {
        return Ok(gpu);
    }
    let wanted = match name {
        Some(n) => Some(n.to_string()),
        None => std::env::var("MESOFLOW_ADAPTER")
            .ok()
            .filter(|s| !s.is_empty()),
    };
    let gpu = GpuContext::open_named(wanted.as_deref())
        .map_err(|e| RunError::new_err(format!("no GPU device: {e}")))?;
    let gpu: &'static GpuContext = Box::leak(Box::new(gpu));
    open.push((key, gpu));
    Ok(gpu)
}

/// A Python value as a graph param value: numbers, booleans, strings, sequences of numbers.
fn param_value(name: &str, v: &Bound<'_, PyAny>) -> PyResult<ParamValue> {
    if let Ok(b) = v.cast::<pyo3::types::PyBool>() {
        return Ok(ParamValue::Bool(b.is_true()));
    }
    if let Ok(x) = v.extract::<f64>() {
        return Ok(ParamValue::Number(x));
    }
    if let Ok(s) = v.extract::<String>() {
        return Ok(ParamValue::Text(s));
    }
    if let Ok(xs) = v.extract::<Vec<f64>>() {
        return Ok(ParamValue::Numbers(xs));
    }
    Err(GraphError::new_err(format!(
        "param `{name}`: {} is not a number, a boolean, a string or a list of numbers",
        v.repr().map(|r| r.to_string()).unwrap_or_default()
    )))
}

fn to_python(py: Python<'_>, v: &ParamValue) -> Py<PyAny> {
    let object: PyResult<Py<PyAny>> = match v {
        ParamValue::Number(x) => Ok(x
            .into_pyobject(py)
            .map(|o| o.into_any().unbind())
            .unwrap_or_else(|e| match e {})),
        ParamValue::Bool(b) => Ok(b
            .into_pyobject(py)
            .map(|o| o.to_owned().into_any().unbind())
            .unwrap_or_else(|e| match e {})),
        ParamValue::Text(s) => Ok(s
            .into_pyobject(py)
            .map(|o| o.into_any().unbind())
            .unwrap_or_else(|e| match e {})),
        ParamValue::Numbers(xs) => PyList::new(py, xs).map(|o| o.into_any().unbind()),
    };
    object.unwrap_or_else(|_| py.None())
}

fn graph_error(e: impl std::fmt::Display) -> PyErr {
    GraphError::new_err(e.to_string())
}

fn run_error(e: impl std::fmt::Display) -> PyErr {
    RunError::new_err(e.to_string())
}

/// A graph file, loaded and checked: `Graph("fcm", box=[64, 64, 64], tolerance=1e-4)`.
#[pyclass(unsendable, module = "mesoflow._mesoflow")]
struct Graph {
    graph: Arc<EngineGraph>,
    path: std::path::PathBuf,
    seed: u64,
    device: Option<String>,
    /// A scene's particles and their data (empty for a graph file).
    scene_inputs: BTreeMap<String, HostArray>,
}

impl Graph {
    fn load(
        path: &std::path::Path,
        overrides: &BTreeMap<String, ParamValue>,
        seed: u64,
        steps: u64,
    ) -> PyResult<EngineGraph> {
        let opts = LoadOptions {
            overrides: overrides.clone(),
            steps,
            seed,
        };
        graph::load(path, &registry(), &opts).map_err(graph_error)
    }
}

fn registry() -> mesoflow::node::Registry {
    mesoflow::nodes::registry()
}

#[pymethods]
impl Graph {
    /// Loads a graph by path or library name with params as keywords; `seed` (the random
    /// draws), `steps` (the built-in param `steps`, for graphs that size records by it)
    /// and `device` (a substring of an adapter's name, see `adapters()`) are the engine's.
    /// A scene file (`"scene": 1`) loads as the graph it builds, its particles placed
    /// (with `seed` where given, else the scene's) and held in `scene_inputs`.
    #[new]
    #[pyo3(signature = (name_or_path, seed=None, steps=1, device=None, **params))]
    fn new(
        name_or_path: &str,
        seed: Option<u64>,
        steps: u64,
        device: Option<String>,
        params: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let path = graph::library::find(name_or_path).ok_or_else(|| {
            GraphError::new_err(format!(
                "no graph file `{name_or_path}` and no graph of that name in the library ({})",
                graph::library::names().join(", ")
            ))
        })?;
        let mut overrides = BTreeMap::new();
        if let Some(params) = params {
            for (k, v) in params.iter() {
                let name: String = k.extract()?;
                overrides.insert(name.clone(), param_value(&name, &v)?);
            }
        }
        if mesoflow::scene::is_scene(&path) {
            let built = mesoflow::scene::compile(&path, seed).map_err(graph_error)?;
            let seed = seed.or(built.seed).unwrap_or(0);
            let opts = LoadOptions {
                overrides,
                steps,
                seed,
            };
            let graph =
                graph::load_text(&path, &built.graph, &registry(), &opts).map_err(graph_error)?;
            return Ok(Graph {
                graph: Arc::new(graph),
                path,
                seed,
                device,
                scene_inputs: built.inputs,
            });
        }
        let seed = seed.unwrap_or(0);
        let graph = Self::load(&path, &overrides, seed, steps)?;
        Ok(Graph {
            graph: Arc::new(graph),
            path,
            seed,
            device,
            scene_inputs: BTreeMap::new(),
        })
    }

    /// The seed of the graph's random draws.
    #[getter]
    fn seed(&self) -> u64 {
        self.seed
    }

    /// A scene's particles and their data by input name (positions, and where the scene
    /// has them masses, velocities, charges, external forces, bond lists), to hand to
    /// `compile` and `run`; empty for a graph file.
    #[getter]
    fn scene_inputs<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (name, a) in &self.scene_inputs {
            d.set_item(name, to_numpy(py, a.clone())?)?;
        }
        Ok(d)
    }

    /// The graph file's path.
    #[getter]
    fn path(&self) -> String {
        self.path.display().to_string()
    }

    /// What the graph computes.
    #[getter]
    fn doc(&self) -> String {
        self.graph.doc.clone()
    }

    /// The params: name -> {"value", "default", "doc"}.
    #[getter]
    fn params<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for p in &self.graph.params {
            let e = PyDict::new(py);
            e.set_item("value", to_python(py, &p.value))?;
            e.set_item("default", to_python(py, &p.default))?;
            e.set_item("doc", &p.doc)?;
            d.set_item(&p.name, e)?;
        }
        Ok(d)
    }

    /// The inputs: name -> {"shape", "optional", "doc"}.
    #[getter]
    fn inputs<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        let declared = self.graph.declared_input_types_with_optional();
        for i in &self.graph.inputs {
            let e = PyDict::new(py);
            let shape = declared
                .get(&i.name)
                .map(|t| t.npy_shape())
                .unwrap_or_default();
            e.set_item("shape", PyTuple::new(py, shape)?)?;
            e.set_item("optional", i.optional)?;
            e.set_item("doc", &i.doc)?;
            d.set_item(&i.name, e)?;
        }
        Ok(d)
    }

    /// The outputs: name -> doc.
    #[getter]
    fn outputs<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for o in &self.graph.outputs {
            d.set_item(&o.name, &o.doc)?;
        }
        Ok(d)
    }

    /// Plans and compiles the graph for these outputs (None: every output the inputs
    /// allow) and input shapes (keywords: name=(N, 3) or N; inputs not named take their
    /// declared shapes, optional ones are absent).
    #[pyo3(signature = (outputs=None, **input_shapes))]
    fn compile(
        &self,
        outputs: Option<Vec<String>>,
        input_shapes: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Program> {
        let mut given = BTreeMap::new();
        if let Some(shapes) = input_shapes {
            for (k, v) in shapes.iter() {
                let name: String = k.extract()?;
                let shape: Vec<usize> = match v.extract::<usize>() {
                    Ok(n) => vec![n],
                    Err(_) => v.extract::<Vec<usize>>().map_err(|_| {
                        GraphError::new_err(format!(
                            "input `{name}`: a shape is an int or a tuple of ints"
                        ))
                    })?,
                };
                given.insert(name.clone(), input_type(&self.graph, &name, &shape)?);
            }
        }
        Program::build(self, outputs, given)
    }

    fn __repr__(&self) -> String {
        format!("mesoflow.Graph({:?})", self.path.display().to_string())
    }
}

/// The type an input takes for an array of this shape: particles as (N, k) or flat (kN,),
/// scalars as () or (1,), index arrays as (N,), grids as declared.
fn input_type(g: &EngineGraph, name: &str, shape: &[usize]) -> PyResult<ValueType> {
    let decl = g.inputs.iter().find(|i| i.name == name).ok_or_else(|| {
        GraphError::new_err(format!(
            "the graph has no input `{name}` (its inputs: {})",
            g.inputs
                .iter()
                .map(|i| i.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        ))
    })?;
    let count: usize = shape.iter().product();
    let too_big =
        |what: &str| GraphError::new_err(format!("input `{name}`: {what} {shape:?} is too large"));
    match &decl.shape {
        InputShape::Particles { cols, .. } => {
            let (n, k) = match shape {
                [n, k] => (*n, *k),
                [m] if *cols > 0 && m % *cols as usize == 0 => (m / *cols as usize, *cols as usize),
                [] => (1, 1),
                _ => {
                    return Err(GraphError::new_err(format!(
                        "input `{name}`: shape {shape:?} is neither (N, {cols}) nor flat (N * {cols},)"
                    )));
                }
            };
            Ok(ValueType::Particles {
                n: u32::try_from(n).map_err(|_| too_big("shape"))?,
                k: u32::try_from(k).map_err(|_| too_big("shape"))?,
            })
        }
        InputShape::Indices { .. } => Ok(ValueType::Indices {
            n: u32::try_from(count).map_err(|_| too_big("shape"))?,
        }),
        InputShape::Fixed(t) => Ok(*t),
    }
}

/// An engine program with the graph and plan it borrows, owned together; the program is
/// declared first so it is dropped first.
struct Compiled {
    program: EngineProgram<'static>,
    _plan: Box<Plan>,
    _graph: Arc<EngineGraph>,
}

/// A `*mut` the GIL-free section may carry to another thread's stack frame: the
/// `Program` is `unsendable`, so only its own thread ever reaches it, and it holds the
/// `&mut` for the whole section.
struct Exclusive(*mut Compiled);
// SAFETY: see the type's doc: the pointer is used only while the owning thread waits for
// the section to end, with exclusive access.
unsafe impl Send for Exclusive {}

/// A compiled graph: `run(steps=1, **arrays)` returns the outputs as a dict of arrays.
#[pyclass(unsendable, module = "mesoflow._mesoflow")]
struct Program {
    compiled: Option<Compiled>,
    cache: KernelCache,
    graph: Arc<EngineGraph>,
    outputs: Option<Vec<String>>,
    input_types: BTreeMap<String, ValueType>,
    gpu: &'static GpuContext,
    /// Pipelines built over the program's life (recompiles for new sizes included).
    built: usize,
    /// Outputs left out when every output the inputs allow was asked for, with why.
    left_out: Vec<(String, String)>,
    /// Inputs uploaded since the program was built (a recompile keeps the buffers' data
    /// only for inputs given again).
    given: std::collections::BTreeSet<String>,
    /// Host time of `run` outside the engine's run: numpy arrays to the engine's, the
    /// upload, the outputs to numpy (seconds, summed over runs).
    convert: f64,
    upload: f64,
    to_numpy: f64,
}

impl Program {
    fn build(
        g: &Graph,
        outputs: Option<Vec<String>>,
        input_types: BTreeMap<String, ValueType>,
    ) -> PyResult<Program> {
        let gpu = device(g.device.as_deref())?;
        let mut p = Program {
            compiled: None,
            cache: KernelCache::default(),
            graph: g.graph.clone(),
            outputs,
            input_types,
            gpu,
            built: 0,
            left_out: Vec::new(),
            given: Default::default(),
            convert: 0.0,
            upload: 0.0,
            to_numpy: 0.0,
        };
        p.recompile()?;
        Ok(p)
    }

    /// Plans for the current input types (the declared ones for inputs not given) and
    /// compiles, with the program's kernel cache.
    fn recompile(&mut self) -> PyResult<()> {
        self.compiled = None;
        // New buffers: every input must be given again. Host times count from here.
        self.given.clear();
        (self.convert, self.upload, self.to_numpy) = (0.0, 0.0, 0.0);
        let optional: Vec<&str> = self.input_types.keys().map(|s| s.as_str()).collect();
        let inputs = self.graph.assumed_input_types(&self.input_types, &optional);
        let opts = PlanOptions {
            outputs: self.outputs.clone(),
            inputs,
            fuse: true,
            in_place: true,
        };
        let planned = if self.outputs.is_some() {
            plan::plan(&self.graph, &opts, &self.gpu.caps).map_err(graph_error)?
        } else {
            let available =
                plan::plan_available(&self.graph, &opts, &self.gpu.caps).map_err(graph_error)?;
            self.left_out = available
                .left_out
                .iter()
                .map(|(name, why)| (name.clone(), why.to_string()))
                .collect();
            available.plan
        };
        let plan = Box::new(planned);
        let graph = self.graph.clone();
        // SAFETY: the program borrows `*graph` (behind an Arc kept in `Compiled`) and
        // `*plan` (a Box kept in `Compiled`, never moved out), and the device, which lives
        // for the process; `Compiled` drops the program before both.
        let (g_ref, p_ref): (&'static EngineGraph, &'static Plan) =
            unsafe { (&*(Arc::as_ptr(&graph)), &*(plan.as_ref() as *const Plan)) };
        let program =
            EngineProgram::compile(self.gpu, g_ref, p_ref, &mut self.cache).map_err(run_error)?;
        self.built += program.kernels_built;
        self.compiled = Some(Compiled {
            program,
            _plan: plan,
            _graph: graph,
        });
        Ok(())
    }

    fn compiled(&mut self) -> PyResult<&mut Compiled> {
        self.compiled
            .as_mut()
            .ok_or_else(|| RunError::new_err("the program did not compile"))
    }
}

/// A numpy array (any float or integer dtype) as the engine's host array of type `ty`.
/// An input as a contiguous numpy array of the program's element type (float32 or
/// uint32: a copy only where the dtype or layout differs), its size checked.
enum Contiguous<'py> {
    F32(Bound<'py, PyArrayDyn<f32>>),
    U32(Bound<'py, PyArrayDyn<u32>>),
}

fn contiguous<'py>(name: &str, v: &Bound<'py, PyAny>, ty: ValueType) -> PyResult<Contiguous<'py>> {
    let expected = ty.words() as usize;
    let integer = matches!(ty, ValueType::Indices { .. });
    let np = v.py().import("numpy")?;
    let dtype = if integer { "uint32" } else { "float32" };
    let arr = np
        .call_method1("ascontiguousarray", (v, dtype))
        .map_err(|e| PyValueError::new_err(format!("input `{name}`: not an array: {e}")))?;
    let size: usize = arr.getattr("size")?.extract()?;
    if size != expected {
        return Err(PyValueError::new_err(format!(
            "input `{name}`: {size} values where the program was compiled for {ty} ({expected} values)"
        )));
    }
    Ok(if integer {
        Contiguous::U32(arr.cast_into::<PyArrayDyn<u32>>()?)
    } else {
        Contiguous::F32(arr.cast_into::<PyArrayDyn<f32>>()?)
    })
}

/// Read-only views of the contiguous arrays (kept alive while their words are uploaded).
enum Borrowed<'py> {
    F32(numpy::PyReadonlyArrayDyn<'py, f32>),
    U32(numpy::PyReadonlyArrayDyn<'py, u32>),
}

impl Borrowed<'_> {
    fn words(&self) -> PyResult<HostWords<'_>> {
        Ok(match self {
            Borrowed::F32(a) => HostWords::F32(a.as_slice()?),
            Borrowed::U32(a) => HostWords::U32(a.as_slice()?),
        })
    }
}

/// The engine's output as a numpy array of its NPY shape (the array takes the data over:
/// no copy).
fn to_numpy<'py>(py: Python<'py>, a: HostArray) -> PyResult<Bound<'py, PyAny>> {
    let shape: Vec<usize> = a.ty.npy_shape().iter().map(|&d| d as usize).collect();
    let flat = match a.data {
        HostData::F32(v) => v.into_pyarray(py).into_any(),
        HostData::U32(v) => v.into_pyarray(py).into_any(),
    };
    flat.call_method1("reshape", (PyTuple::new(py, shape)?,))
}

#[pymethods]
impl Program {
    /// Uploads the arrays given (by input name; float32 or float64, (N, k) or flat), runs
    /// `steps` steps on from the last run (state and step counter carried; `reset()` starts
    /// over) with the GIL released, and returns every output as a numpy array. Arrays of
    /// other sizes than the program's replan and recompile it first.
    #[pyo3(signature = (steps=1, **arrays))]
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        steps: u64,
        arrays: Option<&Bound<'py, PyDict>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        if steps == 0 {
            return Err(PyValueError::new_err("steps must be at least 1"));
        }
        let t_convert = std::time::Instant::now();
        // New sizes first: a recompile when a shape differs from the plan's.
        let mut given: Vec<(String, Bound<'py, PyAny>)> = Vec::new();
        let mut resized = false;
        if let Some(arrays) = arrays {
            for (k, v) in arrays.iter() {
                let name: String = k.extract()?;
                let shape: Vec<usize> = v
                    .cast::<numpy::PyUntypedArray>()
                    .map(|a| a.shape().to_vec())
                    .or_else(|_| {
                        let np = py.import("numpy")?;
                        np.call_method1("shape", (&v,))?.extract::<Vec<usize>>()
                    })?;
                let ty = input_type(&self.graph, &name, &shape)?;
                if self.input_types.get(&name) != Some(&ty) {
                    self.input_types.insert(name.clone(), ty);
                    resized = true;
                }
                given.push((name, v));
            }
        }
        if resized {
            self.recompile()?;
        }
        let optional: Vec<&str> = self.input_types.keys().map(|s| s.as_str()).collect();
        let types = self.graph.assumed_input_types(&self.input_types, &optional);
        let mut arrays = Vec::new();
        for (name, v) in &given {
            let ty = types.get(name).copied().ok_or_else(|| {
                PyValueError::new_err(format!("input `{name}` is not one the program reads"))
            })?;
            arrays.push((name.clone(), contiguous(name, v, ty)?));
        }
        let borrowed: Vec<(&str, Borrowed<'_>)> = arrays
            .iter()
            .map(|(name, a)| {
                Ok((
                    name.as_str(),
                    match a {
                        Contiguous::F32(a) => Borrowed::F32(a.try_readonly()?),
                        Contiguous::U32(a) => Borrowed::U32(a.try_readonly()?),
                    },
                ))
            })
            .collect::<PyResult<_>>()?;
        let upload: Vec<(&str, HostWords<'_>)> = borrowed
            .iter()
            .map(|(name, b)| Ok((*name, b.words()?)))
            .collect::<PyResult<_>>()?;
        let uploading: Vec<String> = upload.iter().map(|(name, _)| name.to_string()).collect();
        // Every input the plan reads must have been given (once is enough: the buffers
        // keep it), or the run would read zeros.
        if let Some(c) = &self.compiled {
            let missing: Vec<&str> = c
                ._plan
                .inputs
                .iter()
                .map(|(i, _)| self.graph.inputs[*i].name.as_str())
                .filter(|name| !self.given.contains(*name) && !uploading.iter().any(|u| u == *name))
                .collect();
            if !missing.is_empty() {
                return Err(PyValueError::new_err(format!(
                    "input{} {} never given: pass {} to run()",
                    if missing.len() == 1 { "" } else { "s" },
                    missing
                        .iter()
                        .map(|m| format!("`{m}`"))
                        .collect::<Vec<_>>()
                        .join(", "),
                    if missing.len() == 1 { "it" } else { "them" }
                )));
            }
        }
        self.convert += t_convert.elapsed().as_secs_f64();
        let compiled = self.compiled()? as *mut Compiled;
        let exclusive = Exclusive(compiled);
        let mut upload_time = 0.0;
        let upload_time_ref = &mut upload_time;
        let result = py.detach(move || {
            let exclusive = exclusive;
            // SAFETY: `Exclusive`'s doc; `self` is borrowed mutably for this whole call.
            let c = unsafe { &mut *exclusive.0 };
            if !upload.is_empty() {
                let t = std::time::Instant::now();
                c.program
                    .update_input_words(&upload)
                    .map_err(|e| e.to_string())?;
                *upload_time_ref = t.elapsed().as_secs_f64();
            }
            c.program
                .run_on_and_read(&RunOptions {
                    steps,
                    profile: Profile::Off,
                    progress: false,
                })
                .map(|(_, outputs)| outputs)
                .map_err(|e| e.to_string())
        });
        self.upload += upload_time;
        let outputs = result.map_err(RunError::new_err)?;
        // Written (the upload comes before the run): later runs may leave them out.
        self.given.extend(uploading);
        let t_numpy = std::time::Instant::now();
        let d = PyDict::new(py);
        for (name, a) in outputs {
            d.set_item(name, to_numpy(py, a)?)?;
        }
        self.to_numpy += t_numpy.elapsed().as_secs_f64();
        Ok(d)
    }

    /// The next run starts over: initial state, step counter 0 (the same draws as the
    /// first run for the same seed).
    fn reset(&mut self) -> PyResult<()> {
        self.compiled()?.program.reset();
        Ok(())
    }

    /// Steps run since the last start (compile or reset).
    #[getter]
    fn steps_done(&mut self) -> PyResult<u64> {
        Ok(self.compiled()?.program.steps_done())
    }

    /// Pipelines built over the program's life, recompiles included (a new size builds
    /// only the kernels it changes; an unchanged run builds none).
    #[getter]
    fn compilations(&self) -> usize {
        self.built
    }

    /// Host time spent in `run` since the last compile, in seconds, by phase: `convert` (the numpy arrays
    /// given to the engine's, shape checks), `upload`, `submit` (recording and submitting
    /// the steps), `wait` (for the GPU), `read` (outputs out of the readback buffers),
    /// `to_numpy`. Where a per-call cost goes; the GPU's own times are `profile()`.
    #[getter]
    fn host_times<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let (convert, upload, to_numpy) = (self.convert, self.upload, self.to_numpy);
        let t = self.compiled()?.program.host_times;
        let d = PyDict::new(py);
        d.set_item("convert", convert)?;
        d.set_item("upload", upload)?;
        d.set_item("submit", t.submit.as_secs_f64())?;
        d.set_item("wait", t.wait.as_secs_f64())?;
        d.set_item("read", t.read.as_secs_f64())?;
        d.set_item("to_numpy", to_numpy)?;
        Ok(d)
    }

    /// The outputs the program computes.
    #[getter]
    fn outputs(&mut self) -> PyResult<Vec<String>> {
        let c = self.compiled()?;
        Ok(c.program.output_names())
    }

    /// Outputs left out (compiled without naming outputs): name -> why.
    #[getter]
    fn left_out<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (name, why) in &self.left_out {
            d.set_item(name, why)?;
        }
        Ok(d)
    }

    /// GPU time per launch of one step (timestamp queries where the adapter has them):
    /// a list of (launch, milliseconds), the launch named by its nodes.
    fn profile(&mut self, py: Python<'_>) -> PyResult<Vec<(String, f64)>> {
        let exclusive = Exclusive(self.compiled()? as *mut Compiled);
        let rows = py
            .detach(move || {
                let exclusive = exclusive;
                // SAFETY: as in `run`.
                let c = unsafe { &mut *exclusive.0 };
                c.program
                    .run_on(&RunOptions {
                        steps: 1,
                        profile: Profile::Launches,
                        progress: false,
                    })
                    .map_err(|e| e.to_string())
            })
            .map_err(RunError::new_err)?;
        Ok(rows
            .profile
            .iter()
            .map(|r| (r.label.clone(), r.median().as_secs_f64() * 1e3))
            .collect())
    }

    /// The plan, as `mesoflow inspect` prints it.
    fn inspect(&mut self) -> PyResult<String> {
        let graph = self.graph.clone();
        let c = self.compiled()?;
        Ok(plan::to_text(&graph, &c._plan))
    }
}

/// The Vulkan adapters: (name, device type); `device=` takes a substring of a name.
#[pyfunction]
fn adapters() -> Vec<(String, String)> {
    GpuContext::adapters()
}

/// The graphs the library carries, by name (`Graph(name)` loads them).
#[pyfunction]
fn library() -> Vec<String> {
    graph::library::names()
}

/// The device a graph with this `device=` runs on, as `mesoflow` prints it.
#[pyfunction]
#[pyo3(signature = (device=None))]
fn device_summary(device: Option<String>) -> PyResult<String> {
    Ok(self::device(device.as_deref())?.caps.summary())
}

#[pymodule]
fn _mesoflow(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Graph>()?;
    m.add_class::<Program>()?;
    m.add_function(wrap_pyfunction!(adapters, m)?)?;
    m.add_function(wrap_pyfunction!(library, m)?)?;
    m.add_function(wrap_pyfunction!(device_summary, m)?)?;
    m.add("GraphError", m.py().get_type::<GraphError>())?;
    m.add("RunError", m.py().get_type::<RunError>())?;
    Ok(())
}
