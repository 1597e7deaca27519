//! `repeat`: a loop that carries one value through its loop body until the body's u32
//! count is zero, or for a fixed number of iterations: the general form of the
//! convergence loops of S1 (edge-flip rounds carrying the mesh until no edge flips,
//! overlap-correction rounds carrying the positions until no pair overlaps) and of steps
//! repeated within a step (MD substeps between two MPCD collisions; several values ride
//! as columns of one array, `concat` and `columns`).
//!
//! The loop body is every node that depends on the `current` output and leads to the
//! `next` and `count` inputs (`Lowering::Iterative`, as `lanczos`); it may read values
//! from outside (the flips read the positions). The GPU copies `initial` to `current` at
//! the start and `current` to `out` at the finish, and per iteration `next` to `current`,
//! each unless the plan gave the two one buffer: a pooled `initial` nothing reads after
//! the loop starts (`PortSpec::started_from`: settle's mesh, flips.out, in
//! bd_delaunay.json), a `current` nothing reads after the loop (`PortSpec::final_of`,
//! `out` then where `current` lies, or `current` where `out` has a buffer of its own, a
//! state's next value), a body node that writes `next` in place of `current`
//! (`PortSpec::refilled_from`, as the flip loops' `edge_flip_round`). It tallies the
//! count (`shaders/repeat/repeat.wgsl`), and decides the stop itself (a zero count, or
//! `max_iterations` reached): the executor runs batches of iterations and reads the
//! status once per batch (one host round trip for a loop that takes as many iterations
//! as at its last run, see `exec/run.rs`); the iterations of a batch past the stop
//! change nothing.
//! A `fixed` count is known when the program is compiled (`fixed_iterations`): the
//! iterations are recorded one after the other within the step, no status read, and the
//! steps batch as in a loop-free program. The body sees the same step counter in every
//! iteration: random draws keyed on the step repeat across its iterations.

use crate::gpu::DeviceCaps;
use crate::gpu::{Binding, CompileCtx, CompileError, KernelSpec, NodeIo, WG_1D};
use crate::node::{
    Decision, GpuIterative, GpuStop, IterativeKernels, LoopError, Lowering, Node, NodeKind,
    ParamSpec, PortError, PortSpec, RefCtx, Registry, Signature,
};
use crate::value::{PortType, RefArray, ValueType};

fn repeat_kind() -> NodeKind {
    NodeKind::declare(
        "repeat",
        "carries a value through its loop body (current -> nodes -> next) until the body's u32 count is 0, or for `fixed` iterations (recorded one after the other, no host round trip; count optional); out is the last value, iterations the body runs (the last one counting 0), total the sum of the counts, first the count of the first iteration. The body sees the same step counter in every iteration (random draws keyed on the step repeat)",
    )
    .input(PortSpec::new(
        "initial",
        PortType::RealOrIndices,
        "the value the loop starts from",
    ))
    .input(
        PortSpec::new(
            "next",
            PortType::RealOrIndices,
            "the loop body's result for `current`",
        )
        .iterate(),
    )
    .input(
        PortSpec::new(
            "count",
            PortType::Indices,
            "the loop body's count for `current` (its first word): 0 stops the loop (optional with `fixed`)",
        )
        .iterate()
        .optional(),
    )
    .input(
        PortSpec::new(
            "halt",
            PortType::Indices,
            "a check made before the loop (its first word; not part of the body): nonzero stops the run at this step with an error naming the step and the value, before anything the loop computes is kept (bd_delaunay.json: edges passed through in the move); not with `fixed`",
        )
        .optional(),
    )
    .output(
        PortSpec::new(
            "out",
            PortType::RealOrIndices,
            "the value after the last iteration",
        )
        // `finish` sets it from `current`, and nothing else writes it.
        .final_of("current"),
    )
    .output(
        PortSpec::new(
            "current",
            PortType::RealOrIndices,
            "the value of this iteration: the loop body starts from it",
        )
        .iterate()
        // `advance` sets it from `next` after every body run and `finish` reads it after
        // the last; the gate keeps the body from running past the stop.
        .refilled_from("next")
        // `start` sets it from `initial`, which the node reads nowhere else.
        .started_from("initial"),
    )
    .output(PortSpec::new(
        "iterations",
        PortType::Indices,
        "the iterations run (1 word)",
    ))
    .output(PortSpec::new(
        "total",
        PortType::Indices,
        "the sum of the counts over the iterations (1 word)",
    ))
    .output(PortSpec::new(
        "first",
        PortType::Indices,
        "the body's count after its first iteration, every word (1 word, 0, without a count): what the loop started from (bd_delaunay.json: the overlaps the move left, before any correction)",
    ))
    .param(ParamSpec::integer(
        "fixed",
        Some(0.0),
        0.0,
        10_000.0,
        "run exactly this many iterations whatever the count, recorded one after the other (0: until the count is 0)",
    ))
    .param(ParamSpec::integer(
        "max_iterations",
        Some(1000.0),
        1.0,
        1e6,
        "until the count is 0: more iterations than this is an error",
    ))
    .param(ParamSpec::integer(
        "stop_word",
        Some(0.0),
        0.0,
        1e6,
        "the word of `count` whose 0 stops the loop (`total` sums word 0): edge_flip_round's word 1, the flips of its last round, stops the flip loops of bd_delaunay.json an iteration early",
    ))
    .build(|p| {
        Ok(Box::new(Repeat {
            fixed: p.number("fixed") as u32,
            max_iterations: p.number("max_iterations") as u32,
            stop_word: p.number("stop_word") as u32,
        }))
    })
}

