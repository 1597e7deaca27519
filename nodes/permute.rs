//! Gather and scatter of rows by index, so any particle array can follow a permutation
//! (the `perm` of a sort: `gather(values, perm)` reorders, `scatter(values, perm)` undoes).
//! Rows are copied as raw 4-byte words, so f32 particle arrays and u32 index arrays alike.

use crate::gpu::DeviceCaps;
use crate::gpu::{Binding, CompileCtx, CompileError, Dispatch, KernelSpec, NodeIo, WG_1D};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamSpec, PortError, PortSpec, RefCtx, Registry,
    Signature,
};
use crate::value::{PortType, RefArray, ValueType};

/// Rows and words per row of a rows-typed value.
fn rows_of(t: ValueType) -> (u32, u32) {
    match t {
        ValueType::Particles { n, k } => (n, k),
        ValueType::Indices { n } => (n, 1),
        other => unreachable!("port type is Rows, got {other}"),
    }
}

/// The same kind of value with `rows` rows.
fn with_rows(t: ValueType, rows: u32) -> ValueType {
    match t {
        ValueType::Particles { k, .. } => ValueType::Particles { n: rows, k },
        ValueType::Indices { .. } => ValueType::Indices { n: rows },
        other => unreachable!("port type is Rows, got {other}"),
    }
}

fn gather_kind() -> NodeKind {
    NodeKind::declare(
        "gather",
        "out[i] = values[index[i]] row by row (an index past the last row gives zeros)",
    )
    .input(PortSpec::new("values", PortType::Rows, "rows to pick from"))
    .input(PortSpec::new(
        "index",
        PortType::Indices,
        "which row of `values` each output row takes",
    ))
    .output(PortSpec::new("out", PortType::Rows, "one row per index"))
    .param(enabled_param())
    .build(|p| {
        Ok(Box::new(Gather {
            enabled: p.flag("enabled"),
        }))
    })
}

/// Lets a graph switch a permutation off by a param (FCM sorts particles only where the
/// grid outgrows the cache): the node then forwards `values` and does no work.
fn enabled_param() -> ParamSpec {
    ParamSpec::flag(
        "enabled",
        true,
        "false: out = values unchanged (the index is not read and the node does no work)",
    )
}

struct Gather {
    enabled: bool,
}

impl Node for Gather {
    fn forwards(&self, _: &[Option<ValueType>]) -> Option<usize> {
        (!self.enabled).then_some(0)
    }

    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let values = inputs[0].expect("required");
        let Some(ValueType::Indices { n }) = inputs[1] else {
            unreachable!("port type checked")
        };
        if !self.enabled {
            return Ok(Signature::outputs(vec![values]));
        }
        Ok(Signature::outputs(vec![with_rows(values, n)]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let values = inputs[0].as_ref().expect("required");
        if !self.enabled {
            outputs[0].data.copy_from_slice(&values.data);
            return;
        }
        let index = &inputs[1].as_ref().expect("required").data;
        let (rows, k) = rows_of(values.ty);
        let k = k as usize;
        for (i, &src) in index.iter().enumerate() {
            for c in 0..k {
                outputs[0].data[i * k + c] = if src < rows as f64 {
                    values.data[src as usize * k + c]
                } else {
                    0.0
                };
            }
        }
    }
}

impl GpuKernels for Gather {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let values = io.inputs[0].expect("required");
        let index = io.inputs[1].expect("required");
        let (in_rows, k) = rows_of(values.ty);
        let (out_rows, _) = rows_of(io.outputs[0].ty);
        let kernel = cx.kernel(&KernelSpec::new(
            "gather",
            cx.shader("permute/gather.wgsl")?,
            &[
                Binding::StorageRead,
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::Uniform,
            ],
        ))?;
        let shape = cx.uniform(
            "gather shape",
            bytemuck::cast_slice(&[out_rows, in_rows, k]),
        );
        let groups = cx.grid_1d(out_rows as u64 * k as u64, WG_1D);
        Ok(vec![cx.dispatch(
            &kernel,
            &[values.buffer, index.buffer, io.outputs[0].buffer, &shape],
            groups,
        )])
    }
}

