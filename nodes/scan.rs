//! Exclusive prefix sums: `scan` over the flat words of an index array (u32) or a real
//! array (f32). The sort nodes reuse [`ScanKernels`] for their digit histograms.
//!
//! Reduce-then-scan: `reduce` writes one sum per tile of [`TILE`] elements, the tile sums
//! are scanned by the same kernels (recursively while there is more than one tile), and
//! `downsweep` rescans every tile from its offset. Workgroups never wait for each other:
//! Vulkan gives no forward-progress guarantee across workgroups, so decoupled look-back
//! (one pass, 8 bytes per element) is off the table; this costs 12 bytes per element (4
//! read by `reduce`, 4 read and 4 written by `downsweep`), plus 12 / 4096 of that per level
//! of tile sums. Tiles are folded over (x, y) dispatches, so any length that fits a
//! binding works.
//!
//! u32 sums wrap modulo 2^32, as u32 arithmetic does in WGSL (and as the reference does).
//!
//! f32 error: every output is the f32 sum of its terms along a tree of additions: a
//! vec4 of 4 consecutive elements sequentially, then subgroup or workgroup-memory scans
//! (pairwise, or sequential where the hardware chooses), the row carry of a thread, the
//! subgroup partials and the tile offset, at each level of tile sums. An output that sums
//! terms x_i therefore has an error of at most about D * 2^-24 * sum |x_i|, where D, the
//! depth of that tree, is at most 80 per level on the subgroup path (subgroups of up to
//! 32 lanes, even if the hardware adds sequentially) and 28 on the portable path (see
//! tests/it/scan.rs), against len * 2^-24 * sum |x_i| for a single running sum. With terms of mixed signs the error
//! is relative to the sum of magnitudes, not to the (possibly much smaller) prefix sum.

use std::sync::Arc;

use crate::gpu::shaders::ShaderError;
use crate::gpu::{
    Binding, Choice, CompileCtx, CompileError, DeviceCaps, Dispatch, Kernel, KernelSpec, NodeIo,
};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamSpec, Params, PortError, PortSpec, RefCtx, Registry,
    Signature,
};
use crate::value::{Elem, PortType, RefArray, ValueType};

/// Elements per tile of the scan kernels: 256 threads x 4 vec4 loads (`TILE` in
/// shaders/scan/common.wgsl).
pub const TILE: u64 = 4096;

/// Which kernels a node runs. `Auto` takes subgroup operations where the device has them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Variant {
    Auto,
    Subgroup,
    Portable,
}

/// The kernels actually chosen for a device.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Path {
    Subgroup,
    Portable,
}

/// The scan node's decision: its kernels' path on this adapter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ScanPlan(pub Path);

impl std::fmt::Display for ScanPlan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "strategy: {} kernels", self.0)
    }
}

impl std::fmt::Display for Path {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Path::Subgroup => "subgroup",
            Path::Portable => "portable (workgroup memory)",
        })
    }
}

impl Variant {
    pub const NAMES: &'static [&'static str] = &["auto", "subgroup", "portable"];

    /// The `variant` param shared by the primitive nodes.
    pub fn param() -> ParamSpec {
        ParamSpec::choice(
            "variant",
            "auto",
            Self::NAMES,
            "kernels: `subgroup` (subgroup operations), `portable` (workgroup memory only), \
             or `auto` (subgroup where the device supports it)",
        )
    }

    pub fn from_params(p: &Params) -> Result<Self, String> {
        match p.text("variant") {
            "auto" => Ok(Variant::Auto),
            "subgroup" => Ok(Variant::Subgroup),
            "portable" => Ok(Variant::Portable),
            other => Err(format!("unknown variant `{other}`")),
        }
    }

    /// The path for a device: `fits` says whether the subgroup kernels can run there (it
    /// is given the device's subgroup sizes); `Auto` falls back to the portable path.
    pub fn choose(
        self,
        caps: &DeviceCaps,
        what: &str,
        fits: impl Fn((u32, u32)) -> Result<(), String>,
    ) -> Result<Path, String> {
        let subgroup = match caps.subgroups {
            None => Err("the device has no subgroup operations".to_string()),
            Some(sizes) => fits(sizes),
        };
        match (self, subgroup) {
            (Variant::Portable, _) => Ok(Path::Portable),
            (Variant::Auto, Ok(())) | (Variant::Subgroup, Ok(())) => Ok(Path::Subgroup),
            (Variant::Auto, Err(_)) => Ok(Path::Portable),
            (Variant::Subgroup, Err(why)) => Err(format!(
                "{what} variant `subgroup` cannot run on {}: {why}; use `auto` or `portable`",
                caps.adapter
            )),
        }
    }
}

