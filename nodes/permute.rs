//! Gather and scatter of rows by index, so any particle array can follow a permutation
//! (the `perm` of a sort: `gather(values, perm)` reorders, `scatter(values, perm)` undoes).
//! Rows are copied as raw 4-byte words, so f32 particle arrays and u32 index arrays alike.
//! `columns` and `concat` take columns apart and put them together (forces and torques
//! as one N x 6 array for a grand mobility, and its result back as two N x 3 arrays).
//! `invert_permutation` and `relabel` renumber what refers to rows by id: a sort's perm
//! inverted (where each row went), and ids stored in an array (a mesh's vertices) renamed
//! through a lookup table, so that a mesh follows its points into a new order and back
//! (graphs/bd_delaunay.json numbers its disks in a Morton order of its own).

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

/// The dispatch of the kernel `shaders/permute/{name}.wgsl` over `threads` items of a
/// 1-D grid. The kernels of these nodes all bind alike, so one function builds each: the
/// inputs read-only in order, then the one output the kernel writes, then a uniform of
/// u32 sizes (`shape`, labelled `{name} shape`).
fn permute_pass(
    cx: &mut CompileCtx<'_>,
    name: &str,
    inputs: &[&wgpu::Buffer],
    out: &wgpu::Buffer,
    shape: &[u32],
    threads: u64,
) -> Result<Dispatch, CompileError> {
    let mut bindings = vec![Binding::StorageRead; inputs.len()];
    bindings.extend([Binding::StorageReadWrite, Binding::Uniform]);
    let kernel = cx.kernel(&KernelSpec::new(
        name,
        cx.shader(&format!("permute/{name}.wgsl"))?,
        &bindings,
    ))?;
    let shape = cx.uniform(&format!("{name} shape"), bytemuck::cast_slice(shape));
    let mut buffers = inputs.to_vec();
    buffers.extend([out, &shape]);
    Ok(cx.dispatch(&kernel, &buffers, cx.grid_1d(threads, WG_1D)))
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

    fn passes_rows(&self, port: usize) -> Option<usize> {
        (port == 0).then_some(0)
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
        Ok(vec![permute_pass(
            cx,
            "gather",
            &[values.buffer, index.buffer],
            io.outputs[0].buffer,
            &[out_rows, in_rows, k],
            out_rows as u64 * k as u64,
        )?])
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
        let mut out_dispatches = Vec::new();
        if !self.permutation {
            out_dispatches.push(cx.fill(out.buffer, out.ty.words(), 0)?);
        }
        out_dispatches.push(permute_pass(
            cx,
            "scatter",
            &[values.buffer, index.buffer],
            out.buffer,
            &[in_rows, out_rows, k],
            in_rows as u64 * k as u64,
        )?);
        Ok(out_dispatches)
    }
}

/// Dispatches copying `count` columns of every row from `x` (starting at `in_first`) to
/// `out` (starting at `out_first`).
#[allow(clippy::too_many_arguments)]
fn copy_columns(
    cx: &mut CompileCtx<'_>,
    x: &wgpu::Buffer,
    out: &wgpu::Buffer,
    rows: u32,
    in_cols: u32,
    out_cols: u32,
    in_first: u32,
    out_first: u32,
    count: u32,
) -> Result<Dispatch, CompileError> {
    permute_pass(
        cx,
        "columns",
        &[x],
        out,
        &[rows, in_cols, out_cols, in_first, out_first, count],
        rows as u64 * count as u64,
    )
}

fn columns_kind() -> NodeKind {
    NodeKind::declare(
        "columns",
        "out = columns first .. first + count of x, row by row (N x count)",
    )
    .input(PortSpec::new(
        "x",
        PortType::Particles(None),
        "the rows (N x k)",
    ))
    .output(PortSpec::new(
        "out",
        PortType::Particles(None),
        "the columns taken (N x count)",
    ))
    .param(ParamSpec::integer(
        "first",
        Some(0.0),
        0.0,
        1024.0,
        "the first column taken",
    ))
    .param(ParamSpec::integer(
        "count",
        None,
        1.0,
        1024.0,
        "how many columns",
    ))
    .build(|p| {
        Ok(Box::new(Columns {
            first: p.number("first") as u32,
            count: p.number("count") as u32,
        }))
    })
}

