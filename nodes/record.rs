//! `record`: a trajectory, snapshots of a particle array every few steps, kept on the GPU
//! for the whole run (a persistent output) and read back once at the end.

use crate::gpu::DeviceCaps;
use crate::gpu::{Binding, CompileCtx, CompileError, Dispatch, KernelSpec, NodeIo, WG_1D};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamSpec, PortError, PortSpec, RefCtx, Registry,
    Signature,
};
use crate::value::{PortType, RefArray, ValueType};

fn record_kind() -> NodeKind {
    NodeKind::declare(
        "record",
        "a trajectory: frame j holds x after step (j + 1) * every (frames past the last step stay zero)",
    )
    .input(PortSpec::new(
        "x",
        PortType::RealArray,
        "the array to record (N x k), or a scalar (an observable's time series: frames of 1 x 1)",
    ))
    .output(PortSpec::new("out", PortType::Frames, "the frames (F x N x k)").persistent())
    .param(ParamSpec::integer(
        "every",
        Some(1.0),
        1.0,
        u32::MAX as f64,
        "steps between frames",
    ))
    .param(ParamSpec::integer(
        "frames",
        None,
        1.0,
        u32::MAX as f64,
        "number of frames; graphs usually pass \"= floor(steps / every)\"",
    ))
    .build(|p| {
        Ok(Box::new(Record {
            every: p.number("every") as u32,
            frames: p.number("frames") as u32,
        }))
    })
}

struct Record {
    every: u32,
    frames: u32,
}

impl Node for Record {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let (n, k) = match inputs[0] {
            Some(ValueType::Particles { n, k }) => (n, k),
            Some(ValueType::Scalar) => (1, 1),
            Some(other) => {
                return Err(PortError::new(
                    "x",
                    format!("records particle arrays and scalars, got {other}"),
                ));
            }
            None => unreachable!("a required port"),
        };
        let out = ValueType::Frames {
            frames: self.frames,
            n,
            k,
        };
        if out.words() > u32::MAX as u64 {
            return Err(PortError::new(
                "x",
                format!("{out} is more than 2^32 values; record fewer frames"),
            ));
        }
        Ok(Signature::outputs(vec![out]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn notes(&self, inputs: &[Option<ValueType>]) -> Vec<String> {
        let _ = inputs;
        vec![format!(
            "{} frames, one every {} steps",
            self.frames, self.every
        )]
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], cx: RefCtx) {
        let Some(x) = &inputs[0] else { return };
        let done = cx.step + 1;
        if !done.is_multiple_of(self.every as u64) {
            return;
        }
        let frame = (done / self.every as u64 - 1) as usize;
        if frame < self.frames as usize {
            let len = x.data.len();
            outputs[0].data[frame * len..(frame + 1) * len].copy_from_slice(&x.data);
        }
    }
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Shape {
    len: u32,
    every: u32,
    frames: u32,
    pad: u32,
}

impl GpuKernels for Record {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let input = io.inputs[0]
            .ok_or_else(|| CompileError::Unsupported("record needs its input".into()))?;
        let len = input.ty.words();
        let kernel = cx.kernel(&KernelSpec::new(
            "record frame",
            cx.shader("record/frame.wgsl")?,
            &[
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::Uniform,
                Binding::StorageRead,
            ],
        ))?;
        let shape = cx.uniform(
            "record shape",
            bytemuck::bytes_of(&Shape {
                len: len as u32,
                every: self.every,
                frames: self.frames,
                pad: 0,
            }),
        );
        Ok(vec![cx.dispatch(
            &kernel,
            &[input.buffer, io.outputs[0].buffer, &shape, cx.clock],
            cx.grid_1d(len, WG_1D),
        )])
    }
}

pub fn register(r: &mut Registry) {
    r.add(record_kind());
}
