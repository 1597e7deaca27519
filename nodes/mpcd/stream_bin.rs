//! `mpcd_stream_bin`: `mpcd_stream` then `mpcd_bin` in one kernel (shaders/mpcd/
//! stream_bin.wgsl). Each particle is streamed, written out and binned from the values in
//! registers, so the binning does not read positions and velocities again (24 of the
//! about 107 bytes a 3D particle-step moves) and the step has one launch fewer. The same
//! arithmetic as the two nodes (tested bitwise against them).

use super::collide::{MpcdBin, MpcdBinKind};
use super::particle_ports;
use super::stream::{MpcdStream, MpcdStreamKind};
use crate::gpu::{Binding, CompileCtx, CompileError, Dispatch, KernelSpec, NodeIo, WG_1D};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamSpec, Params, PortError, PortSpec, RefCtx, Signature,
};
use crate::value::{RefArray, ValueType};

pub struct MpcdStreamBinKind;

impl NodeKind for MpcdStreamBinKind {
    fn name(&self) -> &'static str {
        "mpcd_stream_bin"
    }

    fn doc(&self) -> &'static str {
        "MPCD streaming then binning in one kernel: mpcd_stream's outputs (positions, velocities) and mpcd_bin's (cell, sums) of the streamed particles, with the params of both"
    }

    fn inputs(&self) -> Vec<PortSpec> {
        particle_ports()
    }

    fn outputs(&self) -> Vec<PortSpec> {
        let mut out = MpcdStreamKind.outputs();
        out.extend(MpcdBinKind.outputs());
        out
    }

    fn params(&self) -> Vec<ParamSpec> {
        let mut p = MpcdStreamKind.params();
        for q in MpcdBinKind.params() {
            if !p.iter().any(|e| e.name == q.name) {
                p.push(q);
            }
        }
        p
    }

    fn build(&self, p: &Params) -> Result<Box<dyn Node>, String> {
        Ok(Box::new(MpcdStreamBin {
            stream: MpcdStream::from_params(p)?,
            bin: MpcdBin::from_params(p)?,
        }))
    }
}

struct MpcdStreamBin {
    stream: MpcdStream,
    bin: MpcdBin,
}

impl Node for MpcdStreamBin {
    fn infer(&self, inputs: &[Option<ValueType>]) -> Result<Signature, PortError> {
        let moved = self.stream.infer(inputs)?.outputs;
        let binned = self.bin.infer(&[Some(moved[0]), Some(moved[1])])?.outputs;
        Ok(Signature::outputs(vec![
            moved[0], moved[1], binned[0], binned[1],
        ]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
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
        let kernel = cx.kernel(
            &KernelSpec::new(
                label,
                source,
                &[
                    Binding::Uniform,
                    Binding::StorageRead,
                    Binding::StorageRead,
                    Binding::StorageRead,
                    Binding::StorageReadWrite,
                    Binding::StorageReadWrite,
                    Binding::StorageReadWrite,
                    Binding::StorageReadWrite,
                ],
            )
            .constant("DIMS", self.bin.dims() as f64),
        )?;
        let params = cx.uniform("mpcd stream bin", bytemuck::bytes_of(&u));
        let sums = io.outputs[3].buffer;
        Ok(vec![
            cx.fill(sums, io.outputs[3].ty.words(), 0)?,
            cx.dispatch(
                &kernel,
                &[
                    &params,
                    cx.clock,
                    pos.buffer,
                    vel.buffer,
                    io.outputs[2].buffer,
                    sums,
                    io.outputs[0].buffer,
                    io.outputs[1].buffer,
                ],
                cx.grid_1d(n as u64, WG_1D),
            ),
        ])
    }
}