struct Columns {
    first: u32,
    count: u32,
}

impl Node for Columns {
    fn forwards(&self, inputs: &[Option<ValueType>]) -> Option<usize> {
        match inputs[0] {
            Some(ValueType::Particles { k, .. }) if self.first == 0 && self.count == k => Some(0),
            _ => None,
        }
    }

    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let Some(ValueType::Particles { n, k }) = inputs[0] else {
            unreachable!("port type checked")
        };
        if self.first + self.count > k {
            return Err(PortError::new(
                "x",
                format!(
                    "has {k} columns; columns {} to {} were asked for",
                    self.first,
                    self.first + self.count - 1
                ),
            ));
        }
        Ok(Signature::outputs(vec![ValueType::Particles {
            n,
            k: self.count,
        }]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let x = inputs[0].as_ref().expect("required");
        let (n, k) = rows_of(x.ty);
        let (first, count) = (self.first as usize, self.count as usize);
        for i in 0..n as usize {
            for c in 0..count {
                outputs[0].data[i * count + c] = x.data[i * k as usize + first + c];
            }
        }
    }
}

impl GpuKernels for Columns {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let x = io.inputs[0].expect("required");
        let (n, k) = rows_of(x.ty);
        Ok(vec![copy_columns(
            cx,
            x.buffer,
            io.outputs[0].buffer,
            n,
            k,
            self.count,
            self.first,
            0,
            self.count,
        )?])
    }
}

fn concat_kind() -> NodeKind {
    NodeKind::declare(
        "concat",
        "out = [a | b] row by row (N x (ka + kb)); without b, a followed by zero columns up to `cols` (forces with no torques as the N x 6 of a grand mobility)",
    )
    .input(PortSpec::new("a", PortType::Particles(None), "the first columns (N x ka)"))
    .input(
        PortSpec::new("b", PortType::Particles(None), "the next columns (N x kb)").optional(),
    )
    .output(PortSpec::new("out", PortType::Particles(None), "the rows side by side"))
    .param(ParamSpec::integer(
        "cols",
        Some(0.0),
        0.0,
        1024.0,
        "columns of the output: 0 for ka + kb (ka without b); with b it must be 0 or ka + kb; without b, the columns past a are zero",
    ))
    .build(|p| {
        Ok(Box::new(Concat {
            cols: p.number("cols") as u32,
        }))
    })
}

struct Concat {
    cols: u32,
}

impl Concat {
    fn out_cols(&self, ka: u32, kb: Option<u32>) -> u32 {
        match (self.cols, kb) {
            (0, Some(kb)) => ka + kb,
            (0, None) => ka,
            (c, _) => c,
        }
    }
}