/// Whether the subgroup scan kernels fit subgroups of sizes `(min, max)`: their layout
/// needs full power-of-two subgroups of 4 to 128 lanes (at most 64 per workgroup).
pub fn subgroup_scan_fits((min, max): (u32, u32)) -> Result<(), String> {
    if min >= 4 && max <= 128 {
        Ok(())
    } else {
        Err(format!(
            "subgroups of {min}..{max} lanes (the kernels need 4..128)"
        ))
    }
}

/// Scratch buffers (bytes) for scanning `len` elements: per level of tile sums, the sums
/// and their scan.
pub fn scratch_bytes(len: u64) -> Vec<u64> {
    let mut out = Vec::new();
    let mut m = len;
    while m > TILE {
        m = m.div_ceil(TILE);
        out.extend([4 * m, 4 * m]);
    }
    out
}

/// The two kernels of one scan path and element type.
pub struct ScanKernels {
    reduce: Arc<Kernel>,
    downsweep: Arc<Kernel>,
}

impl ScanKernels {
    pub fn new(cx: &mut CompileCtx<'_>, path: Path, elem: Elem) -> Result<Self, CompileError> {
        let file = match path {
            Path::Subgroup => "scan/subgroup.wgsl",
            Path::Portable => "scan/portable.wgsl",
        };
        let mut source = cx.shader(file)?;
        let (ty, alias) = match elem {
            Elem::U32 => ("u32", None),
            Elem::F32 => ("f32", Some("alias Elem = f32;")),
        };
        if let Some(alias) = alias {
            const WRITTEN: &str = "alias Elem = u32;";
            if source.matches(WRITTEN).count() != 1 {
                return Err(CompileError::Library(ShaderError::NoMarker {
                    file: file.into(),
                    line: WRITTEN.into(),
                }));
            }
            source = source.replace(WRITTEN, alias);
        }
        let bindings = [
            Binding::StorageRead,
            Binding::StorageRead,
            Binding::StorageReadWrite,
            Binding::Uniform,
        ];
        let label = |entry: &str| format!("scan {entry} ({ty}, {path:?})");
        let reduce = cx
            .kernel(&KernelSpec::new(label("reduce"), source.clone(), &bindings).entry("reduce"))?;
        let downsweep =
            cx.kernel(&KernelSpec::new(label("downsweep"), source, &bindings).entry("downsweep"))?;
        Ok(ScanKernels { reduce, downsweep })
    }

    /// Records the exclusive scan of the first `len` elements of `src` into `dst`, with
    /// `scratch` as laid out by [`scratch_bytes`] (or larger).
    pub fn record(
        &self,
        cx: &CompileCtx<'_>,
        src: &wgpu::Buffer,
        dst: &wgpu::Buffer,
        len: u64,
        scratch: &[&wgpu::Buffer],
        out: &mut Vec<Dispatch>,
    ) -> Result<(), CompileError> {
        if len == 0 {
            return Ok(());
        }
        let len32 = u32::try_from(len).map_err(|_| {
            CompileError::Unsupported(format!("scan of {len} elements: at most 2^32 - 1"))
        })?;
        let tiles = len.div_ceil(TILE);
        if tiles == 1 {
            // One tile: no offsets; `src` stands in for the unused offsets binding.
            let params = cx.uniform("scan params", bytemuck::cast_slice(&[len32, 0]));
            out.push(cx.dispatch(&self.downsweep, &[src, src, dst, &params], [1, 1, 1]));
            return Ok(());
        }
        let [sums, scanned, rest @ ..] = scratch else {
            return Err(CompileError::Unsupported(format!(
                "scan of {len} elements: missing scratch buffers for its tile sums"
            )));
        };
        let params = cx.uniform("scan params", bytemuck::cast_slice(&[len32, 1]));
        let grid = cx.grid_1d(tiles, 1);
        out.push(cx.dispatch(&self.reduce, &[src, src, sums, &params], grid));
        self.record(cx, sums, scanned, tiles, rest, out)?;
        out.push(cx.dispatch(&self.downsweep, &[src, scanned, dst, &params], grid));
        Ok(())
    }
}