pub struct Repeat {
    fixed: u32,
    max_iterations: u32,
    stop_word: u32,
}

/// Words of the status: iterations, stopped, last count, total, halt, done.
const STATUS_WORDS: u64 = 6;

impl Node for Repeat {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let initial = inputs[0].expect("required");
        if let Some(next) = inputs[1]
            && next != initial
        {
            return Err(PortError::new(
                "next",
                format!(
                    "is {next} but initial is {initial}: the body must return the value it was given, reshaped the same"
                ),
            ));
        }
        // (The planner types the node first without its loop inputs, `next` absent too.)
        if self.fixed == 0 && inputs[1].is_some() && inputs[2].is_none() {
            return Err(PortError::new(
                "count",
                "is not connected: without `fixed` the loop runs until the body's count is 0",
            ));
        }
        if let Some(ValueType::Indices { n: 0 }) = inputs[3] {
            return Err(PortError::new(
                "halt",
                "is empty: the loop reads its first word",
            ));
        }
        if self.fixed > 0 && inputs[3].is_some() {
            return Err(PortError::new(
                "halt",
                "needs a loop the host decides (a fixed loop reads no status): drop `fixed` or the halt",
            ));
        }
        if let Some(ValueType::Indices { n: 0 }) = inputs[2] {
            return Err(PortError::new(
                "count",
                "is empty: the loop reads its first word",
            ));
        }
        if let Some(ValueType::Indices { n }) = inputs[2]
            && self.stop_word >= n
        {
            return Err(PortError::new(
                "count",
                format!(
                    "has {n} words: stop_word {} is past its last",
                    self.stop_word
                ),
            ));
        }
        let one = ValueType::Indices { n: 1 };
        // (Typed first without the loop inputs: one word until the count is known.)
        let first = match inputs[2] {
            Some(count @ ValueType::Indices { .. }) => count,
            _ => one,
        };
        Ok(Signature::outputs(vec![initial, initial, one, one, first])
            .with_scratch(vec![4 * STATUS_WORDS]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Iterative(self)
    }

    fn notes(&self, _: &[Option<ValueType>]) -> Vec<String> {
        vec![if self.fixed > 0 {
            format!(
                "{} iterations a step, recorded one after the other (no host round trip)",
                self.fixed
            )
        } else {
            format!(
                "until the count is 0, at most {} iterations; one host round trip per batch of iterations",
                self.max_iterations
            )
        }]
    }

    /// There is no reference for the node alone: what it iterates exists only as its
    /// loop body. The tests compare whole loops with their bodies' references iterated on
    /// the host; this fills NaN so that nothing can mistake it for a result.
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
        // The plan may give `current` (output 1) the buffer of `initial` (the loop starts
        // where its value lies: `start` copies nothing), of `next` (the body's last node
        // writes it in place: `advance` is not dispatched) and of `out` (output 0: the
        // loop ends where its value lies, `finish` copies nothing). wgpu refuses a
        // buffer bound read-only and read-write in one dispatch, so a stand-in, unread,
        // takes the read-only binding of a buffer bound as `current`, and another,
        // unwritten, `out`'s binding where it is `current`'s buffer.
        let start_in_place = io.in_place(1, 0);
        let in_place = io.in_place(1, 1);
        let finish_in_place = io.same_output(0, 1);
        let stand_in = cx.table("repeat stand-in", &[0; 16]);
        let out_stand_in = cx.table("repeat out stand-in", &[0; 16]);
        let current = io.outputs[1].buffer;
        let next = unless_current(
            io.inputs[1].expect("the planner connects the loop").buffer,
            current,
            &stand_in,
        );
        // Without a count (a fixed loop) the tally reads none: a stand-in takes its
        // binding.
        let (count, counted) = match io.inputs[2] {
            Some(c) => (c.buffer, 1u32),
            None => (&stand_in, 0),
        };
        let first_words = io.outputs[4].ty.words() as u32;
        let (halt, halts) = match io.inputs[3] {
            Some(h) => (h.buffer, 1u32),
            None => (&stand_in, 0),
        };
        let words = initial.ty.words();
        let params = cx.uniform(
            "repeat params",
            bytemuck::cast_slice(&[
                words as u32,
                self.fixed,
                counted,
                halts,
                self.max_iterations,
                self.stop_word,
                u32::from(!start_in_place),
                u32::from(!finish_in_place),
                first_words,
            ]),
        );
        let status = io.scratch[0];
        let buffers = [
            unless_current(initial.buffer, current, &stand_in),
            next,
            count,
            io.outputs[1].buffer,
            if finish_in_place {
                &out_stand_in
            } else {
                io.outputs[0].buffer
            },
            io.outputs[2].buffer,
            io.outputs[3].buffer,
            status,
            &params,
            halt,
            io.outputs[4].buffer,
        ];
        let mut bindings = vec![Binding::StorageRead; 3];
        bindings.extend([Binding::StorageReadWrite; 5]);
        bindings.push(Binding::Uniform);
        bindings.push(Binding::StorageRead);
        bindings.push(Binding::StorageReadWrite);
        let source = cx.shader("repeat/repeat.wgsl")?;
        let groups = cx.grid_1d(words.max(STATUS_WORDS), WG_1D);
        // `start` and `finish` copy nothing where in place: their status and count words
        // take one workgroup.
        let copying = |copies: bool| {
            if copies {
                groups
            } else {
                cx.grid_1d(STATUS_WORDS, WG_1D)
            }
        };
        let (start_groups, finish_groups) = (copying(!start_in_place), copying(!finish_in_place));
        let mut dispatch = |entry: &str, groups: [u32; 3]| -> Result<_, CompileError> {
            let k = cx.kernel(
                &KernelSpec::new(format!("repeat {entry}"), source.clone(), &bindings).entry(entry),
            )?;
            Ok(cx.dispatch(&k, &buffers, groups))
        };
        Ok(IterativeKernels {
            start: vec![dispatch("start", start_groups)?],
            iterate: if in_place {
                vec![dispatch("tally", [1, 1, 1])?]
            } else {
                vec![dispatch("advance", groups)?, dispatch("tally", [1, 1, 1])?]
            },
            finish: vec![dispatch("finish", finish_groups)?],
            status: status.clone(),
            status_bytes: 4 * STATUS_WORDS,
            answer: status.clone(),
            answer_offset: 0,
            // `tally` sets `stopped` (status[1]) and counts the iterations (status[0]);
            // `advance` and `tally` do nothing after; `done` (status[5]) where `decide`
            // will finish with no answer.
            gpu_stop: Some(GpuStop {
                stopped_word: 1,
                iterations_word: 0,
                done_word: 5,
            }),
        })
    }

