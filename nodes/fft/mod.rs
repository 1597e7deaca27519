//! Fast Fourier transforms over grids, batched over components, for sizes whose prime
//! factors are 2, 3, 5 and 7 (up to [`plan::MAX_LENGTH`] per axis):
//!
//! - `fft` / `ifft`: complex grid -> complex grid;
//! - `rfft`: real grid -> half complex grid, the Hermitian half spectrum: x wave numbers
//!   0..=nx/2 only (nx/2 + 1 values per x line; the others are complex conjugates);
//! - `irfft`: half complex grid -> real grid.
//!
//! Conventions are numpy's: the forward transform is X[k] = sum_j x[j] e^{-2 pi i k.j / n}
//! (unnormalised); the inverse uses e^{+2 pi i k.j / n} and the factor 1/N, N the product
//! of the transformed sizes, so ifft(fft(x)) = x. `irfft` takes the real part of the
//! inverse of the Hermitian extension, so imaginary parts that a true half spectrum of a
//! real grid cannot have (at kx = 0 and kx = nx/2) are ignored, as numpy's irfftn does.
//! The param `axes` (x, xy or xyz) selects 1-D, 2-D or 3-D transforms; axes of size 1
//! are skipped.
//!
//! `plan.rs` turns a shape into a recipe (data: passes, radices, tiling, twiddles),
//! `codegen.rs` turns each pass into WGSL, `reference.rs` is the f64 reference (rustfft).

pub mod codegen;
pub mod plan;
mod reference;

pub use plan::{is_friendly, next_friendly};

use crate::gpu::{CompileCtx, CompileError, DeviceCaps, Dispatch, KernelSpec, NodeIo};
use crate::node::{
    Lowering, Node, NodeKind, ParamSpec, PortError, PortSpec, RefCtx, Registry, Signature,
};
use crate::transform::{Folding, LinePass, SpectralBody, Transform};
use crate::value::{PortType, RefArray, ValueType};
use plan::{Buf, Key, Kind, Limits, MAX_LENGTH};

const AXES: &[&str] = &["x", "xy", "xyz"];

/// The node kind of one transform (`fft`, `ifft`, `rfft`, `irfft`).
fn fft_kind(kind: Kind) -> NodeKind {
    let doc = match kind {
        Kind::Forward => {
            "complex FFT over x, xy or xyz, e^{-2 pi i k.x/n}, unnormalised; batched over components; sizes with factors 2, 3, 5, 7"
        }
        Kind::Inverse => {
            "inverse complex FFT, e^{+2 pi i k.x/n} times 1/N (N: product of the transformed sizes), so ifft(fft(x)) = x"
        }
        Kind::RealForward => {
            "real-to-complex FFT: real grid -> Hermitian half spectrum (x wave numbers 0..=nx/2), e^{-2 pi i k.x/n}, unnormalised"
        }
        Kind::RealInverse => {
            "complex-to-real FFT: Hermitian half spectrum -> real grid, times 1/N, so irfft(rfft(x)) = x (as numpy's irfftn)"
        }
    };
    let (input, output) = match kind {
        Kind::Forward | Kind::Inverse => (PortType::ComplexGrid, PortType::ComplexGrid),
        Kind::RealForward => (PortType::RealGrid, PortType::HalfComplexGrid),
        Kind::RealInverse => (PortType::HalfComplexGrid, PortType::RealGrid),
    };
    NodeKind::declare(kind.name(), doc)
        .input(PortSpec::new("x", input, "the grid to transform"))
        .output(PortSpec::new(
            "out",
            output,
            "the transform, on the same cells",
        ))
        .param(ParamSpec::choice(
            "axes",
            "xyz",
            AXES,
            "axes to transform: x (1-D), xy (2-D) or xyz (3-D); axes of size 1 are skipped",
        ))
        .build(move |params| {
            let a = params.text("axes");
            let axes = [a.contains('x'), a.contains('y'), a.contains('z')];
            Ok(Box::new(FftNode { kind, axes }))
        })
}

struct FftNode {
    kind: Kind,
    axes: [bool; 3],
}

const AXIS: [&str; 3] = ["x", "y", "z"];

impl FftNode {
    fn grid(&self, inputs: &[Option<ValueType>]) -> Result<([u32; 3], u32), PortError> {
        match inputs.first().copied().flatten() {
            Some(
                ValueType::RealGrid { dims, comps }
                | ValueType::ComplexGrid { dims, comps }
                | ValueType::HalfComplexGrid { dims, comps },
            ) => Ok((dims, comps)),
            Some(t) => Err(PortError::new("x", format!("{t} is not a grid"))),
            None => Err(PortError::new("x", "the transform needs an input")),
        }
    }

