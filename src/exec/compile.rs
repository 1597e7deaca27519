//! Compiling a plan's launches, one function per launch kind: a node that records its
//! own dispatches (or a spectral node alone), a transform with what it folds in, a fused
//! group, a state copy, a loop with its body.

use super::{
    Compiled, CompiledLoop, ExecError, FIRST_BATCH, LoopGate, Program, StepChain, engine_err,
};
use crate::gpu::{Binding, CompileCtx, CompileError, KernelSpec, NodeIo, NodePlan, Slot, WG_1D};
use crate::graph::NodeId;
use crate::node::Lowering;
use crate::plan::{FusedKernel, Launch, TransformFold, ValueId};
use crate::transform;

impl<'a> Program<'a> {
    /// The buffers a node's launch binds, for a step of the given parity.
    fn node_io<'p>(
        &'p self,
        inputs: &[Option<ValueId>],
        outputs: &[ValueId],
        scratch: &[ValueId],
        plan: Option<&'p NodePlan>,
        parity: usize,
    ) -> NodeIo<'p> {
        let slot = |v: ValueId| Slot {
            buffer: self.buffer(v, parity),
            ty: self.plan.values[v].ty,
        };
        NodeIo {
            inputs: inputs.iter().map(|v| v.map(slot)).collect(),
            outputs: outputs.iter().map(|&v| slot(v)).collect(),
            scratch: scratch.iter().map(|&v| self.buffer(v, parity)).collect(),
            plan,
        }
    }

    /// Compiles one launch for a step of the given parity, by its kind.
    pub(super) fn compile_launch(
        &self,
        cx: &mut CompileCtx,
        l: &Launch,
        parity: usize,
    ) -> Result<Compiled, ExecError> {
        match l {
            Launch::Node {
                node,
                inputs,
                outputs,
                scratch,
                plan,
                ..
            } => {
                let io = self.node_io(inputs, outputs, scratch, plan.as_ref(), parity);
                self.compile_node(cx, *node, &io)
            }
            Launch::Transform {
                node,
                inputs,
                outputs,
                scratch,
                plan,
                fold,
                ..
            } => {
                // A transform that hosts a spectral node writes the latter's output.
                let outputs = match fold {
                    TransformFold::Hosts(f) => std::slice::from_ref(&f.output),
                    _ => outputs.as_slice(),
                };
                let io = self.node_io(inputs, outputs, scratch, plan.as_ref(), parity);
                self.compile_transform(cx, *node, fold, &io)
            }
            Launch::Fused(k) => self.compile_fused(cx, k, parity),
            Launch::Copy { src, dst } => self.compile_copy(cx, *src, *dst, parity),
            Launch::Loop {
                node,
                inputs,
                outputs,
                scratch,
                plan,
                body,
                ..
            } => {
                let io = self.node_io(inputs, outputs, scratch, plan.as_ref(), parity);
                self.compile_loop(cx, *node, body, &io, parity)
            }
        }
    }

    /// A node that records its own dispatches, or a spectral node run alone.
    fn compile_node(
        &self,
        cx: &mut CompileCtx,
        node: NodeId,
        io: &NodeIo,
    ) -> Result<Compiled, ExecError> {
        let inst = &self.graph.nodes[node];
        let err = |source| ExecError::Compile {
            node: inst.id.clone(),
            source,
        };
        let dispatches = match inst.node().lowering() {
            Lowering::Kernels(k) => k.compile(cx, io).map_err(err)?,
            Lowering::Spectral(body) => {
                let input = io.inputs[0].ok_or_else(|| {
                    err(CompileError::Unsupported(
                        "a spectral node needs its input".into(),
                    ))
                })?;
                vec![
                    transform::standalone_dispatch(
                        cx,
                        "spectral",
                        &body,
                        Some(input),
                        io.outputs[0],
                    )
                    .map_err(err)?,
                ]
            }
            _ => panic!(
                "node `{}` scheduled as a single launch cannot run as one",
                inst.id
            ),
        };
        Ok(Compiled::plain(
            inst.id.clone(),
            inst.kind.to_string(),
            dispatches,
        ))
    }

    /// A transform with what it folds in.
    fn compile_transform(
        &self,
        cx: &mut CompileCtx,
        node: NodeId,
        fold: &TransformFold,
        io: &NodeIo,
    ) -> Result<Compiled, ExecError> {
        let g = self.graph;
        let inst = &g.nodes[node];
        let Lowering::Transform(t) = inst.node().lowering() else {
            panic!("node `{}` scheduled as a transform is not one", inst.id)
        };
        let err = |source| ExecError::Compile {
            node: inst.id.clone(),
            source,
        };
        let TransformFold::Hosts(f) = fold else {
            let dispatches = t.compile(cx, io, fold.folding(), None).map_err(err)?;
            return Ok(Compiled::plain(
                inst.id.clone(),
                inst.kind.to_string(),
                dispatches,
            ));
        };
        let s = &g.nodes[f.node];
        let Lowering::Spectral(body) = s.node().lowering() else {
            panic!("folded node `{}` is not spectral", s.id)
        };
        Ok(Compiled::plain(
            format!("{} + {}", inst.id, s.id),
            format!("{}+{}", inst.kind, s.kind),
            t.compile(cx, io, fold.folding(), Some(&body))
                .map_err(err)?,
        ))
    }

    /// A chain of element-wise nodes as its generated kernel.
    fn compile_fused(
        &self,
        cx: &mut CompileCtx,
        k: &FusedKernel,
        parity: usize,
    ) -> Result<Compiled, ExecError> {
        let g = self.graph;
        let ids: Vec<&str> = k.nodes.iter().map(|&n| g.nodes[n].id.as_str()).collect();
        let kinds: Vec<&str> = k.nodes.iter().map(|&n| g.nodes[n].kind).collect();
        let label = if ids.len() == 1 {
            ids[0].to_string()
        } else {
            format!("fused[{}]", ids.join(", "))
        };
        let mut bindings = vec![Binding::StorageRead];
        if k.uses_clock {
            bindings.push(Binding::StorageRead);
        }
        bindings.extend(k.inputs.iter().map(|_| Binding::StorageRead));
        bindings.extend(k.outputs.iter().map(|_| Binding::StorageReadWrite));
        let spec = KernelSpec::new(
            format!("pointwise {}", kinds.join("+")),
            k.source.clone(),
            &bindings,
        );
        let kernel = cx.kernel(&spec).map_err(|source| ExecError::Compile {
            node: label.clone(),
            source,
        })?;
        let params = cx.table("pointwise params", bytemuck::cast_slice(&k.params));
        let mut bufs: Vec<&wgpu::Buffer> = vec![&params];
        if k.uses_clock {
            bufs.push(cx.clock);
        }
        bufs.extend(k.inputs.iter().map(|&v| self.buffer(v, parity)));
        bufs.extend(k.outputs.iter().map(|&v| self.buffer(v, parity)));
        let d = cx.dispatch(&kernel, &bufs, cx.grid_1d(k.len, WG_1D));
        Ok(Compiled::plain(label, kinds.join("+"), vec![d]))
    }

    /// The engine's copy of a value into a state buffer.
    fn compile_copy(
        &self,
        cx: &mut CompileCtx,
        src: ValueId,
        dst: ValueId,
        parity: usize,
    ) -> Result<Compiled, ExecError> {
        let words = self.plan.values[src].ty.words();
        let kernel = cx
            .kernel(&KernelSpec::new(
                "copy",
                cx.shader("engine/copy.wgsl").map_err(engine_err)?,
                &[
                    Binding::StorageRead,
                    Binding::StorageReadWrite,
                    Binding::Uniform,
                ],
            ))
            .map_err(engine_err)?;
        let shape = cx.uniform("copy shape", bytemuck::bytes_of(&(words as u32)));
        let d = cx.dispatch(
            &kernel,
            &[self.buffer(src, parity), self.buffer(dst, parity), &shape],
            cx.grid_1d(words, WG_1D),
        );
        let label = format!("copy -> {}", self.plan.values[dst].name);
        Ok(Compiled::plain(label, "copy".into(), vec![d]))
    }

    /// An iterative node with its loop body and the staging buffers its decisions read.
    fn compile_loop(
        &self,
        cx: &mut CompileCtx,
        node: NodeId,
        body: &[Launch],
        io: &NodeIo,
        parity: usize,
    ) -> Result<Compiled, ExecError> {
        let inst = &self.graph.nodes[node];
        let Lowering::Iterative(it) = inst.node().lowering() else {
            panic!("node `{}` scheduled as a loop does not iterate", inst.id)
        };
        let kernels = it.compile(cx, io).map_err(|source| ExecError::Compile {
            node: inst.id.clone(),
            source,
        })?;
        let body = body
            .iter()
            .map(|l| self.compile_launch(cx, l, parity))
            .collect::<Result<Vec<_>, _>>()?;
        if let Some(count) = it.fixed_iterations() {
            // Known in advance: the iterations recorded one after the other, a plain
            // launch the executor batches like any other.
            let mut dispatches = kernels.start;
            for _ in 0..count {
                for c in &body {
                    dispatches.extend(c.dispatches.iter().cloned());
                }
                dispatches.extend(kernels.iterate.iter().cloned());
            }
            dispatches.extend(kernels.finish);
            return Ok(Compiled::plain(
                inst.id.clone(),
                format!("{} (x{count} of {})", inst.kind, body.len()),
                dispatches,
            ));
        }
        // A gated loop reads its status once per batch of iterations; an ungated one
        // after every iteration, with the next one in flight.
        let in_flight = if kernels.gpu_stop.is_some() { 1 } else { 2 };
        let staging = (0..in_flight)
            .map(|i| {
                self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(&format!("{} status {i}", inst.id)),
                    size: kernels.status_bytes.max(4).next_multiple_of(4),
                    usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                })
            })
            .collect();
        let mut lp = CompiledLoop {
            node,
            kernels,
            body,
            staging,
            gate: None,
            last_iterations: FIRST_BATCH.into(),
        };
        if let Some(stop) = lp.kernels.gpu_stop {
            lp.gate = Some(self.compile_gate(cx, &lp, stop.stopped_word)?);
        }
        Ok(Compiled {
            label: inst.id.clone(),
            kinds: format!("{} (loop of {})", inst.kind, lp.body.len()),
            dispatches: Vec::new(),
            looped: Some(std::sync::Arc::new(lp)),
            last_only: false,
        })
    }

    /// A dispatch of the gate kernel (shaders/engine/gate.wgsl) at `entry` (`main` for a
    /// loop's gate, `tail` for a chained step's tail gates) over `groups`: the static
    /// `counts`, the loop's `status`, the `args` it writes, its `params` (words, stopped
    /// word, first word, done word) and the chain word.
    #[allow(clippy::too_many_arguments)]
    fn gate_dispatch(
        &self,
        cx: &mut CompileCtx,
        entry: &str,
        counts: &wgpu::Buffer,
        status: &wgpu::Buffer,
        args: &wgpu::Buffer,
        params: [u32; 4],
        groups: [u32; 3],
    ) -> Result<crate::gpu::Dispatch, ExecError> {
        let kernel = cx
            .kernel(
                &KernelSpec::new(
                    format!("loop gate {entry}"),
                    cx.shader("engine/gate.wgsl").map_err(engine_err)?,
                    &[
                        Binding::StorageRead,
                        Binding::StorageRead,
                        Binding::StorageReadWrite,
                        Binding::Uniform,
                        Binding::StorageReadWrite,
                    ],
                )
                .entry(entry),
            )
            .map_err(engine_err)?;
        let params = cx.uniform("loop gate params", bytemuck::cast_slice(&params));
        Ok(cx.dispatch(
            &kernel,
            &[counts, status, args, &params, &self.loop_chain],
            groups,
        ))
    }

    /// The gate of a loop whose node sets status word `stopped_word` at the stop: the
    /// static workgroup counts of its iteration's dispatches, the indirect arguments and
    /// the kernel that writes them from the counts and the word.
    fn compile_gate(
        &self,
        cx: &mut CompileCtx,
        lp: &CompiledLoop,
        stopped_word: u32,
    ) -> Result<LoopGate, ExecError> {
        let counts: Vec<u32> = lp.iteration().flat_map(|d| d.workgroups).collect();
        let static_counts = cx.table("loop gate counts", bytemuck::cast_slice(&counts));
        let args = indirect_args(self.gpu, "loop gate args", counts.len());
        let dispatch = self.gate_dispatch(
            cx,
            "main",
            &static_counts,
            &lp.kernels.status,
            &args,
            [counts.len() as u32, stopped_word, 0, 0],
            cx.grid_1d(counts.len() as u64, WG_1D),
        )?;
        Ok(LoopGate { args, dispatch })
    }

    /// The chained form of a parity's step (`StepChain`), where it has loops and every
    /// one stops on the GPU and runs on every step; `None` otherwise.
    pub(super) fn compile_chain(
        &self,
        cx: &mut CompileCtx,
        parity: usize,
    ) -> Result<Option<StepChain>, ExecError> {
        let step = &self.step[parity];
        let loops: Vec<&CompiledLoop> = step.iter().filter_map(|c| c.looped.as_deref()).collect();
        let chainable = |c: &Compiled| {
            c.looped
                .as_ref()
                .is_none_or(|lp| !c.last_only && lp.gate.is_some() && lp.kernels.gpu_stop.is_some())
        };
        if loops.is_empty() || !step.iter().all(chainable) {
            return Ok(None);
        }
        // The slots in recording order (`run.rs`, `record_chained`): from the first
        // loop's finish on, every dispatch but the loops' gates and iterations.
        let mut counts: Vec<u32> = Vec::new();
        let mut tail_first = Vec::new();
        let mut after_loop = false;
        for c in step {
            match &c.looped {
                None if after_loop => counts.extend(c.dispatches.iter().flat_map(|d| d.workgroups)),
                None => {}
                Some(lp) => {
                    if after_loop {
                        counts.extend(lp.kernels.start.iter().flat_map(|d| d.workgroups));
                    }
                    tail_first.push(counts.len() / 3);
                    counts.extend(lp.kernels.finish.iter().flat_map(|d| d.workgroups));
                    after_loop = true;
                }
            }
        }
        counts.extend(self.clock_tick.workgroups);
        let slots = counts.len() / 3;
        let static_counts = cx.table("step chain counts", bytemuck::cast_slice(&counts));
        let args = indirect_args(self.gpu, "step chain args", counts.len());
        let tails = loops
            .iter()
            .enumerate()
            .map(|(k, lp)| {
                let end = tail_first.get(k + 1).copied().unwrap_or(slots);
                let first = tail_first[k];
                let stop = lp.kernels.gpu_stop.expect("chainable");
                self.gate_dispatch(
                    cx,
                    "tail",
                    &static_counts,
                    &lp.kernels.status,
                    &args,
                    [
                        3 * (end - first) as u32,
                        // (stopped_word: the loop gate's, unread by the tail)
                        0,
                        3 * first as u32,
                        stop.done_word,
                    ],
                    [1, 1, 1],
                )
            })
            .collect::<Result<_, _>>()?;
        Ok(Some(StepChain {
            args,
            tails,
            tail_first,
        }))
    }
}

/// A buffer of `words` indirect dispatch arguments that a gate kernel writes.
fn indirect_args(gpu: &crate::gpu::GpuContext, label: &str, words: usize) -> wgpu::Buffer {
    gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: (4 * words as u64).max(16).next_multiple_of(16),
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::INDIRECT,
        mapped_at_creation: false,
    })
}
