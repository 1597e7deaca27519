//! `mpcd_stream_bin`: `mpcd_stream` then `mpcd_bin` in one kernel (shaders/mpcd/
//! stream_bin.wgsl). Each particle is streamed, written out and binned from the values in
//! registers, so the binning does not read positions and velocities again (24 of the
//! about 107 bytes a 3D particle-step moves) and the step has one launch fewer. The same
//! arithmetic as the two nodes (tested bitwise against them).
//!
//! With `sort_every` K > 0, steps 0, K, 2K, ... also reorder the particles by cell: the
//! streamed particles and their cells go to scratch (`stream_cell`), a stable radix sort
//! orders the cells, and `gather_bin` writes the particles in cell order and bins them. The
//! other steps run the fused kernel. Particles move about 0.1 cell a step, so for some
//! steps after a reordering the binning and the collision touch the cell sums nearly in
//! order (coherent atomics and reads where the sums outgrow the cache). Every step is
//! complete in itself (the schedule is `Period` on the node's dispatches), and the results
//! are those of the unsorted node up to the order of the particles.

use super::collide::{MpcdBin, mpcd_bin_kind};
use super::particle_ports;
use super::stream::{MpcdStream, mpcd_stream_kind};
use crate::gpu::DeviceCaps;
use crate::gpu::{
    Binding, CompileCtx, CompileError, Dispatch, KernelSpec, NodeIo, Period, Slot, WG_1D,
};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamSpec, PortError, RefCtx, RowError, Signature,
};
use crate::nodes::sort::SortNode;
use crate::value::{HostArray, RefArray, ValueType};

pub(super) fn mpcd_stream_bin_kind() -> NodeKind {
    let (stream, bin) = (mpcd_stream_kind(), mpcd_bin_kind());
    // The params of both kinds, once each where they share one.
    let mut params = stream.params().to_vec();
    for q in bin.params() {
        if !params.iter().any(|e| e.name == q.name) {
            params.push(q.clone());
        }
    }
    NodeKind::declare(
        "mpcd_stream_bin",
        "MPCD streaming then binning in one kernel: mpcd_stream's outputs (positions, velocities) and mpcd_bin's (cell, sums) of the streamed particles, with the params of both",
    )
    .inputs(particle_ports())
    .outputs(stream.outputs().iter().chain(bin.outputs()).cloned())
    .params(params)
    .param(ParamSpec::integer(
        "sort_every",
        Some(0.0),
        0.0,
        u32::MAX as f64,
        "reorder the particles by cell on steps 0, K, 2K, ... (stable sort of the cells; outputs in cell order); 0: never",
    ))
    .build(|p| {
        let bin = MpcdBin::from_params(p)?;
        let bits = (bin.layout().ncells as f64).log2().ceil().max(1.0) as u32;
        Ok(Box::new(MpcdStreamBin {
            stream: MpcdStream::from_params(p)?,
            bin,
            sort_every: p.number("sort_every") as u64,
            sorter: SortNode::radix(bits),
        }))
    })
}

struct MpcdStreamBin {
    stream: MpcdStream,
    bin: MpcdBin,
    /// 0: never reorder.
    sort_every: u64,
    sorter: SortNode,
}

impl Node for MpcdStreamBin {
    fn infer(
        &self,
        inputs: &[Option<ValueType>],
        caps: &DeviceCaps,
    ) -> Result<Signature, PortError> {
        let moved = self.stream.infer(inputs, caps)?.outputs;
        let binned = self
            .bin
            .infer(&[Some(moved[0]), Some(moved[1])], caps)?
            .outputs;
        let mut sig = Signature::outputs(vec![moved[0], moved[1], binned[0], binned[1]]);
        if self.sort_every > 0 {
            reorder_scratch(&mut sig, &self.sorter, moved[0], moved[1], binned[0], caps)?;
        }
        Ok(sig)
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn checks_input(&self) -> bool {
        true
    }

    fn check_input(&self, port: usize, data: &HostArray) -> Result<(), RowError> {
        // The positions as the streaming takes them, the velocities as the binning sums
        // them (in the fixed point's range).
        match port {
            0 => self.stream.check_input(port, data),
            _ => self.bin.check_input(port, data),
        }
    }

    fn notes(&self, inputs: &[Option<ValueType>]) -> Vec<String> {
        self.bin.notes(inputs)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], cx: RefCtx) {
        let (moved, binned) = outputs.split_at_mut(2);
        self.stream.cpu_reference(inputs, moved, cx);
        let streamed = [Some(moved[0].clone()), Some(moved[1].clone())];
        self.bin.cpu_reference(&streamed, binned, cx);
    }
}

