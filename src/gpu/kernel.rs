//! Compute kernels (pipeline + explicit bind-group layout), their cache keyed by source and
//! constants, and the recorded unit of GPU work, [`Dispatch`]. Nodes build dispatches
//! through [`CompileCtx`]; only the executor puts them into passes and submits.

use std::collections::HashMap;
use std::io::Write;
use std::sync::Arc;

use thiserror::Error;
use wgpu::util::DeviceExt;

use super::context::{DeviceCaps, GpuContext};
use super::shaders;
use crate::value::ValueType;

/// Errors while turning nodes into pipelines and dispatches.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum CompileError {
    #[error("shader `{label}` failed to compile: {message}")]
    Shader { label: String, message: String },
    #[error("shader library: {0}")]
    Library(#[from] crate::gpu::shaders::ShaderError),
    #[error("{0}")]
    Unsupported(String),
}

/// How a kernel sees one binding (all bindings are in group 0, numbered in order).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Binding {
    StorageRead,
    StorageReadWrite,
    Uniform,
}

/// Everything that identifies a compiled kernel.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct KernelSpec {
    pub label: String,
    /// Complete WGSL (imports already resolved).
    pub source: String,
    pub entry: String,
    /// WGSL `override` constants, as (name, value bits) so the key is hashable.
    pub constants: Vec<(String, u64)>,
    pub bindings: Vec<Binding>,
    /// Whether the library's device-specific forms may replace its portable functions
    /// (`shaders::specialise`); off only to test the portable forms on any device.
    pub specialise: bool,
}

impl KernelSpec {
    pub fn new(label: impl Into<String>, source: impl Into<String>, bindings: &[Binding]) -> Self {
        KernelSpec {
            label: label.into(),
            source: source.into(),
            entry: "main".into(),
            constants: Vec::new(),
            bindings: bindings.to_vec(),
            specialise: true,
        }
    }

    /// The same kernel with the library's portable functions kept on every device.
    pub fn portable(mut self) -> Self {
        self.specialise = false;
        self
    }

    pub fn entry(mut self, entry: &str) -> Self {
        self.entry = entry.into();
        self
    }

    pub fn constant(mut self, name: &str, value: f64) -> Self {
        self.constants.push((name.into(), value.to_bits()));
        self
    }
}

/// A compiled compute pipeline with its explicit layout.
pub struct Kernel {
    pub label: String,
    pub pipeline: wgpu::ComputePipeline,
    pub layout: wgpu::BindGroupLayout,
    pub bindings: Vec<Binding>,
}

/// Pipelines keyed by source, entry point, constants and bindings.
#[derive(Default)]
pub struct KernelCache {
    map: HashMap<KernelSpec, Arc<Kernel>>,
    /// How many pipelines were actually built (cache misses).
    pub built: usize,
}

impl KernelCache {
    pub fn get_or_build(
        &mut self,
        gpu: &GpuContext,
        spec: &KernelSpec,
    ) -> Result<Arc<Kernel>, CompileError> {
        if let Some(k) = self.map.get(spec) {
            return Ok(k.clone());
        }
        let k = Arc::new(build_kernel(gpu, spec)?);
        self.built += 1;
        self.map.insert(spec.clone(), k.clone());
        Ok(k)
    }

    pub fn len(&self) -> usize {
        self.map.len()
    }

    pub fn is_empty(&self) -> bool {
        self.map.is_empty()
    }
}

impl Binding {
    /// Its name in a kernel dump's header.
    fn name(self) -> &'static str {
        match self {
            Binding::StorageRead => "StorageRead",
            Binding::StorageReadWrite => "StorageReadWrite",
            Binding::Uniform => "Uniform",
        }
    }
}

