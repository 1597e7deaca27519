//! Profiling: per-launch (or per-dispatch) GPU times between timestamp queries, and
//! whole steps timed end to end (`Profile::Steps`), on the host where the device has no
//! timestamps or the program makes round trips inside a step.

use std::time::{Duration, Instant};

use super::{Compiled, ExecError, Program, RunStats};
use crate::gpu::{Dispatch, GpuContext};

/// GPU time of one launch over a run.
#[derive(Clone, Debug)]
pub struct ProfileRow {
    pub label: String,
    pub kinds: String,
    pub dispatches: usize,
    pub calls: u64,
    pub total: Duration,
    /// The time of each call, in order.
    pub samples: Vec<Duration>,
    /// With `Profile::Dispatches`: each dispatch's kernel label and its time per call.
    pub dispatch_samples: Vec<(String, Vec<Duration>)>,
    /// Only outputs read the launch (`Plan::last_step_only`): it ran, and was timed, on
    /// the last step of the run only.
    pub last_step_only: bool,
}

impl ProfileRow {
    fn of(c: &Compiled) -> Self {
        ProfileRow {
            label: c.label.clone(),
            kinds: c.kinds.clone(),
            dispatches: c.dispatches.len(),
            calls: 0,
            total: Duration::ZERO,
            samples: Vec::new(),
            dispatch_samples: c
                .dispatches
                .iter()
                .map(|d| (d.kernel.label.clone(), Vec::new()))
                .collect(),
            last_step_only: c.last_only,
        }
    }

    /// One more call taking `dt`.
    fn add(&mut self, dt: Duration) {
        self.total += dt;
        self.samples.push(dt);
        self.calls += 1;
    }

    /// Median time of one call.
    pub fn median(&self) -> Duration {
        let mut s = self.samples.clone();
        s.sort();
        if s.is_empty() {
            Duration::ZERO
        } else {
            s[s.len() / 2]
        }
    }
}

/// Timestamp queries for the timed units of a profiled step, two per unit.
struct StepTimer {
    units: Vec<(usize, Option<usize>)>,
    queries: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    /// Nanoseconds per tick.
    period: f64,
}

impl StepTimer {
    fn new(gpu: &GpuContext, units: Vec<(usize, Option<usize>)>) -> Self {
        let count = (2 * units.len()).max(2) as u32;
        StepTimer {
            queries: gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("profile"),
                ty: wgpu::QueryType::Timestamp,
                count,
            }),
            resolve: gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("profile resolve"),
                size: 8 * count as u64,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            }),
            period: gpu.queue.get_timestamp_period() as f64,
            units,
        }
    }
}

