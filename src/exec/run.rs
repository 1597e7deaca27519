//! Running a compiled program: the prologue, then the steps recorded into compute
//! passes, several steps per submission and at most two submissions in flight; loops
//! with their host decisions; the progress bar.

use std::time::{Duration, Instant};

use std::sync::atomic::Ordering;

use super::{CompiledLoop, ExecError, LoopGate, Profile, Program, RunOptions, RunStats, StepChain};
use crate::gpu::{Dispatch, GpuError};
use crate::node::{Decision, GpuStop, LoopError, Lowering};
use crate::value::HostArray;

impl Program<'_> {
    /// Records the dispatches that run on step `step` (see `Period`).
    pub(super) fn record(pass: &mut wgpu::ComputePass, dispatches: &[Dispatch], step: u64) {
        for d in dispatches {
            if d.workgroups.contains(&0) || !d.runs_at(step) {
                continue;
            }
            pass.set_pipeline(&d.kernel.pipeline);
            pass.set_bind_group(0, &d.bind_group, &[]);
            pass.dispatch_workgroups(d.workgroups[0], d.workgroups[1], d.workgroups[2]);
        }
    }

    /// Resets persistent values and the clock, then runs the prologue.
    pub(super) fn start(&mut self) -> Result<(), ExecError> {
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        for (b, info) in self.buffers.iter().zip(&self.plan.buffers) {
            if info.role == crate::plan::BufferRole::Persistent {
                enc.clear_buffer(b, 0, None);
            }
        }
        enc.clear_buffer(&self.clock, 0, None);
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            for c in &self.prologue {
                Self::record(&mut pass, &c.dispatches, 0);
            }
        }
        let idx = self.gpu.queue.submit([enc.finish()]);
        self.gpu.wait(idx)?;
        self.steps_done = 0;
        self.iterations.clear();
        Ok(())
    }

    pub(super) fn has_loops(&self) -> bool {
        self.step[0].iter().any(|c| c.looped.is_some())
    }

    /// Submits the dispatches that run on step `step` in one compute pass.
    pub(super) fn submit(&self, dispatches: &[&Dispatch], step: u64) -> wgpu::SubmissionIndex {
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            for d in dispatches {
                Self::record(&mut pass, std::slice::from_ref(*d), step);
            }
        }
        self.gpu.queue.submit([enc.finish()])
    }

    /// Records one dispatch of a gated loop's iteration, its workgroup counts read from
    /// the loop gate's arguments (slot `index` of `CompiledLoop::iteration`).
    pub(super) fn record_gated(
        pass: &mut wgpu::ComputePass,
        d: &Dispatch,
        args: &wgpu::Buffer,
        index: usize,
    ) {
        pass.set_pipeline(&d.kernel.pipeline);
        pass.set_bind_group(0, &d.bind_group, &[]);
        pass.dispatch_workgroups_indirect(args, 12 * index as u64);
    }

    /// Runs an iterative node: `pending` (work recorded before it) goes out with the
    /// first iteration. Leaves the node's finishing dispatches in `pending` and returns the
    /// number of iterations. A loop that stops on the GPU runs in batches (`run_batches`);
    /// any other reads its status after every iteration (`run_iterations`).
    fn run_loop<'p>(
        &'p self,
        lp: &'p CompiledLoop,
        pending: &mut Vec<&'p Dispatch>,
        step: u64,
    ) -> Result<u32, ExecError> {
        match (&lp.gate, lp.kernels.gpu_stop) {
            (Some(gate), Some(stop)) => self.run_batches(lp, gate, stop, pending, step),
            _ => self.run_iterations(lp, pending, step),
        }
    }

    /// Reads a loop's status: `status_bytes` of the node's status buffer, copied into
    /// `staging` by submission `index`.
    fn read_status(
        &self,
        lp: &CompiledLoop,
        staging: &wgpu::Buffer,
        index: wgpu::SubmissionIndex,
    ) -> Result<Vec<u8>, ExecError> {
        let (tx, rx) = std::sync::mpsc::channel();
        staging.slice(..).map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.gpu.wait(index)?;
        rx.recv()
            .map_err(|_| GpuError::Device("buffer map callback never ran".into()))?
            .map_err(|e| GpuError::Device(format!("mapping a status buffer failed: {e}")))?;
        let status = staging
            .slice(..)
            .get_mapped_range()
            .map_err(|e| GpuError::Device(format!("reading a status buffer failed: {e}")))?
            [..lp.kernels.status_bytes as usize]
            .to_vec();
        staging.unmap();
        Ok(status)
    }

    /// A loop that stops on the GPU (`IterativeKernels::gpu_stop`): batches of
    /// iterations, each one submission whose status the host reads once at its end. The
    /// gate kernel, after each iteration, zeroes the indirect workgroup counts of the
    /// iterations after it once the loop has stopped, so the iterations a batch holds past
    /// the stop cost only their launches and change nothing. A batch is one iteration
    /// longer than the loop's last run (`CompiledLoop::next_batch`): a loop that takes as
    /// many iterations as at its last step, or one more (the common case in a time loop),
    /// costs one host round trip.
    fn run_batches<'p>(
        &'p self,
        lp: &'p CompiledLoop,
        gate: &'p LoopGate,
        stop: GpuStop,
        pending: &mut Vec<&'p Dispatch>,
        step: u64,
    ) -> Result<u32, ExecError> {
        pending.extend(&lp.kernels.start);
        // The first iteration's counts, the stopped word just cleared by `start`.
        pending.push(&gate.dispatch);
        let (iterations, answer) = self.batches_until_stop(lp, gate, stop, pending, step, 0)?;
        self.gpu
            .queue
            .write_buffer(&lp.kernels.answer, lp.kernels.answer_offset, &answer);
        pending.extend(&lp.kernels.finish);
        Ok(iterations as u32)
    }

    /// Sets the chain word (shaders/engine/gate.wgsl) to 1 for the next submission where
    /// it may be 0: the loop gates run their loops only while it is set, and a chained
    /// step's tail gates clear it where a loop did not finish (`judge_chained` then marks
    /// it cleared). A step whose loops all finish leaves it set: nothing to write.
    fn open_chain(&self) {
        if self.chain_cleared.swap(false, Ordering::Relaxed) {
            self.gpu
                .queue
                .write_buffer(&self.loop_chain, 0, bytemuck::bytes_of(&1u32));
        }
    }

    /// Batches of a gated loop's iterations (`pending`, recorded before them, goes out
    /// with the first), `submitted` of them already run, until the loop stops: its
    /// iterations and its answer. Stores the iterations as the loop's last run.
    fn batches_until_stop<'p>(
        &'p self,
        lp: &'p CompiledLoop,
        gate: &'p LoopGate,
        stop: GpuStop,
        pending: &mut Vec<&'p Dispatch>,
        step: u64,
        mut submitted: usize,
    ) -> Result<(usize, Vec<u8>), ExecError> {
        let batch = lp.next_batch();
        loop {
            // Where a chained step's tail gate found this loop unfinished, it cleared the
            // chain word (`judge_chained` marked it).
            self.open_chain();
            let mut enc = self.gpu.device.create_command_encoder(&Default::default());
            {
                let mut pass = enc.begin_compute_pass(&Default::default());
                for d in pending.iter() {
                    Self::record(&mut pass, std::slice::from_ref(*d), step);
                }
                Self::record_batch(&mut pass, lp, gate, batch, step);
            }
            lp.copy_status(&mut enc);
            pending.clear();
            let index = self.gpu.queue.submit([enc.finish()]);
            submitted += batch;
            let status = self.read_status(lp, &lp.staging[0], index)?;
            if let Some(finished) = self.judge(lp, stop, &status, submitted, step)? {
                lp.last_iterations.store(finished.0, Ordering::Relaxed);
                return Ok(finished);
            }
        }
    }

    /// `batch` iterations of a gated loop, each followed by its gate.
    fn record_batch(
        pass: &mut wgpu::ComputePass,
        lp: &CompiledLoop,
        gate: &LoopGate,
        batch: usize,
        step: u64,
    ) {
        for _ in 0..batch {
            for (i, d) in lp.iteration().enumerate() {
                if !d.workgroups.contains(&0) && d.runs_at(step) {
                    Self::record_gated(pass, d, &gate.args, i);
                }
            }
            Self::record(pass, std::slice::from_ref(&gate.dispatch), step);
        }
    }

    /// The host's reading of a gated loop's status after `submitted` iterations went out:
    /// `None` where it goes on (every one of them ran), its iterations and answer where it
    /// finished, the loop's error where it failed. The node's `done` word must agree with
    /// its `decide` (a chained step ran, or skipped, the rest of the step on it).
    fn judge(
        &self,
        lp: &CompiledLoop,
        stop: GpuStop,
        status: &[u8],
        submitted: usize,
        step: u64,
    ) -> Result<Option<(usize, Vec<u8>)>, ExecError> {
        let inst = &self.graph.nodes[lp.node];
        let Lowering::Iterative(it) = inst.node().lowering() else {
            unreachable!("compiled as a loop")
        };
        let words: &[u32] = bytemuck::cast_slice(status);
        let iterations = words[stop.iterations_word as usize] as usize;
        let done = words[stop.done_word as usize] != 0;
        let failed = |source| ExecError::Loop {
            node: inst.id.clone(),
            kind: inst.kind,
            step: step + 1,
            source,
        };
        let decision = it.decide(iterations, status);
        let disagree = |verdict: &str| {
            failed(LoopError::Internal(format!(
                "the loop {verdict} after {iterations} iterations, but its node's `done` word \
                 says {}",
                if done { "done" } else { "not done" }
            )))
        };
        match decision {
            Err(_) | Ok(Decision::Continue) if done => Err(disagree("did not finish")),
            Err(source) => Err(failed(source)),
            Ok(Decision::Continue) if iterations == submitted => Ok(None),
            Ok(Decision::Continue) => Err(failed(LoopError::Internal(format!(
                "the GPU ran {iterations} of {submitted} iterations without stopping"
            )))),
            Ok(Decision::Finish(answer)) if done && answer.is_empty() => {
                Ok(Some((iterations, answer)))
            }
            Ok(Decision::Finish(_)) => Err(disagree("finished with an answer")),
        }
    }

    /// One step whose loops all stop on the GPU as one submission (`StepChain`): the
    /// launches before the first loop, each loop's start, gate and batch, then its tail
    /// gate and, gated by it, its finish and everything up to the next loop's batch, the
    /// clock tick last. Returns the last submission and the loops' iterations
    /// (`judge_chained`).
    fn submit_step_chained(
        &self,
        chain: &StepChain,
        step: u64,
        last: bool,
    ) -> Result<(wgpu::SubmissionIndex, Vec<u32>), ExecError> {
        let (commands, batches) = self.encode_chained(chain, step, last, None);
        let index = self.submit_chained(commands);
        self.judge_chained(chain, step, last, index, batches)
    }

    /// A chained step recorded (`record_chained`, from its start or from loop `from`'s
    /// tail), not yet submitted: its commands and each loop's batch.
    fn encode_chained(
        &self,
        chain: &StepChain,
        step: u64,
        last: bool,
        from: Option<usize>,
    ) -> (wgpu::CommandBuffer, Vec<usize>) {
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        let batches = self.record_chained(&mut enc, chain, (step % 2) as usize, step, last, from);
        (enc.finish(), batches)
    }

    /// Submits a chained step's commands, the chain word set first.
    fn submit_chained(&self, commands: wgpu::CommandBuffer) -> wgpu::SubmissionIndex {
        self.open_chain();
        self.gpu.queue.submit([commands])
    }

    /// After a chained step went out (submission `index`, the loops' `batches`): reads
    /// its loops' statuses in order; a loop its batch did not finish goes on in batches of
    /// its own, and the step from its tail on goes out again (the launches after it were
    /// gated off). Returns the last submission and the loops' iterations.
    fn judge_chained(
        &self,
        chain: &StepChain,
        step: u64,
        last: bool,
        mut index: wgpu::SubmissionIndex,
        mut batches: Vec<usize>,
    ) -> Result<(wgpu::SubmissionIndex, Vec<u32>), ExecError> {
        let loops: Vec<&CompiledLoop> = self.step[(step % 2) as usize]
            .iter()
            .filter_map(|c| c.looped.as_deref())
            .collect();
        let mut counts = vec![0u32; loops.len()];
        let mut first = 0;
        loop {
            let mut goes_on = None;
            for (k, lp) in loops.iter().enumerate().skip(first) {
                let (Some(gate), Some(stop)) = (&lp.gate, lp.kernels.gpu_stop) else {
                    unreachable!("a chained step's loops are gated")
                };
                let verdict = self
                    .read_status(lp, &lp.staging[0], index.clone())
                    .and_then(|status| self.judge(lp, stop, &status, batches[k], step));
                if !matches!(verdict, Ok(Some(_))) {
                    // Its tail gate cleared the chain word.
                    self.chain_cleared.store(true, Ordering::Relaxed);
                }
                match verdict? {
                    Some((iterations, _)) => {
                        lp.last_iterations.store(iterations, Ordering::Relaxed);
                        counts[k] = iterations as u32;
                    }
                    None => {
                        let (iterations, _) = self.batches_until_stop(
                            lp,
                            gate,
                            stop,
                            &mut Vec::new(),
                            step,
                            batches[k],
                        )?;
                        counts[k] = iterations as u32;
                        goes_on = Some(k);
                        break;
                    }
                }
            }
            let Some(k) = goes_on else {
                return Ok((index, counts));
            };
            let (commands, rest) = self.encode_chained(chain, step, last, Some(k));
            index = self.submit_chained(commands);
            batches = rest;
            first = k + 1;
        }
    }

    /// Runs `steps` chained steps from step `from`, each recorded while the one before
    /// it runs on the GPU (its batches sized by the loops' runs before that one, a guess
    /// that `judge_chained` corrects), so the host's recording leaves the GPU busy: one
    /// host round trip a step, the GPU idle only through it. Returns the steps done and
    /// the first error.
    fn run_chained_steps(
        &mut self,
        from: u64,
        steps: u64,
        bar: Option<&indicatif::ProgressBar>,
    ) -> (u64, Result<(), ExecError>) {
        let chained = |step: u64| {
            self.chains[(step % 2) as usize]
                .as_ref()
                .expect("every parity chained")
        };
        let mut ahead = None;
        let mut counts_per_step = Vec::new();
        let mut done = 0;
        let result = loop {
            if done == steps {
                break Ok(());
            }
            let step = from + done;
            let last = done + 1 == steps;
            let (commands, batches) = ahead
                .take()
                .unwrap_or_else(|| self.encode_chained(chained(step), step, last, None));
            let index = self.submit_chained(commands);
            if !last {
                let next = step + 1;
                ahead = Some(self.encode_chained(chained(next), next, done + 2 == steps, None));
            }
            match self
                .judge_chained(chained(step), step, last, index, batches)
                .and_then(|(index, counts)| Ok((self.gpu.wait(index)?, counts)))
            {
                Ok((_, counts)) => counts_per_step.push(counts),
                Err(e) => break Err(e),
            }
            done += 1;
            if let Some(b) = bar {
                b.inc(1);
            }
        };
        for counts in counts_per_step {
            self.note_iterations(counts);
        }
        (done, result)
    }

    /// Records a chained step from its start (`from` None) or from loop `from`'s tail
    /// gate on (the loops before it and their launches done); returns the batch recorded
    /// for each loop (0 for those not recorded). The slots of the gated dispatches follow
    /// the layout `compile_chain` counted. Each loop's status is copied for the host right
    /// after its tail gate (a pass ends there): it lies in the node's scratch, which
    /// launches after the loop may reuse.
    fn record_chained(
        &self,
        enc: &mut wgpu::CommandEncoder,
        chain: &StepChain,
        parity: usize,
        step: u64,
        last: bool,
        from: Option<usize>,
    ) -> Vec<usize> {
        // A dispatch before the first loop's batch goes out as recorded; one after it
        // through its slot of the chain's arguments (counted whether it runs or not).
        let emit =
            |pass: &mut wgpu::ComputePass, d: &Dispatch, slot: &mut Option<usize>, runs| match slot
            {
                None if runs => Self::record(pass, std::slice::from_ref(d), step),
                None => {}
                Some(s) => {
                    if runs && !d.workgroups.contains(&0) && d.runs_at(step) {
                        Self::record_gated(pass, d, &chain.args, *s);
                    }
                    *s += 1;
                }
            };
        let mut batches = vec![0; chain.tails.len()];
        let mut slot = None;
        let mut k = 0;
        let mut pass = enc.begin_compute_pass(&Default::default());
        for c in &self.step[parity] {
            let Some(lp) = &c.looped else {
                if from.is_none_or(|f| k > f) {
                    for d in &c.dispatches {
                        emit(&mut pass, d, &mut slot, c.runs_on(last));
                    }
                }
                continue;
            };
            let gate = lp.gate.as_ref().expect("a chained step's loops are gated");
            let batched = from.is_none_or(|f| k > f);
            if batched {
                for d in &lp.kernels.start {
                    emit(&mut pass, d, &mut slot, true);
                }
                Self::record(&mut pass, std::slice::from_ref(&gate.dispatch), step);
                batches[k] = lp.next_batch();
                Self::record_batch(&mut pass, lp, gate, batches[k], step);
            }
            if from.is_none_or(|f| k >= f) {
                debug_assert!(slot.is_none_or(|s| s == chain.tail_first[k]));
                Self::record(&mut pass, std::slice::from_ref(&chain.tails[k]), step);
                if batched {
                    drop(pass);
                    lp.copy_status(enc);
                    pass = enc.begin_compute_pass(&Default::default());
                }
                slot = Some(chain.tail_first[k]);
                for d in &lp.kernels.finish {
                    emit(&mut pass, d, &mut slot, true);
                }
            }
            k += 1;
        }
        emit(&mut pass, &self.clock_tick, &mut slot, true);
        batches
    }

    /// A loop only the host can stop: each iteration ends with a host round trip that
    /// reads the node's status and asks it whether to go on.
    fn run_iterations<'p>(
        &'p self,
        lp: &'p CompiledLoop,
        pending: &mut Vec<&'p Dispatch>,
        step: u64,
    ) -> Result<u32, ExecError> {
        let inst = &self.graph.nodes[lp.node];
        let Lowering::Iterative(it) = inst.node().lowering() else {
            unreachable!("compiled as a loop")
        };
        // Iteration k goes out with a copy of the status after it. While the host reads
        // and judges iteration k, the next one already runs (speculatively: when k
        // finishes, its work is discarded; it only wrote basis rows past the answer, or
        // values the loop no longer reads), so the GPU does not idle through the round
        // trip.
        let in_flight = lp.staging.len();
        let bytes = lp.kernels.status_bytes.max(4).next_multiple_of(4);
        let submit_iteration = |pending: &mut Vec<&'p Dispatch>, k: usize| {
            let mut enc = self.gpu.device.create_command_encoder(&Default::default());
            {
                let mut pass = enc.begin_compute_pass(&Default::default());
                for d in pending.iter() {
                    Self::record(&mut pass, std::slice::from_ref(*d), step);
                }
                for d in lp.iteration() {
                    Self::record(&mut pass, std::slice::from_ref(d), step);
                }
            }
            enc.copy_buffer_to_buffer(&lp.kernels.status, 0, &lp.staging[k % in_flight], 0, bytes);
            pending.clear();
            self.gpu.queue.submit([enc.finish()])
        };
        pending.extend(&lp.kernels.start);
        let mut submitted: std::collections::VecDeque<_> = (1..=in_flight)
            .map(|k| submit_iteration(pending, k))
            .collect();
        let mut iterations = 1usize;
        loop {
            let current = submitted.pop_front().expect("an iteration in flight");
            let status = self.read_status(lp, &lp.staging[iterations % in_flight], current)?;
            match it.decide(iterations, &status) {
                Ok(Decision::Continue) => {
                    // Its copy goes to the staging buffer just read.
                    submitted.push_back(submit_iteration(pending, iterations + in_flight));
                    iterations += 1;
                }
                Ok(Decision::Finish(answer)) => {
                    self.gpu.queue.write_buffer(
                        &lp.kernels.answer,
                        lp.kernels.answer_offset,
                        &answer,
                    );
                    pending.extend(&lp.kernels.finish);
                    return Ok(iterations as u32);
                }
                Err(source) => {
                    return Err(ExecError::Loop {
                        node: inst.id.clone(),
                        kind: inst.kind,
                        step: step + 1,
                        source,
                    });
                }
            }
        }
    }

    /// Submits one step of a program with loops (`last`: the run's last step, which runs
    /// the launches only outputs read); returns the last submission and the iterations of
    /// each loop.
    pub(super) fn submit_step_with_loops(
        &self,
        step: u64,
        last: bool,
    ) -> Result<(wgpu::SubmissionIndex, Vec<u32>), ExecError> {
        let parity = (step % 2) as usize;
        if let (true, Some(chain)) = (self.chain_loops, &self.chains[parity]) {
            return self.submit_step_chained(chain, step, last);
        }
        let mut pending: Vec<&Dispatch> = Vec::new();
        let mut counts = Vec::new();
        for c in self.step[parity].iter().filter(|c| c.runs_on(last)) {
            match &c.looped {
                None => pending.extend(&c.dispatches),
                Some(lp) => counts.push(self.run_loop(lp, &mut pending, step)?),
            }
        }
        pending.push(&self.clock_tick);
        Ok((self.submit(&pending, step), counts))
    }

    /// Runs a loop alone and waits for it: its wall time (host round trips included) and
    /// its iterations.
    pub(super) fn time_loop(
        &self,
        lp: &CompiledLoop,
        step: u64,
    ) -> Result<(Duration, u32), ExecError> {
        let t = Instant::now();
        let mut pending = Vec::new();
        let k = self.run_loop(lp, &mut pending, step)?;
        let idx = self.submit(&pending, step);
        self.gpu.wait(idx)?;
        Ok((t.elapsed(), k))
    }

    /// Iterations each loop took at every step of the last run, by node id.
    pub fn loop_iterations(&self) -> &[(String, Vec<u32>)] {
        &self.iterations
    }

    pub(super) fn note_iterations(&mut self, counts: Vec<u32>) {
        if self.iterations.is_empty() {
            self.iterations = self.step[0]
                .iter()
                .filter(|c| c.looped.is_some())
                .map(|c| (c.label.clone(), Vec::new()))
                .collect();
        }
        for (row, k) in self.iterations.iter_mut().zip(counts) {
            row.1.push(k);
        }
    }

    /// Runs the prologue and `steps` time steps.
    pub fn run(&mut self, opts: &RunOptions) -> Result<RunStats, ExecError> {
        if opts.steps == 0 {
            return Err(ExecError::Run(
                "the number of steps must be at least 1".into(),
            ));
        }
        let t0 = Instant::now();
        self.start()?;
        self.run_steps(opts, t0)
    }

    /// `opts.steps` steps after those already run, timed as `opts.profile` says.
    fn run_steps(&mut self, opts: &RunOptions, t0: Instant) -> Result<RunStats, ExecError> {
        let stats = match opts.profile {
            Profile::Off => self.run_batched(opts, false)?.0,
            Profile::Launches => self.run_profiled(opts.steps, false)?,
            Profile::Dispatches => self.run_profiled(opts.steps, true)?,
            Profile::Steps => self.run_timed_steps(opts.steps)?,
        };
        Ok(RunStats {
            wall: t0.elapsed(),
            ..stats
        })
    }

    /// Runs `steps` more time steps after the last run's, state and step counter carried
    /// on (random draws fresh); the first call after compiling or [`Program::reset`] runs
    /// the prologue as [`Program::run`] does. Inputs uploaded since are read by the steps;
    /// states keep their values (their initial values come from inputs at the prologue).
    pub fn run_on(&mut self, opts: &RunOptions) -> Result<RunStats, ExecError> {
        if self.steps_done == 0 {
            return self.run(opts);
        }
        if opts.steps == 0 {
            return Err(ExecError::Run(
                "the number of steps must be at least 1".into(),
            ));
        }
        self.run_steps(opts, Instant::now())
    }

    /// [`Program::run_on`], then the outputs as [`Program::read_outputs`] gives them;
    /// without profiling or loops the copies to the host ride with the last steps'
    /// submission (one wait for both).
    pub fn run_on_and_read(
        &mut self,
        opts: &RunOptions,
    ) -> Result<(RunStats, Vec<(String, HostArray)>), ExecError> {
        if opts.profile != Profile::Off || self.has_loops() || opts.steps == 0 {
            let stats = self.run_on(opts)?;
            return Ok((stats, self.read_outputs()?));
        }
        let t0 = Instant::now();
        if self.steps_done == 0 {
            self.start()?;
        }
        let (stats, outputs) = self.run_batched(opts, true)?;
        Ok((
            RunStats {
                wall: t0.elapsed(),
                ..stats
            },
            outputs.expect("asked for"),
        ))
    }

    /// The next [`Program::run_on`] starts over: prologue, states from their initial
    /// values, step counter at 0 (the same draws as the first run, for the same seed).
    pub fn reset(&mut self) {
        self.steps_done = 0;
    }

    /// Whether steps whose loops all stop on the GPU go out as one submission each
    /// (`StepChain`; on by default), or with a host round trip per loop (for comparisons).
    pub fn set_chain_loops(&mut self, on: bool) {
        self.chain_loops = on;
    }

    /// Steps run since the prologue.
    pub fn steps_done(&self) -> u64 {
        self.steps_done
    }

    /// The steps in batches; with `read`, the outputs copied back in the last batch's
    /// submission.
    #[allow(clippy::type_complexity)]
    fn run_batched(
        &mut self,
        opts: &RunOptions,
        read: bool,
    ) -> Result<(RunStats, Option<Vec<(String, HostArray)>>), ExecError> {
        let per_step: usize = self.step[0]
            .iter()
            .map(|c| c.dispatches.len())
            .sum::<usize>()
            + 1;
        // Several steps per submission, bounded so that the progress bar moves and the
        // driver's queue stays shallow.
        let steps_per_submit = ((4096 / per_step).max(1) as u64).min(opts.steps);
        let bar = if opts.progress && opts.steps > 1 {
            let b = indicatif::ProgressBar::new(opts.steps);
            b.set_style(
                indicatif::ProgressStyle::with_template(
                    "{bar:40} {pos}/{len} steps  {per_sec}  eta {eta}",
                )
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
            );
            Some(b)
        } else {
            None
        };
        let mut in_flight: Option<(wgpu::SubmissionIndex, u64)> = None;
        let mut mapped = None;
        let mut done = 0;
        if self.has_loops() && self.chain_loops && self.chains.iter().all(Option::is_some) {
            let (ran, result) = self.run_chained_steps(self.steps_done, opts.steps, bar.as_ref());
            // The steps before a failed one ran and are kept (see below).
            self.steps_done += ran;
            if let Some(b) = &bar {
                b.finish_and_clear();
            }
            result?;
            return Ok((
                RunStats {
                    steps: opts.steps,
                    wall: Duration::ZERO,
                    profile: Vec::new(),
                    timed_by_gpu: false,
                    step_samples: Vec::new(),
                },
                None,
            ));
        }
        if self.has_loops() {
            // Loops decide on the host, so steps go out one at a time.
            while done < opts.steps {
                let last = done + 1 == opts.steps;
                let (idx, counts) = match self.submit_step_with_loops(self.steps_done + done, last)
                {
                    Ok(step) => step,
                    Err(e) => {
                        // The steps before this one ran and are kept: the next run goes on
                        // from them (their step number, so their random draws and which of
                        // a state's two buffers holds it), not from this run's start.
                        self.steps_done += done;
                        return Err(e);
                    }
                };
                self.note_iterations(counts);
                self.gpu.wait(idx)?;
                done += 1;
                if let Some(b) = &bar {
                    b.inc(1);
                }
            }
        }
        while done < opts.steps {
            let t_submit = Instant::now();
            let n = steps_per_submit.min(opts.steps - done);
            let mut enc = self.gpu.device.create_command_encoder(&Default::default());
            {
                let mut pass = enc.begin_compute_pass(&Default::default());
                for s in 0..n {
                    let step = self.steps_done + done + s;
                    let parity = (step % 2) as usize;
                    let last = done + s + 1 == opts.steps;
                    for c in self.step[parity].iter().filter(|c| c.runs_on(last)) {
                        Self::record(&mut pass, &c.dispatches, step);
                    }
                    Self::record(&mut pass, std::slice::from_ref(&self.clock_tick), step);
                }
            }
            let last = done + n == opts.steps;
            if read && last {
                self.record_output_copies(&mut enc, self.steps_done + opts.steps - 1);
            }
            let idx = self.gpu.queue.submit([enc.finish()]);
            if read && last {
                mapped = Some(self.map_readback());
            }
            let t_wait = Instant::now();
            self.host_times.submit += t_wait - t_submit;
            if let Some((prev, k)) = in_flight.take() {
                self.gpu.wait(prev)?;
                self.host_times.wait += t_wait.elapsed();
                if let Some(b) = &bar {
                    b.inc(k);
                }
            }
            in_flight = Some((idx, n));
            done += n;
        }
        if let Some((prev, k)) = in_flight {
            let t_wait = Instant::now();
            self.gpu.wait(prev)?;
            self.host_times.wait += t_wait.elapsed();
            if let Some(b) = &bar {
                b.inc(k);
            }
        }
        if let Some(b) = bar {
            b.finish_and_clear();
        }
        self.steps_done += opts.steps;
        let t_read = Instant::now();
        let outputs = match mapped {
            Some(m) => Some(self.collect_readback(m)?),
            None => None,
        };
        self.host_times.read += t_read.elapsed();
        Ok((
            RunStats {
                steps: opts.steps,
                wall: Duration::ZERO,
                profile: Vec::new(),
                timed_by_gpu: false,
                step_samples: Vec::new(),
            },
            outputs,
        ))
    }
}