    fn fixed_iterations(&self) -> Option<u32> {
        (self.fixed > 0).then_some(self.fixed)
    }

    fn decide(&self, iterations: usize, status: &[u8]) -> Result<Decision, LoopError> {
        let words: &[u32] = bytemuck::cast_slice(status);
        if words[4] != 0 {
            return Err(LoopError::Input(format!(
                "stopped before the loop: its `halt` check is {} (must be 0)",
                words[4]
            )));
        }
        let (counted, stopped, last) = (words[0] as usize, words[1] != 0, words[2]);
        if counted != iterations {
            return Err(LoopError::Internal(format!(
                "the GPU counted {counted} iterations, the host {iterations}"
            )));
        }
        if !stopped {
            return Ok(Decision::Continue);
        }
        // The GPU stops at max_iterations too: there with the count still nonzero.
        if last != 0 {
            return Err(LoopError::NoConvergence(format!(
                "the loop body's count is still {last} after {iterations} iterations (max_iterations)"
            )));
        }
        Ok(Decision::Finish(Vec::new()))
    }
}

/// `buffer` for a read-only binding, or `stand_in` where it is `current`'s (bound
/// read-write in the same dispatches).
fn unless_current<'a>(
    buffer: &'a wgpu::Buffer,
    current: &wgpu::Buffer,
    stand_in: &'a wgpu::Buffer,
) -> &'a wgpu::Buffer {
    if buffer == current { stand_in } else { buffer }
}

pub fn register(r: &mut Registry) {
    r.add(repeat_kind());
}