impl Node for Concat {
    fn forwards(&self, inputs: &[Option<ValueType>]) -> Option<usize> {
        match (inputs[0], inputs[1]) {
            (Some(ValueType::Particles { k, .. }), None) if self.out_cols(k, None) == k => Some(0),
            _ => None,
        }
    }

    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let Some(ValueType::Particles { n, k: ka }) = inputs[0] else {
            unreachable!("port type checked")
        };
        let kb = match inputs[1] {
            Some(ValueType::Particles { n: m, k }) => {
                if m != n {
                    return Err(PortError::new("b", format!("has {m} rows but a has {n}")));
                }
                Some(k)
            }
            _ => None,
        };
        let cols = self.out_cols(ka, kb);
        if let Some(kb) = kb
            && cols != ka + kb
        {
            return Err(PortError::new(
                "b",
                format!("a has {ka} columns and b {kb}: `cols` {cols} is neither 0 nor their sum"),
            ));
        }
        if cols < ka {
            return Err(PortError::new(
                "a",
                format!("has {ka} columns, more than `cols` {cols}"),
            ));
        }
        Ok(Signature::outputs(vec![ValueType::Particles {
            n,
            k: cols,
        }]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let a = inputs[0].as_ref().expect("required");
        let (n, ka) = rows_of(a.ty);
        let (_, cols) = rows_of(outputs[0].ty);
        let (ka, cols) = (ka as usize, cols as usize);
        outputs[0].data.fill(0.0);
        for i in 0..n as usize {
            outputs[0].data[i * cols..i * cols + ka].copy_from_slice(&a.data[i * ka..(i + 1) * ka]);
            if let Some(b) = &inputs[1] {
                let kb = cols - ka;
                outputs[0].data[i * cols + ka..(i + 1) * cols]
                    .copy_from_slice(&b.data[i * kb..(i + 1) * kb]);
            }
        }
    }
}

impl GpuKernels for Concat {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let a = io.inputs[0].expect("required");
        let out = io.outputs[0];
        let (n, ka) = rows_of(a.ty);
        let (_, cols) = rows_of(out.ty);
        let mut dispatches = Vec::new();
        match io.inputs[1] {
            Some(b) => {
                let (_, kb) = rows_of(b.ty);
                dispatches.push(copy_columns(
                    cx, a.buffer, out.buffer, n, ka, cols, 0, 0, ka,
                )?);
                dispatches.push(copy_columns(
                    cx, b.buffer, out.buffer, n, kb, cols, 0, ka, kb,
                )?);
            }
            None => {
                dispatches.push(cx.fill(out.buffer, out.ty.words(), 0)?);
                dispatches.push(copy_columns(
                    cx, a.buffer, out.buffer, n, ka, cols, 0, 0, ka,
                )?);
            }
        }
        Ok(dispatches)
    }
}

fn invert_permutation_kind() -> NodeKind {
    NodeKind::declare(
        "invert_permutation",
        "out[index[i]] = i: the inverse of a permutation (for a sort's perm, where each input row went: its slot in the sorted order); entries no index points at hold 4294967295 (u32::MAX), indices past the end are skipped, with repeated indices the winner is unspecified",
    )
    .input(PortSpec::new(
        "index",
        PortType::Indices,
        "a permutation of 0 .. N (a sort's perm: the input row of each sorted slot)",
    ))
    .output(PortSpec::new(
        "out",
        PortType::Indices,
        "the inverse permutation (N words)",
    ))
    .build(|_| Ok(Box::new(InvertPermutation)))
}

struct InvertPermutation;

impl Node for InvertPermutation {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let index = inputs[0].expect("required");
        Ok(Signature::outputs(vec![index]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let index = &inputs[0].as_ref().expect("required").data;
        let n = index.len();
        outputs[0].data.fill(u32::MAX as f64);
        for (i, &dst) in index.iter().enumerate() {
            if dst < n as f64 {
                outputs[0].data[dst as usize] = i as f64;
            }
        }
    }
}

impl GpuKernels for InvertPermutation {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let index = io.inputs[0].expect("required");
        let out = io.outputs[0];
        let n = out.ty.words();
        Ok(vec![
            cx.fill(out.buffer, n, u32::MAX)?,
            permute_pass(
                cx,
                "invert_permutation",
                &[index.buffer],
                out.buffer,
                &[n as u32],
                n,
            )?,
        ])
    }
}