impl Program<'_> {
    /// Runs steps one launch (or dispatch) per compute pass with timestamps around each
    /// pass, or with a wait after each launch where the device has no timestamp queries.
    pub(super) fn run_profiled(
        &mut self,
        steps: u64,
        per_dispatch: bool,
    ) -> Result<RunStats, ExecError> {
        let mut rows: Vec<ProfileRow> = self.step[0].iter().map(ProfileRow::of).collect();
        let use_gpu = self.gpu.caps.timestamps;
        let timer = use_gpu.then(|| StepTimer::new(self.gpu, self.timed_units(per_dispatch)));
        for s in 0..steps {
            let step = self.steps_done + s;
            let last = s + 1 == steps;
            let counted = match &timer {
                Some(timer) => self.profile_step_by_timestamps(timer, step, last, &mut rows),
                None => self.profile_step_on_host(step, last, &mut rows),
            };
            // A failed step keeps the steps before it (see run_batched).
            let counts = counted.inspect_err(|_| self.steps_done += s)?;
            self.note_iterations(counts);
        }
        self.steps_done += steps;
        Ok(RunStats {
            steps,
            wall: Duration::ZERO,
            profile: rows,
            timed_by_gpu: use_gpu,
            step_samples: Vec::new(),
        })
    }

    /// Times whole steps: each step's dispatches in one compute pass, recorded as
    /// `run_batched` records them, with timestamps written at the pass's beginning and
    /// end, one step per submission. A step's time thus runs from its first kernel's start
    /// to its last one's end, the gaps between kernels included: what CUDA events around
    /// a library call measure. A program with loops makes host round trips inside its
    /// steps, and a device without timestamp queries has no GPU clock to read: those
    /// steps are timed on the host, from the first submission to the end of the wait.
    pub(super) fn run_timed_steps(&mut self, steps: u64) -> Result<RunStats, ExecError> {
        let by_gpu = self.gpu.caps.timestamps && !self.has_loops();
        let queries = by_gpu.then(|| {
            self.gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("step timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: 2,
            })
        });
        let resolve = self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("step timestamps resolve"),
            size: 16,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let period = self.gpu.queue.get_timestamp_period() as f64;
        let mut samples = Vec::with_capacity(steps as usize);
        for s in 0..steps {
            let step = self.steps_done + s;
            let parity = (step % 2) as usize;
            let last = s + 1 == steps;
            let Some(qs) = &queries else {
                let t = Instant::now();
                let idx = if self.has_loops() {
                    // A failed step keeps the steps before it (see run_batched).
                    let (idx, counts) = self
                        .submit_step_with_loops(step, last)
                        .inspect_err(|_| self.steps_done += s)?;
                    self.note_iterations(counts);
                    idx
                } else {
                    let dispatches: Vec<&Dispatch> = self.step[parity]
                        .iter()
                        .filter(|c| c.runs_on(last))
                        .flat_map(|c| &c.dispatches)
                        .chain(std::iter::once(&self.clock_tick))
                        .collect();
                    self.submit(&dispatches, step)
                };
                self.gpu.wait(idx)?;
                samples.push(t.elapsed());
                continue;
            };
            let mut enc = self.gpu.device.create_command_encoder(&Default::default());
            {
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("step"),
                    timestamp_writes: Some(wgpu::ComputePassTimestampWrites {
                        query_set: qs,
                        beginning_of_pass_write_index: Some(0),
                        end_of_pass_write_index: Some(1),
                    }),
                });
                for c in self.step[parity].iter().filter(|c| c.runs_on(last)) {
                    Self::record(&mut pass, &c.dispatches, step);
                }
                Self::record(&mut pass, std::slice::from_ref(&self.clock_tick), step);
            }
            enc.resolve_query_set(qs, 0..2, &resolve, 0);
            let idx = self.gpu.queue.submit([enc.finish()]);
            self.gpu.wait(idx)?;
            let ticks: Vec<u64> =
                bytemuck::pod_collect_to_vec(&self.gpu.read_buffer(&resolve, 16)?);
            samples.push(Duration::from_nanos(
                (ticks[1].saturating_sub(ticks[0]) as f64 * period) as u64,
            ));
        }
        self.steps_done += steps;
        Ok(RunStats {
            steps,
            wall: Duration::ZERO,
            profile: Vec::new(),
            timed_by_gpu: by_gpu,
            step_samples: samples,
        })
    }

    /// The timed units of a step: each launch, or each dispatch of each launch. A loop is
    /// one unit, timed on the host (its decisions are host round trips).
    fn timed_units(&self, per_dispatch: bool) -> Vec<(usize, Option<usize>)> {
        if !per_dispatch {
            return (0..self.step[0].len()).map(|i| (i, None)).collect();
        }
        self.step[0]
            .iter()
            .enumerate()
            .flat_map(|(i, c)| {
                let whole = c.looped.is_some();
                let parts = if whole { 1 } else { c.dispatches.len() };
                (0..parts).map(move |d| (i, (!whole).then_some(d)))
            })
            .collect()
    }

    /// One step, each unit in a compute pass of its own between two timestamps. A launch
    /// only outputs read runs on the run's `last` step only: on the others its pass is
    /// empty and its row gets no sample.
    fn profile_step_by_timestamps(
        &self,
        timer: &StepTimer,
        step: u64,
        last: bool,
        rows: &mut [ProfileRow],
    ) -> Result<Vec<u32>, ExecError> {
        let parity = (step % 2) as usize;
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        let mut host_timed: Vec<(usize, Duration)> = Vec::new();
        let mut counts = Vec::new();
        for (u, &(i, d)) in timer.units.iter().enumerate() {
            let c = &self.step[parity][i];
            if let Some(lp) = &c.looped {
                let before = std::mem::replace(
                    &mut enc,
                    self.gpu.device.create_command_encoder(&Default::default()),
                );
                let idx = self.gpu.queue.submit([before.finish()]);
                self.gpu.wait(idx)?;
                let (dt, k) = self.time_loop(lp, step)?;
                host_timed.push((u, dt));
                counts.push(k);
                continue;
            }
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(&c.label),
                timestamp_writes: Some(wgpu::ComputePassTimestampWrites {
                    query_set: &timer.queries,
                    beginning_of_pass_write_index: Some(2 * u as u32),
                    end_of_pass_write_index: Some(2 * u as u32 + 1),
                }),
            });
            if !c.runs_on(last) {
                continue;
            }
            match d {
                Some(d) => Self::record(&mut pass, std::slice::from_ref(&c.dispatches[d]), step),
                None => Self::record(&mut pass, &c.dispatches, step),
            }
        }
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            Self::record(&mut pass, std::slice::from_ref(&self.clock_tick), 0);
        }
        let timed = timer.units.len();
        if timed > 0 {
            enc.resolve_query_set(&timer.queries, 0..2 * timed as u32, &timer.resolve, 0);
        }
        let idx = self.gpu.queue.submit([enc.finish()]);
        self.gpu.wait(idx)?;
        if timed == 0 {
            return Ok(counts);
        }
        let bytes = self.gpu.read_buffer(&timer.resolve, 16 * timed as u64)?;
        let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&bytes);
        let mut per_launch = vec![Duration::ZERO; rows.len()];
        for (u, &(i, d)) in timer.units.iter().enumerate() {
            if !self.step[parity][i].runs_on(last) {
                continue;
            }
            let dt = match host_timed.iter().find(|(h, _)| *h == u) {
                Some((_, dt)) => *dt,
                None => Duration::from_nanos(
                    (ticks[2 * u + 1].saturating_sub(ticks[2 * u]) as f64 * timer.period) as u64,
                ),
            };
            per_launch[i] += dt;
            if let Some(d) = d {
                rows[i].dispatch_samples[d].1.push(dt);
            }
        }
        for ((row, dt), c) in rows.iter_mut().zip(per_launch).zip(&self.step[parity]) {
            if c.runs_on(last) {
                row.add(dt);
            }
        }
        Ok(counts)
    }

    /// One step, each launch submitted alone and timed on the host (those only outputs
    /// read on the run's `last` step only).
    fn profile_step_on_host(
        &self,
        step: u64,
        last: bool,
        rows: &mut [ProfileRow],
    ) -> Result<Vec<u32>, ExecError> {
        let parity = (step % 2) as usize;
        let mut counts = Vec::new();
        for (i, c) in self.step[parity].iter().enumerate() {
            if !c.runs_on(last) {
                continue;
            }
            if let Some(lp) = &c.looped {
                let (dt, k) = self.time_loop(lp, step)?;
                counts.push(k);
                rows[i].add(dt);
                continue;
            }
            let t = Instant::now();
            let idx = self.submit(&c.dispatches.iter().collect::<Vec<_>>(), step);
            self.gpu.wait(idx)?;
            rows[i].add(t.elapsed());
        }
        let idx = self.submit(&[&self.clock_tick], 0);
        self.gpu.wait(idx)?;
        Ok(counts)
    }
}