impl GpuKernels for MpcdStreamBin {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let pos = io.inputs[0].expect("required");
        let vel = io.inputs[1].expect("required");
        let ValueType::Particles { n, .. } = pos.ty else {
            unreachable!()
        };
        let mut u = self.bin.uniform();
        u.n = n;
        self.stream.uniform_into(&mut u);
        let (label, source) = self.bin.source(cx, "mpcd/stream_bin.wgsl")?;
        let bindings = [
            Binding::Uniform,
            Binding::StorageRead,
            Binding::StorageRead,
            Binding::StorageRead,
            Binding::StorageReadWrite,
            Binding::StorageReadWrite,
            Binding::StorageReadWrite,
            Binding::StorageReadWrite,
            Binding::StorageRead,
            Binding::StorageRead,
        ];
        let dims = self.bin.dims() as f64;
        let spec = |entry: &str| {
            KernelSpec::new(format!("{label} {entry}"), source.clone(), &bindings)
                .entry(entry)
                .constant("DIMS", dims)
        };
        let fused = cx.kernel(&spec("main"))?;
        let params = cx.uniform("mpcd stream bin", bytemuck::bytes_of(&u));
        let (x, v, cell, sums) = (
            io.outputs[0].buffer,
            io.outputs[1].buffer,
            io.outputs[2].buffer,
            io.outputs[3].buffer,
        );
        let grid = cx.grid_1d(n as u64, WG_1D);
        // Bindings 8 and 9 (permutation, sorted cells) are read by gather_bin only; the
        // other entry points get a read-only stand-in.
        let main = cx.dispatch(
            &fused,
            &[
                &params, cx.clock, pos.buffer, vel.buffer, cell, sums, x, v, pos.buffer, pos.buffer,
            ],
            grid,
        );
        let mut out = vec![cx.fill(sums, io.outputs[3].ty.words(), 0)?];
        if self.sort_every == 0 {
            out.push(main);
            return Ok(out);
        }
        let missing = || CompileError::Unsupported("mpcd_stream_bin: scratch missing".into());
        let [xt, vt, ct, sorted, perm, sort_scratch @ ..] = io.scratch.as_slice() else {
            return Err(missing());
        };
        let stream_cell = cx.kernel(&spec("stream_cell"))?;
        let gather_bin = cx.kernel(&spec("gather_bin"))?;
        let on = Period {
            every: self.sort_every,
            on: true,
        };
        out.push(
            cx.dispatch(
                &stream_cell,
                &[
                    &params, cx.clock, pos.buffer, vel.buffer, ct, sums, xt, vt, pos.buffer,
                    pos.buffer,
                ],
                grid,
            )
            .on_steps(on),
        );
        let cells = io.outputs[2].ty;
        let sort = [*ct, *sorted, *perm];
        out.extend(sort_cells(
            cx,
            &self.sorter,
            io,
            cells,
            sort,
            sort_scratch,
            on,
        )?);
        out.push(
            cx.dispatch(
                &gather_bin,
                &[&params, cx.clock, xt, vt, cell, sums, x, v, perm, sorted],
                grid,
            )
            .on_steps(on),
        );
        out.push(main.on_steps(Period { on: false, ..on }));
        Ok(out)
    }
}

/// The scratch of a node that reorders particles by cell every few steps (mpcd_stream_bin,
/// mpcd_stream_spheres), after its outputs in `sig`: streamed positions and velocities,
/// cells, sorted cells, permutation, then the sort's own scratch. The sorter's decision, if
/// it takes one, is the node's: its compile gets it.
pub(super) fn reorder_scratch(
    sig: &mut Signature,
    sorter: &SortNode,
    positions: ValueType,
    velocities: ValueType,
    cells: ValueType,
    caps: &DeviceCaps,
) -> Result<(), PortError> {
    sig.scratch = vec![
        positions.bytes(),
        velocities.bytes(),
        cells.bytes(),
        cells.bytes(),
        cells.bytes(),
    ];
    let sorted = sorter.infer(&[Some(cells)], caps)?;
    sig.scratch.extend(sorted.scratch);
    sig.plan = sorted.plan;
    Ok(())
}

/// The stable sort of the cells `[cells, sorted, permutation]` (scratch of
/// [`reorder_scratch`]) on the steps `on`.
pub(super) fn sort_cells(
    cx: &mut CompileCtx<'_>,
    sorter: &SortNode,
    io: &NodeIo<'_>,
    ty: ValueType,
    [cells, sorted, perm]: [&wgpu::Buffer; 3],
    sort_scratch: &[&wgpu::Buffer],
    on: Period,
) -> Result<Vec<Dispatch>, CompileError> {
    let slot = |buffer| Slot { buffer, ty };
    let sort_io = NodeIo {
        inputs: vec![Some(slot(cells))],
        outputs: vec![slot(sorted), slot(perm)],
        scratch: sort_scratch.to_vec(),
        plan: io.plan,
    };
    Ok(sorter
        .compile(cx, &sort_io)?
        .into_iter()
        .map(|d| d.on_steps(on))
        .collect())
}