    /// The recipe of the whole transform with what `folding` folds into it (an inverse
    /// whose first pass runs elsewhere has the recipe of its own, passes left out when
    /// it runs).
    fn recipe(
        &self,
        inputs: &[Option<ValueType>],
        folding: Folding,
        caps: &DeviceCaps,
    ) -> Result<std::sync::Arc<plan::Recipe>, String> {
        let (dims, comps) = self.grid(inputs).map_err(|e| e.message)?;
        plan::recipe(&Key {
            kind: self.kind,
            dims,
            comps,
            axes: self.axes,
            spectral: matches!(folding, Folding::Spectral | Folding::SpectralThenInverse),
            inverse_after: folding == Folding::SpectralThenInverse,
            limits: Limits::of(caps),
        })
    }

    /// The passes the launch runs: the recipe's, less the first where it ran in the
    /// forward transform (the second then reads the input).
    fn passes(recipe: &plan::Recipe, folding: Folding) -> Result<Vec<plan::Pass>, String> {
        let mut passes = recipe.passes.clone();
        if folding == Folding::FirstPassFolded {
            if passes.len() < 2 {
                return Err("a transform of one pass has no pass left after its first".into());
            }
            passes.remove(0);
            passes[0].src = Buf::Input;
        }
        Ok(passes)
    }

    fn line_pass(&self, dims: [u32; 3], comps: u32, axis: usize) -> LinePass {
        LinePass {
            axis,
            dims,
            comps,
            axes: self.axes,
            half: matches!(self.kind, Kind::RealForward | Kind::RealInverse),
        }
    }

    /// The launch's dispatches; `spectral`: the body of the node folded in, where
    /// `folding` folds one.
    fn dispatches(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
        folding: Folding,
        spectral: Option<&SpectralBody>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let types: Vec<Option<ValueType>> = io.inputs.iter().map(|s| s.map(|s| s.ty)).collect();
        let recipe = self
            .recipe(&types, folding, cx.caps())
            .map_err(CompileError::Unsupported)?;
        let passes = Self::passes(&recipe, folding).map_err(CompileError::Unsupported)?;
        let input = io.inputs[0]
            .ok_or_else(|| CompileError::Unsupported("the transform needs an input".into()))?;
        let params =
            spectral.map(|b| cx.table("spectral params", bytemuck::cast_slice(&b.param_words())));
        let fold = spectral.map(|body| codegen::Fold {
            body,
            dims: recipe.dims,
            stored: recipe.spectrum_dims(),
            half: matches!(self.kind, Kind::RealForward | Kind::RealInverse),
        });
        let mut out = Vec::new();
        let first = usize::from(folding == Folding::FirstPassFolded) + 1;
        for (i, pass) in passes.iter().enumerate() {
            let label = format!(
                "{} pass {}{} ({}, {}-point)",
                self.kind.name(),
                i + first,
                if pass.inverse_after {
                    " + inverse's first"
                } else {
                    ""
                },
                AXIS[pass.axis],
                pass.n
            );
            let spec = KernelSpec::new(
                label,
                codegen::source(pass, fold.as_ref()),
                &codegen::bindings(pass, fold.as_ref()),
            );
            let kernel = cx.kernel(&spec)?;
            let twiddles = cx.table("fft twiddles", bytemuck::cast_slice(&pass.twiddles()));
            let buffer = |b: Buf| -> Result<&wgpu::Buffer, CompileError> {
                match b {
                    Buf::Input => Ok(input.buffer),
                    Buf::Output => Ok(io.outputs[0].buffer),
                    Buf::Scratch => io.scratch.first().copied().ok_or_else(|| {
                        CompileError::Unsupported(
                            "the transform's scratch buffer is missing".into(),
                        )
                    }),
                }
            };
            let mut buffers = Vec::new();
            if pass.src != pass.dst {
                buffers.push(buffer(pass.src)?);
            }
            buffers.push(buffer(pass.dst)?);
            buffers.push(&twiddles);
            if let (true, Some(p)) = (pass.spectral, &params) {
                buffers.push(p);
                if spectral.is_some_and(|b| b.uses_step) {
                    buffers.push(cx.clock);
                }
            }
            // Workgroups folded over (x, y) as 1-D kernels fold them; the pass rebuilds
            // its group index as wid.y * nwg.x + wid.x.
            let groups = cx.grid_1d(pass.groups as u64, 1);
            out.push(cx.dispatch(&kernel, &buffers, groups));
        }
        Ok(out)
    }
}

