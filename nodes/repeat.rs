//! `repeat`: a loop of a fixed number of iterations, x_(k+1) = body(x_k), for values a
//! step advances several times (a molecular-dynamics step repeated between two MPCD
//! collisions, a relaxation sweep). The body is any nodes that read the node's `current`
//! output and end in its `next` input, as for `lanczos`; unlike Lanczos, the count is
//! known when the program is compiled, so the executor records the iterations one after
//! the other within the step (no host round trip, steps batched as in a loop-free
//! program). Several values ride together as columns of one array (`concat`, `columns`).
//!
//! GPU: copies only (shaders/engine/copy.wgsl): `initial` into `current` before the first
//! iteration, `next` into `current` after each, `current` into `out` after the last.

use crate::gpu::DeviceCaps;
use crate::gpu::{Binding, CompileCtx, CompileError, KernelSpec, NodeIo};
use crate::node::{
    Decision, GpuIterative, IterativeKernels, LoopError, Lowering, Node, NodeKind, ParamSpec,
    PortError, PortSpec, RefCtx, Registry, Signature,
};
use crate::value::{PortType, RefArray, ValueType};

const WG: u32 = 256;

/// The most iterations a step may unroll (each is the body's dispatches once more).
pub const MAX_REPEAT: f64 = 10_000.0;

fn repeat_kind() -> NodeKind {
    NodeKind::declare(
        "repeat",
        "x_(k+1) = body(x_k), `count` times within a step: the loop body reads `current` (x_k) and ends in `next` (x_(k+1)); `out` is x_count. Carry several values as columns of one array. The body sees the same step counter in every iteration (random draws keyed on the step repeat)",
    )
    .input(PortSpec::new(
        "initial",
        PortType::Particles(None),
        "x_0",
    ))
    .input(
        PortSpec::new(
            "next",
            PortType::Particles(None),
            "body(x_k): the loop body's result for the current value",
        )
        .iterate(),
    )
    .output(PortSpec::new(
        "out",
        PortType::Particles(None),
        "x_count, after the last iteration",
    ))
    .output(
        PortSpec::new(
            "current",
            PortType::Particles(None),
            "x_k, the current value: the loop body computes x_(k+1) from it",
        )
        .iterate(),
    )
    .param(ParamSpec::integer(
        "count",
        None,
        1.0,
        MAX_REPEAT,
        "iterations per step (each records the body's dispatches once more)",
    ))
    .build(|p| {
        Ok(Box::new(Repeat {
            count: p.number("count") as u32,
        }))
    })
}

pub struct Repeat {
    count: u32,
}

impl Node for Repeat {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let x = inputs[0].expect("required");
        if let Some(next) = inputs[1]
            && next != x
        {
            return Err(PortError::new(
                "next",
                format!(
                    "is {next} but initial is {x}: the loop body must give a value of the shape it reads"
                ),
            ));
        }
        // One word the executor's loop protocol asks for (status and answer); unread.
        Ok(Signature::outputs(vec![x, x]).with_scratch(vec![4]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Iterative(self)
    }

    fn notes(&self, _: &[Option<ValueType>]) -> Vec<String> {
        vec![format!(
            "{} iterations per step, recorded one after the other (no host round trip)",
            self.count
        )]
    }

    /// There is no reference for the node alone: the body is the loop's. The tests run
    /// graphs against f64 recurrences; this fills NaN so that nothing can mistake it for
    /// a result.
    fn cpu_reference(&self, _: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        for o in outputs {
            o.data.fill(f64::NAN);
        }
    }
}

impl GpuIterative for Repeat {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<IterativeKernels, CompileError> {
        let initial = io.inputs[0].expect("required");
        let next = io.inputs[1].expect("the planner connects the loop");
        let words = initial.ty.words();
        let kernel = cx.kernel(&KernelSpec::new(
            "repeat copy",
            cx.shader("engine/copy.wgsl")?,
            &[
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::Uniform,
            ],
        ))?;
        let shape = cx.uniform("repeat shape", bytemuck::bytes_of(&(words as u32)));
        let groups = cx.grid_1d(words, WG);
        let (out, value) = (io.outputs[0].buffer, io.outputs[1].buffer);
        let copy = |cx: &mut CompileCtx<'_>, src: &wgpu::Buffer, dst: &wgpu::Buffer| {
            cx.dispatch(&kernel, &[src, dst, &shape], groups)
        };
        let start = vec![copy(cx, initial.buffer, value)];
        let iterate = vec![copy(cx, next.buffer, value)];
        let finish = vec![copy(cx, value, out)];
        let small = io.scratch[0];
        Ok(IterativeKernels {
            start,
            iterate,
            finish,
            status: small.clone(),
            status_bytes: 4,
            answer: small.clone(),
            answer_offset: 0,
        })
    }

    fn fixed_iterations(&self) -> Option<u32> {
        Some(self.count)
    }

    fn decide(&self, iterations: usize, _: &[u8]) -> Result<Decision, LoopError> {
        // Only asked where the executor runs loops with host decisions.
        Ok(if iterations >= self.count as usize {
            Decision::Finish(Vec::new())
        } else {
            Decision::Continue
        })
    }
}

pub fn register(r: &mut Registry) {
    r.add(repeat_kind());
}