impl KernelSpec {
    /// The text `MESOFLOW_KERNEL_DUMP` writes for this kernel: its label, entry, bindings
    /// and constants in three comment lines, then `compiled`, the WGSL as built.
    pub fn dump_text(&self, compiled: &str) -> String {
        let bindings: Vec<&str> = self.bindings.iter().map(|b| b.name()).collect();
        let constants: Vec<String> = self
            .constants
            .iter()
            .map(|(n, bits)| format!("{n} = {}", f64::from_bits(*bits)))
            .collect();
        format!(
            "// {}\n// entry {}, bindings [{}], specialise {}\n// constants: {}\n{}",
            self.label,
            self.entry,
            bindings.join(", "),
            self.specialise,
            constants.join(", "),
            compiled
        )
    }

    /// The kernel of a dump's text (`dump_text`), its source as it was compiled (so
    /// `specialise` is off: the device's forms are in it already).
    pub fn from_dump(text: &str) -> Result<KernelSpec, String> {
        let not_a_dump = || "not a MESOFLOW_KERNEL_DUMP file (its three header lines)".to_string();
        let mut lines = text.splitn(4, '\n');
        let mut header = |prefix: &str| {
            lines
                .next()
                .and_then(|l| l.strip_prefix(prefix))
                .ok_or_else(not_a_dump)
        };
        let label = header("// ")?;
        let spec = header("// entry ")?;
        let constants = header("// constants:")?;
        let source = lines.next().unwrap_or("");
        let (entry, rest) = spec.split_once(", bindings [").ok_or_else(not_a_dump)?;
        let (list, _) = rest.split_once(']').ok_or_else(not_a_dump)?;
        let all = [
            Binding::StorageRead,
            Binding::StorageReadWrite,
            Binding::Uniform,
        ];
        let bindings = list
            .split(',')
            .map(str::trim)
            .filter(|b| !b.is_empty())
            .map(|b| {
                all.into_iter()
                    .find(|x| x.name() == b)
                    .ok_or_else(|| format!("unknown binding {b:?} in its header"))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let mut spec = KernelSpec::new(label, source, &bindings)
            .entry(entry)
            .portable();
        for c in constants
            .split(',')
            .map(str::trim)
            .filter(|c| !c.is_empty())
        {
            let (name, value) = c.split_once(" = ").ok_or_else(not_a_dump)?;
            let value = value
                .parse()
                .map_err(|_| format!("constant {name}: {value:?} is not a number"))?;
            spec = spec.constant(name, value);
        }
        Ok(spec)
    }
}

/// For kernel work and for checking that a refactor leaves the kernels as they were:
/// with `MESOFLOW_KERNEL_DUMP=<folder>`, every kernel built is written there as
/// `<hash of its spec>.wgsl` (`KernelSpec::dump_text`: the WGSL as compiled, `specialised`
/// for the device), so two runs' folders compare file by file and `mesoflow kernel-stats`
/// can build a file again (`KernelSpec::from_dump`). Failing to write is reported on
/// stderr, never an error of the run.
fn dump(spec: &KernelSpec, specialised: &str) {
    use std::hash::{Hash, Hasher};
    static DIR: std::sync::OnceLock<Option<std::path::PathBuf>> = std::sync::OnceLock::new();
    let Some(dir) = DIR
        .get_or_init(|| std::env::var_os("MESOFLOW_KERNEL_DUMP").map(Into::into))
        .as_deref()
    else {
        return;
    };
    let mut h = std::collections::hash_map::DefaultHasher::new();
    spec.hash(&mut h);
    let file = dir.join(format!("{:016x}.wgsl", h.finish()));
    let text = spec.dump_text(specialised);
    if let Err(e) = std::fs::create_dir_all(dir).and_then(|()| std::fs::write(&file, text)) {
        let _ = writeln!(
            std::io::stderr(),
            "mesoflow: MESOFLOW_KERNEL_DUMP: cannot write {}: {e}",
            file.display()
        );
    }
}

fn build_kernel(gpu: &GpuContext, spec: &KernelSpec) -> Result<Kernel, CompileError> {
    let device = &gpu.device;
    let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let entries: Vec<wgpu::BindGroupLayoutEntry> = spec
        .bindings
        .iter()
        .enumerate()
        .map(|(i, b)| wgpu::BindGroupLayoutEntry {
            binding: i as u32,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: match b {
                Binding::StorageRead => wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only: true },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                Binding::StorageReadWrite => wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only: false },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                Binding::Uniform => wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
            },
            count: None,
        })
        .collect();
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some(&spec.label),
        entries: &entries,
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(&spec.label),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let source = if spec.specialise {
        shaders::specialise(&spec.source, &gpu.caps)
    } else {
        std::borrow::Cow::Borrowed(spec.source.as_str())
    };
    dump(spec, &source);
    let descriptor = wgpu::ShaderModuleDescriptor {
        label: Some(&spec.label),
        source: wgpu::ShaderSource::Wgsl(source),
    };
    let module = match runtime_checks() {
        None => device.create_shader_module(descriptor),
        // SAFETY: see `runtime_checks`.
        Some(checks) => unsafe { device.create_shader_module_trusted(descriptor, checks) },
    };
    let constants: Vec<(&str, f64)> = spec
        .constants
        .iter()
        .map(|(n, b)| (n.as_str(), f64::from_bits(*b)))
        .collect();
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(&spec.label),
        layout: Some(&pipeline_layout),
        module: &module,
        entry_point: Some(&spec.entry),
        compilation_options: wgpu::PipelineCompilationOptions {
            constants: &constants,
            zero_initialize_workgroup_memory: false,
        },
        cache: None,
    });
    if let Some(err) = pollster::block_on(scope.pop()) {
        return Err(CompileError::Shader {
            label: spec.label.clone(),
            message: err.to_string(),
        });
    }
    Ok(Kernel {
        label: spec.label.clone(),
        pipeline,
        layout,
        bindings: spec.bindings.clone(),
    })
}

