//! Transforms and the spectral nodes they host: the one capability behind folding.
//!
//! A spectral node ([`crate::node::Lowering::Spectral`], a [`SpectralBody`]) is a function
//! of the wave vector over all components of a spectrum: a Green function, a filter, a
//! projection. A transform ([`crate::node::Lowering::Transform`], the FFT kinds) runs in
//! passes over the lines of a grid; the planner (`src/plan/fold.rs`) may ask the forward
//! transform that produces a spectral node's input to apply the node in its last pass,
//! and the inverse transform that alone reads the result to leave its first pass to that
//! same kernel. Only transforms implement [`Transform`]; every other node knows nothing
//! of folding. A spectral node that is not folded runs through [`standalone_dispatch`].

use std::fmt::Write;

use crate::gpu::{
    Binding, CompileCtx, CompileError, DeviceCaps, Dispatch, KernelSpec, NodeIo, Slot, WG_1D,
};
use crate::value::{ValueType, half_dims};

/// The capability of a transform node: passes over grid lines that can host a spectral
/// node and hand passes to the transforms around it. The planner asks; the node answers
/// from its recipe for these input types on this device.
pub trait Transform: Send + Sync {
    /// The launch's dispatches for `folding`; `spectral` is the body of the folded node
    /// (given exactly when `folding` is [`Folding::Spectral`] or
    /// [`Folding::SpectralThenInverse`]). With a spectral node, `io.outputs[0]` is the
    /// spectral node's output, which the transform's last pass writes.
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
        folding: Folding,
        spectral: Option<&SpectralBody>,
    ) -> Result<Vec<Dispatch>, CompileError>;

    /// Decisions that depend on the device (tiling, passes), for the passes the launch
    /// runs, shown by `mesoflow inspect`.
    fn device_notes(
        &self,
        inputs: &[Option<ValueType>],
        caps: &DeviceCaps,
        folding: Folding,
    ) -> Vec<String>;

    /// Whether the last pass can apply a spectral node to the transform's only output.
    fn hosts_spectral(&self, inputs: &[Option<ValueType>], caps: &DeviceCaps) -> bool;

    /// For an inverse transform: its first pass, when a forward transform's last pass may
    /// run it instead (`None`: it cannot be split off).
    fn first_pass(&self, inputs: &[Option<ValueType>], caps: &DeviceCaps) -> Option<LinePass>;

    /// For a forward transform: whether its last pass, hosting a spectral node, can also
    /// run `first` (an inverse transform's [`Transform::first_pass`]).
    fn hosts_inverse(
        &self,
        inputs: &[Option<ValueType>],
        caps: &DeviceCaps,
        first: &LinePass,
    ) -> bool;
}

/// How a transform's launch shares passes with the nodes around it (decided by
/// `src/plan/fold.rs`): what its recipe, its dispatches and its notes follow.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Folding {
    /// Every pass of its own, nothing folded in.
    #[default]
    Alone,
    /// A spectral node applied in the last pass .
    Spectral,
    /// ... and the last pass also runs the first pass of the inverse transform after it.
    SpectralThenInverse,
    /// An inverse transform whose first pass ran in the forward transform's last
    ///.
    FirstPassFolded,
}

/// A transform's pass over the lines along one axis of a grid, as the planner matches a
/// forward transform's last pass with the first pass of the inverse transform after it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LinePass {
    pub axis: usize,
    /// Real-space dims and components of the grid.
    pub dims: [u32; 3],
    pub comps: u32,
    /// The transformed axes.
    pub axes: [bool; 3],
    /// On a half spectrum (real transforms).
    pub half: bool,
}

