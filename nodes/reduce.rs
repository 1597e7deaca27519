//! Reductions: over a whole array (sum, dot, norm, max, min), per component over the rows
//! of a particle array (`column_reduce`), and per segment of sorted rows (`segment_reduce`).
//!
//! Accuracy in f32: by default each thread sums its grid-strided share sequentially and
//! the workgroups combine pairwise (blocked summation, error O((n/threads + log n) eps));
//! `compensated: true` carries a TwoSum error term through every addition, which keeps
//! conserved totals (momentum) to about f32 rounding of the result.

use crate::expr::ParamValue;
use crate::gpu::DeviceCaps;
use crate::gpu::{Binding, CompileCtx, CompileError, Dispatch, KernelSpec, NodeIo, WG_1D};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamKind, ParamSpec, PortError, PortSpec, RefCtx,
    Registry, Signature,
};
use crate::value::{PortType, RefArray, ValueType};

/// Workgroups of a first reduction pass: enough to fill a large GPU, few enough for the
/// second pass to fold them in one workgroup. Each thread handles at least 8 vec4 loads.
fn groups_for(words: u64) -> u32 {
    let vec4s = words / 4;
    vec4s.div_ceil(WG_1D as u64 * 8).clamp(1, 2048) as u32
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Op {
    Sum,
    Max,
    Min,
    Mean,
}

impl Op {
    fn code(self) -> f64 {
        match self {
            Op::Sum => 0.0,
            Op::Max => 1.0,
            Op::Min => 2.0,
            Op::Mean => 3.0,
        }
    }

    fn parse(s: &str) -> Op {
        match s {
            "max" => Op::Max,
            "min" => Op::Min,
            "mean" => Op::Mean,
            _ => Op::Sum,
        }
    }

    /// f64 reference over a sequence (empty: 0 for sum and mean, -inf / +inf for max / min).
    fn fold(self, xs: impl Iterator<Item = f64>) -> f64 {
        let mut n = 0usize;
        let mut acc = match self {
            Op::Max => f64::NEG_INFINITY,
            Op::Min => f64::INFINITY,
            _ => 0.0,
        };
        for x in xs {
            n += 1;
            acc = match self {
                Op::Max => acc.max(x),
                Op::Min => acc.min(x),
                _ => acc + x,
            };
        }
        if self == Op::Mean {
            if n == 0 { 0.0 } else { acc / n as f64 }
        } else {
            acc
        }
    }
}

const OPS: &[&str] = &["sum", "mean", "max", "min"];

fn compensated_param() -> ParamSpec {
    ParamSpec {
        name: "compensated",
        kind: ParamKind::Bool,
        default: Some(ParamValue::Bool(false)),
        doc: "carry a TwoSum error term through every addition (sums only)",
    }
}

/// What a flat reduction maps each element to before folding.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Map {
    Value,
    Product,
    Square,
}

/// sum, dot, norm, max, min over all elements of an array.
pub struct FlatKind {
    name: &'static str,
    doc: &'static str,
    op: Op,
    map: Map,
    root: bool,
}

static FLAT: &[FlatKind] = &[
    FlatKind {
        name: "sum",
        doc: "sum of all elements (scalar)",
        op: Op::Sum,
        map: Map::Value,
        root: false,
    },
    FlatKind {
        name: "dot",
        doc: "dot product of two arrays of one shape (scalar)",
        op: Op::Sum,
        map: Map::Product,
        root: false,
    },
    FlatKind {
        name: "norm",
        doc: "Euclidean norm of all elements (scalar)",
        op: Op::Sum,
        map: Map::Square,
        root: true,
    },
    FlatKind {
        name: "max",
        doc: "largest element (scalar; -inf for an empty array)",
        op: Op::Max,
        map: Map::Value,
        root: false,
    },
    FlatKind {
        name: "min",
        doc: "smallest element (scalar; +inf for an empty array)",
        op: Op::Min,
        map: Map::Value,
        root: false,
    },
];

/// The node kind of a table row.
fn flat_kind(row: &'static FlatKind) -> NodeKind {
    let inputs = if row.map == Map::Product {
        vec![
            PortSpec::new("a", PortType::RealArray, "first operand"),
            PortSpec::new("b", PortType::RealArray, "second operand, shaped like a"),
        ]
    } else {
        vec![PortSpec::new("x", PortType::RealArray, "values")]
    };
    NodeKind::declare(row.name, row.doc)
        .inputs(inputs)
        .output(PortSpec::new("out", PortType::Scalar, "the result"))
        // Only sums (sum, dot, norm) carry an error term.
        .params((row.op == Op::Sum).then(compensated_param))
        .build(move |p| {
            let compensated = p.get("compensated") == Some(&ParamValue::Bool(true));
            Ok(Box::new(FlatReduce {
                kind: row,
                compensated,
            }))
        })
}

struct FlatReduce {
    kind: &'static FlatKind,
    compensated: bool,
}