/// One recorded dispatch: a kernel, its bind group and a workgroup count.
#[derive(Clone)]
pub struct Dispatch {
    pub kernel: Arc<Kernel>,
    pub bind_group: wgpu::BindGroup,
    pub workgroups: [u32; 3],
    /// Steps it runs on (every step when `None`); the executor skips it on the others.
    pub period: Option<Period>,
}

/// A step schedule within a node's dispatches: `on` runs on the steps s with
/// s % every == 0 (the first step, 0, included), `!on` on all the other steps. A node
/// uses the pair to do one thing every `every` steps and another in between (MPCD:
/// reorder the particles by cell every few steps), all within a step, so that no value
/// depends on which dispatches an earlier step ran.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Period {
    pub every: u64,
    pub on: bool,
}

impl Dispatch {
    /// Whether it runs on step `step`.
    pub fn runs_at(&self, step: u64) -> bool {
        self.period
            .is_none_or(|p| step.is_multiple_of(p.every.max(1)) == p.on)
    }

    /// The same dispatch on a schedule.
    pub fn on_steps(mut self, period: Period) -> Dispatch {
        self.period = Some(period);
        self
    }
}

/// A value's buffer as a node sees it.
#[derive(Clone, Copy)]
pub struct Slot<'a> {
    pub buffer: &'a wgpu::Buffer,
    pub ty: ValueType,
}

/// The buffers of one node invocation, in port order, and the node's decision for them.
pub struct NodeIo<'a> {
    pub inputs: Vec<Option<Slot<'a>>>,
    pub outputs: Vec<Slot<'a>>,
    pub scratch: Vec<&'a wgpu::Buffer>,
    /// What the node decided when it was planned for these inputs (`Signature::plan`).
    pub plan: Option<&'a NodePlan>,
}