/// An operation on all components of a spectrum at one wave vector (a Green function
/// that mixes components, a filter, a projection). The planner folds it into the last
/// pass of the forward transform that produces its input when it can (see
/// [`Transform::hosts_spectral`]), so it costs no pass over the grid of its own;
/// otherwise it runs as a kernel of its own through the same function.
///
/// The body is the WGSL body of `fn spectral(k: vec3<i32>, n: vec3<u32>, v: array<vec2<f32>,
/// SPECTRAL_IN>) -> array<vec2<f32>, SPECTRAL_OUT>`: `k` holds the signed wave
/// numbers (index i on an axis of n points is i for i <= n/2, else i - n), `n` the dims of
/// the real-space grid, `v` the input's components at k as (re, im), the result the
/// output's. The counts are the input's and the output's types' (the node's `infer`
/// says the output's; a Green function that differentiates returns more components than
/// it reads). Only a node whose counts are equal is folded into a transform (see
/// `src/plan/fold.rs`); the others run alone. Params are read as
/// `spectral_params[i]` (f32); a body with `uses_step` reads the time step as `step`.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct SpectralBody {
    pub body: String,
    pub params: Vec<f32>,
    /// Shader files whose functions the body calls (`common/philox.wgsl`).
    pub imports: Vec<String>,
    /// The body reads `step`: the kernel hosting it binds the engine clock as `clock`.
    pub uses_step: bool,
}

impl SpectralBody {
    /// The params as the `spectral_params` binding holds them: at least one word, since
    /// a binding cannot be empty.
    pub fn param_words(&self) -> Vec<f32> {
        let mut p = self.params.clone();
        p.resize(p.len().max(1), 0.0);
        p
    }

    /// The WGSL function from `in_comps` to `out_comps` components (the constants
    /// `SPECTRAL_IN` and `SPECTRAL_OUT`), preceded by its imports. A kernel using
    /// it declares `spectral_params: array<f32>` as a read-only storage binding holding
    /// [`SpectralBody::param_words`], `clock: array<u32>` (the engine clock) when
    /// `uses_step`, and imports `common/wave.wgsl` for `wave_number`.
    pub fn function(&self, in_comps: u32, out_comps: u32) -> String {
        let mut w = String::new();
        for i in &self.imports {
            w.push_str(&format!("#import {i}\n"));
        }
        let step = if self.uses_step {
            "let step = clock[0];\n    "
        } else {
            ""
        };
        w.push_str(&format!(
            "const SPECTRAL_IN: u32 = {in_comps}u;\nconst SPECTRAL_OUT: u32 = {out_comps}u;\nfn spectral(k: vec3<i32>, n: vec3<u32>, v: array<vec2<f32>, SPECTRAL_IN>) -> array<vec2<f32>, SPECTRAL_OUT> {{\n    {step}{}\n}}\n",
            self.body.trim()
        ));
        w
    }
}