impl Node for FftNode {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let (dims, comps) = self.grid(inputs)?;
        for (a, &n) in dims.iter().enumerate() {
            if n == 0 {
                return Err(PortError::new(
                    "x",
                    format!(
                        "size 0 along {}: a transform needs at least one cell",
                        AXIS[a]
                    ),
                ));
            }
            if !self.axes[a] || n == 1 {
                continue;
            }
            if n > MAX_LENGTH {
                return Err(PortError::new(
                    "x",
                    format!(
                        "size {n} along {} is longer than {MAX_LENGTH}, the longest line an FFT node transforms (lines live in one workgroup's memory)",
                        AXIS[a]
                    ),
                ));
            }
            if !is_friendly(n) {
                return Err(PortError::new(
                    "x",
                    format!(
                        "size {n} along {} is not a product of 2, 3, 5, 7; the next friendly size is {}",
                        AXIS[a],
                        next_friendly(n)
                    ),
                ));
            }
        }
        let out = match self.kind {
            Kind::Forward | Kind::Inverse => ValueType::ComplexGrid { dims, comps },
            Kind::RealForward => ValueType::HalfComplexGrid { dims, comps },
            Kind::RealInverse => ValueType::RealGrid { dims, comps },
        };
        let mut sig = Signature::outputs(vec![out]);
        // The inverse real transform keeps its input intact, and its real output is too
        // small for the spectrum, so the passes before the last go through scratch.
        if self.kind == Kind::RealInverse
            && (self.axes[1] && dims[1] > 1 || self.axes[2] && dims[2] > 1)
        {
            sig.scratch
                .push(ValueType::HalfComplexGrid { dims, comps }.bytes());
        }
        Ok(sig)
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Transform(self)
    }

    fn notes(&self, inputs: &[Option<ValueType>]) -> Vec<String> {
        let Ok((dims, _)) = self.grid(inputs) else {
            return Vec::new();
        };
        let axes: Vec<String> = (0..3)
            .filter(|&a| self.axes[a] && dims[a] > 1)
            .map(|a| {
                let real = matches!(self.kind, Kind::RealForward | Kind::RealInverse);
                let n = if a == 0 && real && dims[0].is_multiple_of(2) {
                    dims[0] / 2
                } else {
                    dims[a]
                };
                let r: Vec<String> = plan::radices(n).iter().map(|r| r.to_string()).collect();
                format!(
                    "{} {}{}",
                    AXIS[a],
                    r.join("x"),
                    if n != dims[a] {
                        format!(" ({n} packed pairs)")
                    } else {
                        String::new()
                    }
                )
            })
            .collect();
        let n_total: u64 = (0..3)
            .filter(|&a| self.axes[a] && dims[a] > 1)
            .map(|a| dims[a] as u64)
            .product();
        vec![format!(
            "{}; radices {}",
            if self.kind.inverse() {
                format!("inverse, e^(+2 pi i k.x/n), times 1/{n_total}")
            } else {
                "forward, e^(-2 pi i k.x/n), unnormalised".to_string()
            },
            if axes.is_empty() {
                "none (every transformed axis has size 1)".to_string()
            } else {
                axes.join(", ")
            }
        )]
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _cx: RefCtx) {
        if let Some(x) = &inputs[0] {
            reference::transform(self.kind, self.axes, x, &mut outputs[0]);
        }
    }
}

impl Transform for FftNode {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
        folding: Folding,
        spectral: Option<&SpectralBody>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let hosts = matches!(folding, Folding::Spectral | Folding::SpectralThenInverse);
        if hosts != spectral.is_some() {
            return Err(CompileError::Unsupported(format!(
                "a transform launch {folding:?} needs {} spectral body",
                if hosts { "a" } else { "no" }
            )));
        }
        self.dispatches(cx, io, folding, spectral)
    }

    fn device_notes(
        &self,
        inputs: &[Option<ValueType>],
        caps: &DeviceCaps,
        folding: Folding,
    ) -> Vec<String> {
        match self.recipe(inputs, folding, caps) {
            Ok(r) => {
                let mut lines = r.describe();
                if folding == Folding::FirstPassFolded {
                    lines.remove(0);
                }
                lines
            }
            Err(e) => vec![format!("cannot run on this device: {e}")],
        }
    }

    fn hosts_spectral(&self, inputs: &[Option<ValueType>], caps: &DeviceCaps) -> bool {
        !self.kind.inverse() && self.recipe(inputs, Folding::Spectral, caps).is_ok()
    }

    fn first_pass(&self, inputs: &[Option<ValueType>], caps: &DeviceCaps) -> Option<LinePass> {
        let (dims, comps) = self.grid(inputs).ok()?;
        let recipe = self.recipe(inputs, Folding::Alone, caps).ok()?;
        let first = recipe.passes.first()?;
        let later_reads_input =
            recipe.passes.len() > 1 && first.load == plan::Load::Complex && first.axis > 0;
        (self.kind.inverse() && later_reads_input).then(|| self.line_pass(dims, comps, first.axis))
    }

    fn hosts_inverse(
        &self,
        inputs: &[Option<ValueType>],
        caps: &DeviceCaps,
        first: &LinePass,
    ) -> bool {
        let (Ok((dims, comps)), Ok(recipe)) = (
            self.grid(inputs),
            self.recipe(inputs, Folding::SpectralThenInverse, caps),
        ) else {
            return false;
        };
        let last = recipe.passes.last().expect("a recipe has passes");
        !self.kind.inverse() && self.line_pass(dims, comps, last.axis) == *first
    }
}

pub fn register(r: &mut Registry) {
    for k in [
        Kind::Forward,
        Kind::Inverse,
        Kind::RealForward,
        Kind::RealInverse,
    ] {
        r.add(fft_kind(k));
    }
}