impl NodeIo<'_> {
    /// Whether the plan gave output `output` the buffer of input `input`: an output
    /// declared in place of that input (`PortSpec::in_place_of`, or an iterative node's
    /// `refilled_from` or `started_from`) that the planner aliased. The node then skips copying the input
    /// and binds the buffer once. An output shares an input's buffer in no other case.
    pub fn in_place(&self, output: usize, input: usize) -> bool {
        self.inputs[input].is_some_and(|i| i.buffer == self.outputs[output].buffer)
    }

    /// Whether the plan gave outputs `a` and `b` one buffer: an iterative node's output
    /// declared the final value of an iterate output (`PortSpec::final_of`) that the
    /// planner aliased. The node then skips its copy at the loop's finish and binds the
    /// buffer once.
    pub fn same_output(&self, a: usize, b: usize) -> bool {
        self.outputs[a].buffer == self.outputs[b].buffer
    }

    /// The node's planned decision as its own type. A node that decides in `infer` finds
    /// it here; its absence (or another type) is a planner bug.
    pub fn plan<T: NodeDecision>(&self) -> &T {
        self.plan
            .and_then(|p| p.get::<T>())
            .expect("the node's decision is planned with it (Signature::plan)")
    }
}

/// A node's decision for one set of input types and one adapter: a value of the node's
/// own type (spreading's strategy), shown as one line by `mesoflow inspect`.
pub trait NodeDecision: std::any::Any + std::fmt::Display + Send + Sync {}

impl<T: std::any::Any + std::fmt::Display + Send + Sync> NodeDecision for T {}

/// A node's decision as the plan carries it: taken once in `Node::infer`, read back by
/// the node when it compiles ([`NodeIo::plan`]).
#[derive(Clone)]
pub struct NodePlan(Arc<dyn NodeDecision>);

impl NodePlan {
    pub fn new(decision: impl NodeDecision) -> Self {
        NodePlan(Arc::new(decision))
    }

    /// The decision as the node's own type; `None` for another type.
    pub fn get<T: NodeDecision>(&self) -> Option<&T> {
        let any: &dyn std::any::Any = &*self.0;
        any.downcast_ref()
    }
}

impl std::fmt::Display for NodePlan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.0.fmt(f)
    }
}

impl std::fmt::Debug for NodePlan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "NodePlan({})", self.0)
    }
}

/// A decision that may be "not on this adapter": a param asks for what the adapter lacks
/// (a subgroup kernel without subgroups). The refusal travels with the plan and is the
/// error of compiling for that adapter, so that a graph file stays valid where no device
/// is at hand (`mesoflow validate` plans on baseline capabilities).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Choice<T>(pub Result<T, String>);

impl<T> Choice<T> {
    /// The choice, or the refusal as the compile error.
    pub fn get(&self) -> Result<&T, CompileError> {
        self.0
            .as_ref()
            .map_err(|why| CompileError::Unsupported(why.clone()))
    }
}

impl<T: std::fmt::Display> std::fmt::Display for Choice<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.0 {
            Ok(choice) => choice.fmt(f),
            Err(why) => write!(f, "strategy: none on this adapter: {why}"),
        }
    }
}

/// What a node may use while compiling: the device, the kernel cache, the engine clock.
pub struct CompileCtx<'a> {
    pub gpu: &'a GpuContext,
    pub kernels: &'a mut KernelCache,
    /// The engine clock: a storage buffer whose first u32 is the current step.
    pub clock: &'a wgpu::Buffer,
    /// Bytes of uniforms and tables created so far (reported with the plan's memory).
    pub allocated: std::cell::Cell<u64>,
}

/// Workgroup size of the engine's 1-D kernels.
pub const WG_1D: u32 = 256;