/// The kernel of a spectral node that runs alone, writing a spectrum of type `ty`: one
/// thread per wave vector, all components. Bindings: params, input (when `in_comps` is
/// given: the input spectrum's components, on the output's wave vectors; else the body
/// sees zeros of the output's count, as a generator), output, then the engine clock when
/// the body reads the step.
pub fn standalone_source(body: &SpectralBody, ty: &ValueType, in_comps: Option<u32>) -> String {
    let reads_input = in_comps.is_some();
    let (dims, comps, half) = match *ty {
        ValueType::HalfComplexGrid { dims, comps } => (dims, comps, true),
        ValueType::ComplexGrid { dims, comps } => (dims, comps, false),
        other => unreachable!("spectral nodes infer spectra, got {other}"),
    };
    let s = if half { half_dims(dims) } else { dims };
    let cells = s[0] as u64 * s[1] as u64 * s[2] as u64;
    let [nx, ny, nz] = dims;
    let mut w = String::from(
        "// A spectral node's function over a spectrum (generated by mesoflow).\n#import common/index.wgsl\n#import common/wave.wgsl\n\n@group(0) @binding(0) var<storage, read> spectral_params: array<f32>;\n",
    );
    let mut binding = 1;
    if reads_input {
        writeln!(
            w,
            "@group(0) @binding({binding}) var<storage, read> src: array<vec2<f32>>;"
        )
        .expect("String");
        binding += 1;
    }
    writeln!(
        w,
        "@group(0) @binding({binding}) var<storage, read_write> dst: array<vec2<f32>>;"
    )
    .expect("String");
    if body.uses_step {
        writeln!(
            w,
            "@group(0) @binding({}) var<storage, read> clock: array<u32>;",
            binding + 1
        )
        .expect("String");
    }
    let in_comps = in_comps.unwrap_or(comps);
    w.push_str(&body.function(in_comps, comps));
    let kx = if half {
        "i32(ix)".to_string()
    } else {
        format!("wave_number(ix, {nx}u)")
    };
    writeln!(
        w,
        "\n@compute @workgroup_size({WG_1D})\nfn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,\n        @builtin(local_invocation_index) lid: u32) {{\n    let i = flat_index(wid, nwg, lid, {WG_1D}u);\n    if (i >= {cells}u) {{ return; }}\n    let ix = i % {sx}u; let iy = (i / {sx}u) % {sy}u; let iz = i / {sxy}u;\n    var v: array<vec2<f32>, SPECTRAL_IN>;",
        sx = s[0],
        sy = s[1],
        sxy = s[0] * s[1]
    )
    .expect("String");
    if reads_input {
        for c in 0..in_comps as u64 {
            writeln!(w, "    v[{c}] = src[{}u + i];", c * cells).expect("String");
        }
    }
    writeln!(
        w,
        "    let u = spectral(vec3<i32>({kx}, wave_number(iy, {ny}u), wave_number(iz, {nz}u)), vec3<u32>({nx}u, {ny}u, {nz}u), v);"
    )
    .expect("String");
    for c in 0..comps as u64 {
        writeln!(w, "    dst[{}u + i] = u[{c}];", c * cells).expect("String");
    }
    w.push_str("}\n");
    // The body's imports name embedded files (its node's tests compile it).
    crate::gpu::shaders::resolve(&w)
        .expect("common/index.wgsl, common/wave.wgsl and the body's imports are embedded")
}

/// The kernel of a spectral function run alone over every wave vector of `out`: on
/// `input` (a spectral node that is not folded into a transform; its component count
/// may differ from the output's, its wave vectors may not), or on zeros (a generator
/// such as `stokes_noise`). `label` names the kernel and its params table.
pub fn standalone_dispatch(
    cx: &mut CompileCtx,
    label: &str,
    body: &SpectralBody,
    input: Option<Slot>,
    out: Slot,
) -> Result<Dispatch, CompileError> {
    let in_comps = match input.map(|s| s.ty) {
        None => None,
        Some(ValueType::ComplexGrid { comps, .. } | ValueType::HalfComplexGrid { comps, .. }) => {
            Some(comps)
        }
        Some(other) => {
            return Err(CompileError::Unsupported(format!(
                "a spectral node reads a spectrum, got {other}"
            )));
        }
    };
    let source = standalone_source(body, &out.ty, in_comps);
    let mut bindings = vec![Binding::StorageRead];
    if input.is_some() {
        bindings.push(Binding::StorageRead);
    }
    bindings.push(Binding::StorageReadWrite);
    if body.uses_step {
        bindings.push(Binding::StorageRead);
    }
    let kernel = cx.kernel(&KernelSpec::new(label, source, &bindings))?;
    let params = cx.table(
        &format!("{label} params"),
        bytemuck::cast_slice(&body.param_words()),
    );
    let cells = match out.ty {
        ValueType::ComplexGrid { comps, .. } | ValueType::HalfComplexGrid { comps, .. } => {
            out.ty.words() / 2 / comps.max(1) as u64
        }
        _ => 0,
    };
    let mut buffers = vec![&params];
    buffers.extend(input.map(|s| s.buffer));
    buffers.push(out.buffer);
    if body.uses_step {
        buffers.push(cx.clock);
    }
    Ok(cx.dispatch(&kernel, &buffers, cx.grid_1d(cells, WG_1D)))
}