fn scatter_kind() -> NodeKind {
    NodeKind::declare(
        "scatter",
        "out[index[i]] = values[i] row by row (unwritten rows are 0; indices should be distinct)",
    )
    .input(PortSpec::new("values", PortType::Rows, "rows to place"))
    .input(PortSpec::new(
        "index",
        PortType::Indices,
        "destination row of each row of `values`",
    ))
    .output(PortSpec::new("out", PortType::Rows, "the placed rows"))
    .param(ParamSpec::integer(
        "rows",
        Some(0.0),
        0.0,
        u32::MAX as f64,
        "rows of the output (0: as many as `values`); indices past it are skipped",
    ))
    .param(enabled_param())
    .param(ParamSpec::flag(
        "permutation",
        false,
        "the index is a permutation of the rows (a sort's perm): every output row is written, so the output is not cleared first (one dispatch less; rows the index misses would hold stale data)",
    ))
    .build(|p| {
        Ok(Box::new(Scatter {
            rows: p.number("rows") as u32,
            enabled: p.flag("enabled"),
            permutation: p.flag("permutation"),
        }))
    })
}

struct Scatter {
    rows: u32,
    enabled: bool,
    permutation: bool,
}

impl Node for Scatter {
    fn forwards(&self, _: &[Option<ValueType>]) -> Option<usize> {
        (!self.enabled).then_some(0)
    }

    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let values = inputs[0].expect("required");
        let Some(ValueType::Indices { n }) = inputs[1] else {
            unreachable!("port type checked")
        };
        let (rows, _) = rows_of(values);
        if n != rows {
            return Err(PortError::new(
                "index",
                format!("has {n} entries for {rows} rows of `values`"),
            ));
        }
        let out_rows = if self.rows == 0 { rows } else { self.rows };
        if self.permutation && out_rows != rows {
            return Err(PortError::new(
                "values",
                format!(
                    "has {rows} rows but `rows` asks for {out_rows}: with `permutation` the index must place every row of the output"
                ),
            ));
        }
        if !self.enabled && out_rows != rows {
            return Err(PortError::new(
                "values",
                format!(
                    "has {rows} rows but `rows` asks for {out_rows}: a disabled scatter forwards its values unchanged"
                ),
            ));
        }
        Ok(Signature::outputs(vec![with_rows(values, out_rows)]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let values = inputs[0].as_ref().expect("required");
        if !self.enabled {
            outputs[0].data.copy_from_slice(&values.data);
            return;
        }
        let index = &inputs[1].as_ref().expect("required").data;
        let (_, k) = rows_of(values.ty);
        let (out_rows, _) = rows_of(outputs[0].ty);
        let k = k as usize;
        outputs[0].data.fill(0.0);
        for (i, &dst) in index.iter().enumerate() {
            if dst < out_rows as f64 {
                for c in 0..k {
                    outputs[0].data[dst as usize * k + c] = values.data[i * k + c];
                }
            }
        }
    }
}

impl GpuKernels for Scatter {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let values = io.inputs[0].expect("required");
        let index = io.inputs[1].expect("required");
        let out = io.outputs[0];
        let (in_rows, k) = rows_of(values.ty);
        let (out_rows, _) = rows_of(out.ty);
        let kernel = cx.kernel(&KernelSpec::new(
            "scatter",
            cx.shader("permute/scatter.wgsl")?,
            &[
                Binding::StorageRead,
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::Uniform,
            ],
        ))?;
        let shape = cx.uniform(
            "scatter shape",
            bytemuck::cast_slice(&[in_rows, out_rows, k]),
        );
        let groups = cx.grid_1d(in_rows as u64 * k as u64, WG_1D);
        let mut out_dispatches = Vec::new();
        if !self.permutation {
            out_dispatches.push(cx.fill(out.buffer, out.ty.words(), 0)?);
        }
        out_dispatches.push(cx.dispatch(
            &kernel,
            &[values.buffer, index.buffer, out.buffer, &shape],
            groups,
        ));
        Ok(out_dispatches)
    }
}

pub fn register(r: &mut Registry) {
    r.add(gather_kind());
    r.add(scatter_kind());
}