impl Node for FlatReduce {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let a = inputs[0].expect("required");
        if self.kind.map == Map::Product {
            let b = inputs[1].expect("required");
            if a != b {
                return Err(PortError::new(
                    "b",
                    format!("is {b} but `a` is {a}; a dot product needs one shape"),
                ));
            }
        }
        Ok(Signature::outputs(vec![ValueType::Scalar])
            .with_scratch(vec![8 * groups_for(a.words()) as u64]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let a = &inputs[0].as_ref().expect("required").data;
        let mapped: Vec<f64> = match self.kind.map {
            Map::Value => a.clone(),
            Map::Square => a.iter().map(|x| x * x).collect(),
            Map::Product => {
                let b = &inputs[1].as_ref().expect("required").data;
                a.iter().zip(b).map(|(x, y)| x * y).collect()
            }
        };
        let r = self.kind.op.fold(mapped.into_iter());
        outputs[0].data[0] = if self.kind.root { r.sqrt() } else { r };
    }
}

impl GpuKernels for FlatReduce {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let a = io.inputs[0].expect("required");
        let b = io.inputs.get(1).copied().flatten().unwrap_or(a);
        let n = a.ty.words() as u32;
        let groups = groups_for(a.ty.words());
        let map = match self.kind.map {
            Map::Value => 0.0,
            Map::Product => 1.0,
            Map::Square => 2.0,
        };
        let partial = cx.kernel(
            &KernelSpec::new(
                format!("{} partial", self.kind.name),
                cx.shader("reduce/partial.wgsl")?,
                &[
                    Binding::StorageRead,
                    Binding::StorageRead,
                    Binding::StorageRead,
                    Binding::StorageRead,
                    Binding::StorageReadWrite,
                    Binding::Uniform,
                ],
            )
            .constant("OP", self.kind.op.code())
            .constant("MAP", map)
            .constant("COMPENSATED", f64::from(u8::from(self.compensated))),
        )?;
        let last = cx.kernel(
            &KernelSpec::new(
                format!("{} final", self.kind.name),
                cx.shader("reduce/final.wgsl")?,
                &[
                    Binding::StorageRead,
                    Binding::StorageReadWrite,
                    Binding::Uniform,
                ],
            )
            .constant("OP", self.kind.op.code())
            .constant("COMPENSATED", f64::from(u8::from(self.compensated)))
            .constant("ROOT", f64::from(u8::from(self.kind.root))),
        )?;
        let one = 1f32.to_bits();
        let shape1 = cx.uniform("reduce shape", bytemuck::cast_slice(&[n, groups, one]));
        let shape2 = cx.uniform("reduce shape", bytemuck::cast_slice(&[groups, one]));
        let partials = io.scratch[0];
        Ok(vec![
            cx.dispatch(
                &partial,
                &[a.buffer, a.buffer, b.buffer, b.buffer, partials, &shape1],
                [groups, 1, 1],
            ),
            cx.dispatch(&last, &[partials, io.outputs[0].buffer, &shape2], [1, 1, 1]),
        ])
    }
}

/// Per-component reduction over the rows of a particle array.
fn column_reduce_kind() -> NodeKind {
    NodeKind::declare(
        "column_reduce",
        "sum, mean, max or min of each column of a particle array (N x k, k <= 4) -> 1 x k",
    )
    .input(PortSpec::new(
        "x",
        PortType::Particles(None),
        "rows to reduce",
    ))
    .output(PortSpec::new(
        "out",
        PortType::Particles(None),
        "one row: the per-column result",
    ))
    .param(ParamSpec::choice("op", "sum", OPS, "the reduction"))
    .param(compensated_param())
    .build(|p| {
        Ok(Box::new(ColumnReduce {
            op: Op::parse(p.text("op")),
            compensated: p.flag("compensated"),
        }))
    })
}

struct ColumnReduce {
    op: Op,
    compensated: bool,
}