impl CompileCtx<'_> {
    pub fn caps(&self) -> &DeviceCaps {
        &self.gpu.caps
    }

    /// Builds (or finds) a kernel.
    pub fn kernel(&mut self, spec: &KernelSpec) -> Result<Arc<Kernel>, CompileError> {
        self.kernels.get_or_build(self.gpu, spec)
    }

    /// A shader file from `shaders/` with its imports resolved.
    pub fn shader(&self, path: &str) -> Result<String, CompileError> {
        Ok(shaders::source(path)?)
    }

    /// A uniform buffer holding `bytes` (padded to 16 bytes).
    pub fn uniform(&self, label: &str, bytes: &[u8]) -> wgpu::Buffer {
        let mut data = bytes.to_vec();
        data.resize(bytes.len().max(16).next_multiple_of(16), 0);
        self.allocated.set(self.allocated.get() + data.len() as u64);
        self.gpu
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: &data,
                usage: wgpu::BufferUsages::UNIFORM,
            })
    }

    /// A read-only storage buffer holding a table computed on the host.
    pub fn table(&self, label: &str, bytes: &[u8]) -> wgpu::Buffer {
        let mut data = bytes.to_vec();
        data.resize(bytes.len().max(16).next_multiple_of(4), 0);
        self.allocated.set(self.allocated.get() + data.len() as u64);
        self.gpu
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: &data,
                usage: wgpu::BufferUsages::STORAGE,
            })
    }

    /// A dispatch of `kernel` with `buffers` bound in order.
    pub fn dispatch(
        &self,
        kernel: &Arc<Kernel>,
        buffers: &[&wgpu::Buffer],
        workgroups: [u32; 3],
    ) -> Dispatch {
        assert_eq!(
            buffers.len(),
            kernel.bindings.len(),
            "kernel `{}`: wrong number of buffers",
            kernel.label
        );
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource: b.as_entire_binding(),
            })
            .collect();
        let bind_group = self
            .gpu
            .device
            .create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(&kernel.label),
                layout: &kernel.layout,
                entries: &entries,
            });
        Dispatch {
            kernel: kernel.clone(),
            bind_group,
            workgroups,
            period: None,
        }
    }

    /// A dispatch that sets the first `words` 4-byte words of `buffer` to `value` (a
    /// node's first dispatch before accumulating into an output, say), and, where the
    /// buffer has room, up to 3 words past them (its padding: whole 16-byte stores).
    pub fn fill(
        &mut self,
        buffer: &wgpu::Buffer,
        words: u64,
        value: u32,
    ) -> Result<Dispatch, CompileError> {
        // 16-byte stores where the buffer has room for whole quads (every engine buffer:
        // sizes are multiples of 16), one word per thread otherwise.
        let quads = words.div_ceil(4);
        if buffer.size() >= quads * 16 {
            let kernel = self.kernel(&KernelSpec::new(
                "fill4",
                self.shader("engine/fill4.wgsl")?,
                &[Binding::StorageReadWrite, Binding::Uniform],
            ))?;
            let params = self.uniform("fill", bytemuck::cast_slice(&[quads as u32, value]));
            return Ok(self.dispatch(&kernel, &[buffer, &params], self.grid_1d(quads, WG_1D)));
        }
        let kernel = self.kernel(&KernelSpec::new(
            "fill",
            self.shader("engine/fill.wgsl")?,
            &[Binding::StorageReadWrite, Binding::Uniform],
        ))?;
        let params = self.uniform("fill", bytemuck::cast_slice(&[words as u32, value]));
        Ok(self.dispatch(&kernel, &[buffer, &params], self.grid_1d(words, WG_1D)))
    }

    /// Workgroup counts covering `items` threads in groups of `wg`, folded into (x, y)
    /// because one dimension holds at most `max_workgroups_per_dim` groups. Kernels
    /// rebuild the flat index as `(wid.y * nwg.x + wid.x) * wg + lid`.
    pub fn grid_1d(&self, items: u64, wg: u32) -> [u32; 3] {
        grid_1d(items, wg, self.caps().max_workgroups_per_dim)
    }
}

/// See [`CompileCtx::grid_1d`].
pub fn grid_1d(items: u64, wg: u32, max_per_dim: u32) -> [u32; 3] {
    let groups = items.div_ceil(wg as u64);
    if groups == 0 {
        return [0, 1, 1];
    }
    let x = groups.min(max_per_dim as u64);
    let y = groups.div_ceil(x);
    [x as u32, y as u32, 1]
}