fn relabel_kind() -> NodeKind {
    NodeKind::declare(
        "relabel",
        "out = x with the ids it holds renamed through a lookup table: in every row of `stride` words, each word w of columns first .. first + count becomes table[w] when w is below the table's length (ids past it, such as a u32::MAX sentinel, are kept), every other word is copied; a mesh's vertex ids follow its points into a new order (table: the inverse of the sort's perm, from invert_permutation) and back (table: the perm)",
    )
    .input(PortSpec::new(
        "x",
        PortType::Indices,
        "the words holding ids (a multiple of `stride`)",
    ))
    .input(PortSpec::new(
        "table",
        PortType::Indices,
        "the new id of each old id: new = table[old]",
    ))
    .output(PortSpec::new(
        "out",
        PortType::Indices,
        "x with the ids renamed (as many words)",
    ))
    .param(ParamSpec::integer(
        "stride",
        Some(1.0),
        1.0,
        1024.0,
        "words per row of x (a mesh of nodes/disks/mesh.rs: 6 per triangle)",
    ))
    .param(ParamSpec::integer(
        "first",
        Some(0.0),
        0.0,
        1023.0,
        "the first column of a row holding ids (below stride)",
    ))
    .param(ParamSpec::integer(
        "count",
        Some(0.0),
        0.0,
        1024.0,
        "how many columns from `first` hold ids (0: every column from `first` to the row's end; the mesh: 3, its vertices, not its twin slots)",
    ))
    .param(ParamSpec::flag(
        "permutation",
        false,
        "the graph guarantees that the table is a permutation of 0 .. its length (a sort's perm or its inverse): ids are renamed one to one, so the checks of the nodes reading the output (a mesh's twins) apply to the data given for x, as behind a gather (Node::passes_rows)",
    ))
    .build(|p| {
        let stride = p.number("stride") as u32;
        let first = p.number("first") as u32;
        let count = p.number("count") as u32;
        if first >= stride {
            return Err(format!(
                "`first` {first} must be below `stride` {stride}: a column of the row"
            ));
        }
        let count = if count == 0 { stride - first } else { count };
        if first + count > stride {
            return Err(format!(
                "columns {first} to {} do not fit a row of {stride} words",
                first + count - 1
            ));
        }
        Ok(Box::new(Relabel {
            stride,
            first,
            count,
            permutation: p.flag("permutation"),
        }))
    })
}

struct Relabel {
    stride: u32,
    first: u32,
    count: u32,
    permutation: bool,
}

impl Relabel {
    /// Whether word `w` of x lies in a column holding ids.
    fn holds_id(&self, w: usize) -> bool {
        let col = (w % self.stride as usize) as u32;
        col >= self.first && col < self.first + self.count
    }
}

impl Node for Relabel {
    fn passes_rows(&self, port: usize) -> Option<usize> {
        (self.permutation && port == 0).then_some(0)
    }

    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let Some(x @ ValueType::Indices { n }) = inputs[0] else {
            unreachable!("port type checked")
        };
        if !n.is_multiple_of(self.stride) {
            return Err(PortError::new(
                "x",
                format!(
                    "has {n} words, not a whole number of rows of `stride` {} words",
                    self.stride
                ),
            ));
        }
        Ok(Signature::outputs(vec![x]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let x = &inputs[0].as_ref().expect("required").data;
        let table = &inputs[1].as_ref().expect("required").data;
        for (w, (&v, o)) in x.iter().zip(outputs[0].data.iter_mut()).enumerate() {
            *o = if self.holds_id(w) && v < table.len() as f64 {
                table[v as usize]
            } else {
                v
            };
        }
    }
}

impl GpuKernels for Relabel {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let x = io.inputs[0].expect("required");
        let table = io.inputs[1].expect("required");
        let words = x.ty.words();
        Ok(vec![permute_pass(
            cx,
            "relabel",
            &[x.buffer, table.buffer],
            io.outputs[0].buffer,
            &[
                words as u32,
                self.stride,
                self.first,
                self.count,
                table.ty.words() as u32,
            ],
            words,
        )?])
    }
}

pub fn register(r: &mut Registry) {
    r.add(gather_kind());
    r.add(scatter_kind());
    r.add(columns_kind());
    r.add(concat_kind());
    r.add(invert_permutation_kind());
    r.add(relabel_kind());
}