impl Node for ColumnReduce {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let Some(ValueType::Particles { n, k }) = inputs[0] else {
            unreachable!("port type checked")
        };
        if k > 4 {
            return Err(PortError::new(
                "x",
                format!("has {k} columns; column_reduce handles at most 4"),
            ));
        }
        Ok(Signature::outputs(vec![ValueType::Particles { n: 1, k }])
            .with_scratch(vec![32 * groups_for(n as u64 * 4) as u64]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let x = inputs[0].as_ref().expect("required");
        let ValueType::Particles { k, .. } = x.ty else {
            unreachable!()
        };
        for c in 0..k as usize {
            outputs[0].data[c] = self
                .op
                .fold(x.data.iter().skip(c).step_by(k as usize).copied());
        }
    }
}

impl GpuKernels for ColumnReduce {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let x = io.inputs[0].expect("required");
        let ValueType::Particles { n, k } = x.ty else {
            unreachable!()
        };
        let groups = groups_for(n as u64 * 4);
        let (op, mean) = match self.op {
            Op::Mean => (Op::Sum, true),
            o => (o, false),
        };
        let comp = f64::from(u8::from(self.compensated));
        let partial = cx.kernel(
            &KernelSpec::new(
                "column_reduce partial",
                cx.shader("reduce/columns_partial.wgsl")?,
                &[
                    Binding::StorageRead,
                    Binding::StorageReadWrite,
                    Binding::Uniform,
                ],
            )
            .constant("OP", op.code())
            .constant("COMPENSATED", comp)
            .constant("K", k as f64),
        )?;
        let last = cx.kernel(
            &KernelSpec::new(
                "column_reduce final",
                cx.shader("reduce/columns_final.wgsl")?,
                &[
                    Binding::StorageRead,
                    Binding::StorageReadWrite,
                    Binding::Uniform,
                ],
            )
            .constant("OP", op.code())
            .constant("COMPENSATED", comp)
            .constant("MEAN", f64::from(u8::from(mean)))
            .constant("K", k as f64),
        )?;
        let one = 1f32.to_bits();
        let shape = cx.uniform(
            "column_reduce shape",
            bytemuck::cast_slice(&[n, groups, one]),
        );
        let partials = io.scratch[0];
        Ok(vec![
            cx.dispatch(&partial, &[x.buffer, partials, &shape], [groups, 1, 1]),
            cx.dispatch(&last, &[partials, io.outputs[0].buffer, &shape], [1, 1, 1]),
        ])
    }
}

/// Per-segment reduction of rows sorted by segment.
fn segment_reduce_kind() -> NodeKind {
    NodeKind::declare(
        "segment_reduce",
        "sum, mean, max or min of each segment of rows (segment s = rows starts[s] .. starts[s+1], the last ends at N)",
    )
    .input(PortSpec::new(
        "values",
        PortType::Particles(None),
        "rows, sorted by segment",
    ))
    .input(PortSpec::new(
        "starts",
        PortType::Indices,
        "first row of each segment (non-decreasing)",
    ))
    .output(PortSpec::new(
        "out",
        PortType::Particles(None),
        "one row per segment",
    ))
    .param(ParamSpec::choice(
        "op",
        "sum",
        OPS,
        "the reduction (empty segments: 0, or -inf / +inf for max / min)",
    ))
    .param(compensated_param())
    .build(|p| {
        Ok(Box::new(SegmentReduce {
            op: Op::parse(p.text("op")),
            compensated: p.flag("compensated"),
        }))
    })
}

struct SegmentReduce {
    op: Op,
    compensated: bool,
}

fn segment_bounds(starts: &[f64], s: usize, rows: usize) -> (usize, usize) {
    let begin = (starts[s] as usize).min(rows);
    let end = starts
        .get(s + 1)
        .map(|&e| (e as usize).min(rows))
        .unwrap_or(rows);
    (begin, end.max(begin))
}

impl Node for SegmentReduce {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let Some(ValueType::Particles { k, .. }) = inputs[0] else {
            unreachable!("port type checked")
        };
        let Some(ValueType::Indices { n: segments }) = inputs[1] else {
            unreachable!("port type checked")
        };
        Ok(Signature::outputs(vec![ValueType::Particles {
            n: segments,
            k,
        }]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let v = inputs[0].as_ref().expect("required");
        let starts = &inputs[1].as_ref().expect("required").data;
        let ValueType::Particles { n, k } = v.ty else {
            unreachable!()
        };
        let k = k as usize;
        for s in 0..starts.len() {
            let (b, e) = segment_bounds(starts, s, n as usize);
            for c in 0..k {
                outputs[0].data[s * k + c] = self.op.fold((b..e).map(|r| v.data[r * k + c]));
            }
        }
    }
}

impl GpuKernels for SegmentReduce {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let v = io.inputs[0].expect("required");
        let starts = io.inputs[1].expect("required");
        let ValueType::Particles { n, k } = v.ty else {
            unreachable!()
        };
        let ValueType::Indices { n: segments } = starts.ty else {
            unreachable!()
        };
        let kernel = cx.kernel(
            &KernelSpec::new(
                "segment_reduce",
                cx.shader("reduce/segments.wgsl")?,
                &[
                    Binding::StorageRead,
                    Binding::StorageRead,
                    Binding::StorageReadWrite,
                    Binding::Uniform,
                ],
            )
            .constant("OP", self.op.code())
            .constant("COMPENSATED", f64::from(u8::from(self.compensated))),
        )?;
        let one = 1f32.to_bits();
        let shape = cx.uniform(
            "segment shape",
            bytemuck::cast_slice(&[n, k, segments, one]),
        );
        let groups = cx.grid_1d(segments as u64, WG_1D);
        Ok(vec![cx.dispatch(
            &kernel,
            &[v.buffer, starts.buffer, io.outputs[0].buffer, &shape],
            groups,
        )])
    }
}

pub fn register(r: &mut Registry) {
    for row in FLAT {
        r.add(flat_kind(row));
    }
    r.add(column_reduce_kind());
    r.add(segment_reduce_kind());
}