fn scan_kind() -> NodeKind {
    NodeKind::declare(
        "scan",
        "exclusive prefix sum over the flat words: out[i] = x[0] + ... + x[i-1] (u32 sums wrap mod 2^32)",
    )
    .input(PortSpec::new(
        "x",
        PortType::RealOrIndices,
        "values to sum (u32 indices or f32 words)",
    ))
    .output(PortSpec::new(
        "out",
        PortType::RealOrIndices,
        "exclusive prefix sums, shaped like x (out[0] = 0)",
    ))
    .param(Variant::param())
    .build(|params| {
        Ok(Box::new(ScanNode {
            variant: Variant::from_params(params)?,
        }))
    })
}

struct ScanNode {
    variant: Variant,
}

impl Node for ScanNode {
    fn infer(
        &self,
        inputs: &[Option<ValueType>],
        caps: &DeviceCaps,
    ) -> Result<Signature, PortError> {
        let Some(Some(t)) = inputs.first() else {
            return Err(PortError::new("x", "is required"));
        };
        let path = self.variant.choose(caps, "scan", subgroup_scan_fits);
        Ok(Signature::outputs(vec![*t])
            .with_scratch(scratch_bytes(t.words()))
            .with_plan(Choice(path.map(ScanPlan))))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _cx: RefCtx) {
        let Some(Some(x)) = inputs.first() else {
            return;
        };
        let out = &mut outputs[0];
        match x.ty.elem() {
            Elem::U32 => {
                let mut acc = 0u32;
                for (o, &v) in out.data.iter_mut().zip(&x.data) {
                    *o = acc as f64;
                    acc = acc.wrapping_add(v as u32);
                }
            }
            Elem::F32 => {
                let mut acc = 0.0;
                for (o, &v) in out.data.iter_mut().zip(&x.data) {
                    *o = acc;
                    acc += v;
                }
            }
        }
    }
}

impl GpuKernels for ScanNode {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let (Some(Some(x)), Some(out)) = (io.inputs.first(), io.outputs.first()) else {
            return Err(CompileError::Unsupported(
                "scan: input x or output out has no buffer".into(),
            ));
        };
        let path = io.plan::<Choice<ScanPlan>>().get()?.0;
        let kernels = ScanKernels::new(cx, path, x.ty.elem())?;
        let mut dispatches = Vec::new();
        kernels.record(
            cx,
            x.buffer,
            out.buffer,
            x.ty.words(),
            &io.scratch,
            &mut dispatches,
        )?;
        Ok(dispatches)
    }
}

pub fn register(r: &mut Registry) {
    r.add(scan_kind());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tile_matches_the_shader() {
        let src = crate::gpu::shaders::raw("scan/common.wgsl").unwrap_or_default();
        assert!(src.contains(&format!("const TILE: u32 = {TILE}u;")));
    }

    #[test]
    fn scratch_has_two_buffers_per_level_of_tile_sums() {
        assert!(scratch_bytes(0).is_empty());
        assert!(scratch_bytes(TILE).is_empty());
        assert_eq!(scratch_bytes(TILE + 1), vec![8, 8]);
        assert_eq!(
            scratch_bytes(TILE * TILE + 1),
            vec![4 * (TILE + 1), 4 * (TILE + 1), 8, 8]
        );
    }
}