/// The runtime checks naga adds to the kernels. By default (`trusted`) loops are not
/// force-bounded and workgroup and private array indices are not clamped: every loop of
/// mesoflow's kernels ends by construction and every such index is in range by
/// construction (the tests run in this mode), while buffer accesses stay guarded by the
/// driver's robust buffer access (wgpu asks for it; with `robustBufferAccess2` wgpu's own
/// checks add no buffer check either). The checks cost what no kernel could spare: on an
/// H200 the box spreading kernel took 0.94 ns per particle with them, 0.73 without the
/// loop bounds and 0.55 without the index clamps as well (BENCHMARKS.md).
/// `MESOFLOW_RUNTIME_CHECKS` picks another set: `all` (wgpu's default, every check),
/// `noloop` (only the loop bounds off), `noloopdiv` (loop bounds and the integer
/// division guards off), `none` (nothing checked). Integer division keeps its guard
/// (division by zero gives the dividend, as WGSL defines) except with `noloopdiv`/`none`.
fn runtime_checks() -> Option<wgpu::ShaderRuntimeChecks> {
    static CHECKS: std::sync::OnceLock<Option<wgpu::ShaderRuntimeChecks>> =
        std::sync::OnceLock::new();
    *CHECKS.get_or_init(|| {
        let mode = std::env::var("MESOFLOW_RUNTIME_CHECKS").unwrap_or_default();
        let mut checks = wgpu::ShaderRuntimeChecks::checked();
        match mode.as_str() {
            "all" => return None,
            "noloop" => checks.force_loop_bounding = false,
            "noloopdiv" => {
                checks.force_loop_bounding = false;
                checks.int_div_checks = false;
            }
            "none" => checks = wgpu::ShaderRuntimeChecks::unchecked(),
            other => {
                if !other.is_empty() && other != "trusted" {
                    // Best effort: `eprintln!` would panic on a closed stderr.
                    let _ = writeln!(
                        std::io::stderr(),
                        "MESOFLOW_RUNTIME_CHECKS={other} is none of all, noloop, noloopdiv, none, trusted: using trusted"
                    );
                }
                checks.force_loop_bounding = false;
                checks.bounds_checks = false;
            }
        }
        Some(checks)
    })
}

#[cfg(test)]
mod tests {
    use super::{Binding, KernelSpec, grid_1d};

    /// A dump's text gives back the kernel it was written from (its source as compiled),
    /// and what is not a dump is an error that says why.
    #[test]
    fn a_dump_gives_back_its_kernel() {
        let spec = KernelSpec::new(
            "a kernel",
            "fn main() {}",
            &[
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::Uniform,
            ],
        )
        .entry("go")
        .constant("SCALE", 2.5)
        .constant("TINY", 1e-300);
        let back = KernelSpec::from_dump(&spec.dump_text("// compiled\nfn main() {}")).unwrap();
        assert_eq!(back.label, spec.label);
        assert_eq!(back.entry, spec.entry);
        assert_eq!(back.bindings, spec.bindings);
        assert_eq!(back.constants, spec.constants);
        assert_eq!(back.source, "// compiled\nfn main() {}");
        assert!(!back.specialise);
        for (text, needle) in [
            ("fn main() {}\n", "not a MESOFLOW_KERNEL_DUMP file"),
            (
                "// k\n// entry main, bindings [Texture], specialise true\n// constants: \n",
                "unknown binding \"Texture\"",
            ),
            (
                "// k\n// entry main, bindings [], specialise true\n// constants: N = many\n",
                "constant N: \"many\" is not a number",
            ),
        ] {
            let e = KernelSpec::from_dump(text).unwrap_err();
            assert!(e.contains(needle), "{text:?}: {e}");
        }
    }

    #[test]
    fn grid_folds_past_the_dimension_cap() {
        assert_eq!(grid_1d(0, 256, 65535), [0, 1, 1]);
        assert_eq!(grid_1d(1, 256, 65535), [1, 1, 1]);
        assert_eq!(grid_1d(256 * 65535, 256, 65535), [65535, 1, 1]);
        let g = grid_1d(256 * 65535 + 1, 256, 65535);
        assert_eq!(g, [65535, 2, 1]);
        assert!(g[0] as u64 * g[1] as u64 * 256 > 256 * 65535);
    }
}
