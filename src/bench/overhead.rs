//! `mesoflow bench overhead`: what the executor adds to a chain of tiny kernels, against
//! raw wgpu recording the same kernel with pre-made bind groups in the same process.
//! Wall clock per node over many batched steps (the host's recording and submission),
//! and the GPU time of one chain end to end (one compute pass, first to last timestamp)
//! beside the executor's per-launch sum.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use mesoflow::exec::{Profile, Program, RunOptions};
use mesoflow::gpu::{Binding, CompileCtx, Dispatch, GpuContext, KernelCache, KernelSpec, WG_1D};
use mesoflow::plan::{self, PlanOptions};
use mesoflow::value::{HostArray, ValueType};

use super::{BenchError, end_to_end_clock, load_text, median, median_duration, time_loaded};

/// A graph file with a chain of `n` scale nodes.
fn chain_graph(n: usize) -> String {
    let nodes: Vec<String> = (0..n)
        .map(|i| {
            let src = if i == 0 {
                "inputs.x".to_string()
            } else {
                format!("s{}.out", i - 1)
            };
            format!(
                r#"{{"id": "s{i}", "kind": "scale", "params": {{"factor": 1.0001}}, "inputs": {{"x": "{src}"}}}}"#
            )
        })
        .collect();
    format!(
        r#"{{"mesoflow": 1, "doc": "chain of {n} scale nodes",
  "inputs": {{"x": {{"type": "particles", "cols": 1}}}},
  "nodes": [{}],
  "outputs": {{"y": "s{}.out"}}}}"#,
        nodes.join(",\n"),
        n - 1
    )
}

pub fn run(nodes: usize, elements: u32, reps: u64) -> Result<(), BenchError> {
    if nodes == 0 || reps == 0 {
        return Err(BenchError::Args(
            "--nodes and --reps must be positive".into(),
        ));
    }
    let gpu = GpuContext::new()?;
    let g = load_text(&chain_graph(nodes))?;
    let ty = ValueType::Particles { n: elements, k: 1 };
    let x = HostArray::f32(ty, (0..elements).map(|i| i as f32).collect());
    let inputs: BTreeMap<String, HostArray> = [("x".to_string(), x)].into_iter().collect();
    let opts = PlanOptions {
        outputs: None,
        inputs: [("x".to_string(), ty)].into_iter().collect(),
        fuse: false,
        in_place: true,
    };
    let p = plan::plan(&g, &opts, &gpu.caps)?;
    let mut cache = KernelCache::default();
    let mut program = Program::compile(&gpu, &g, &p, &mut cache)?;
    program.upload(&inputs)?;
    let run = |program: &mut Program, steps: u64| {
        program.run(&RunOptions {
            steps,
            profile: Profile::Off,
            progress: false,
        })
    };
    run(&mut program, 2)?; // warm-up
    let mut exec_times = Vec::new();
    for _ in 0..5 {
        exec_times.push(run(&mut program, reps)?.wall.as_secs_f64());
    }
    let exec = median(&mut exec_times) / (reps as f64 * nodes as f64);
    let timed = time_loaded(&gpu, &g, &inputs, None, reps, false)?;

    let raw = RawChain::new(&gpu, &mut cache, nodes, elements)?;
    raw.wall(2)?;
    let mut raw_times = Vec::new();
    for _ in 0..5 {
        raw_times.push(raw.wall(reps)?);
    }
    let raw_wall = median(&mut raw_times) / (reps as f64 * nodes as f64);
    let raw_gpu = raw.end_to_end(reps)?;
    let roundtrip = raw.round_trip()?;

    let per_node = |d: Duration| d.as_secs_f64() * 1e6 / nodes as f64;
    outln!("adapter: {}", gpu.caps.summary());
    outln!(
        "chain of {nodes} unfused pointwise nodes, {elements} elements each, {reps} repetitions; \
         wall: median of 5 batched runs; end to end: median chain on the GPU, one compute pass \
         ({}); launches: sum of per-launch medians",
        end_to_end_clock(&gpu)
    );
    outln!(
        "{:<44} {:>12} {:>16} {:>16}",
        "us per node",
        "wall",
        "end to end",
        "launches"
    );
    outln!(
        "{:<44} {:>12.3} {:>16.3} {:>16.3}",
        "mesoflow executor (graph file, planned)",
        exec * 1e6,
        per_node(timed.end_to_end()),
        per_node(timed.launch_sum())
    );
    outln!(
        "{:<44} {:>12.3} {:>16.3} {:>16}",
        "raw wgpu (same kernel, one pass per submit)",
        raw_wall * 1e6,
        per_node(raw_gpu),
        "-"
    );
    outln!(
        "{:<44} {:>12.3} {:>16.3}",
        "ratio executor / raw",
        exec / raw_wall,
        timed.end_to_end().as_secs_f64() / raw_gpu.as_secs_f64()
    );
    outln!(
        "{:<44} {:>12.1}",
        "submit-and-wait round trip (us)",
        roundtrip.as_secs_f64() * 1e6
    );
    Ok(())
}

/// The same chain in raw wgpu: one pipeline, pre-made bind groups, all dispatches of a
/// submission in one compute pass.
struct RawChain<'g> {
    gpu: &'g GpuContext,
    dispatches: Vec<Dispatch>,
}

impl<'g> RawChain<'g> {
    fn new(
        gpu: &'g GpuContext,
        cache: &mut KernelCache,
        nodes: usize,
        elements: u32,
    ) -> Result<Self, BenchError> {
        let src = mesoflow::gpu::shaders::resolve(&raw_kernel_source())
            .map_err(mesoflow::gpu::CompileError::Library)?;
        let clock = storage(gpu, 16);
        let mut cx = CompileCtx {
            gpu,
            kernels: cache,
            clock: &clock,
            allocated: Default::default(),
        };
        let k = cx.kernel(&KernelSpec::new(
            "raw scale",
            src,
            &[
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::Uniform,
            ],
        ))?;
        let bufs: Vec<wgpu::Buffer> = (0..2).map(|_| storage(gpu, elements as u64 * 4)).collect();
        let uni = cx.uniform("n", bytemuck::bytes_of(&elements));
        let dispatches = (0..nodes)
            .map(|i| {
                cx.dispatch(
                    &k,
                    &[&bufs[i % 2], &bufs[(i + 1) % 2], &uni],
                    cx.grid_1d(elements as u64, WG_1D),
                )
            })
            .collect();
        Ok(RawChain { gpu, dispatches })
    }

    fn record(&self, pass: &mut wgpu::ComputePass, chains: u64) {
        for _ in 0..chains {
            for d in &self.dispatches {
                pass.set_pipeline(&d.kernel.pipeline);
                pass.set_bind_group(0, &d.bind_group, &[]);
                pass.dispatch_workgroups(d.workgroups[0], d.workgroups[1], d.workgroups[2]);
            }
        }
    }

    /// Wall seconds of `reps` chains, several per submission (as the executor batches
    /// steps), at most two submissions in flight.
    fn wall(&self, reps: u64) -> Result<f64, BenchError> {
        let per_submit = (4096 / (self.dispatches.len() + 1)).max(1) as u64;
        let t = Instant::now();
        let mut last = None;
        let mut done = 0;
        while done < reps {
            let n = per_submit.min(reps - done);
            let mut enc = self.gpu.device.create_command_encoder(&Default::default());
            self.record(&mut enc.begin_compute_pass(&Default::default()), n);
            let idx = self.gpu.queue.submit([enc.finish()]);
            if let Some(prev) = last.replace(idx) {
                self.gpu.wait(prev)?;
            }
            done += n;
        }
        if let Some(prev) = last {
            self.gpu.wait(prev)?;
        }
        Ok(t.elapsed().as_secs_f64())
    }

    /// Median time of one chain end to end: one pass per submission between
    /// timestamps, as the executor's `Profile::Steps` times a step (on the host around
    /// the submission where the device has no timestamp queries).
    fn end_to_end(&self, reps: u64) -> Result<Duration, BenchError> {
        let gpu = self.gpu;
        let queries = gpu.caps.timestamps.then(|| {
            gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("raw chain timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: 2,
            })
        });
        let resolve = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("raw chain timestamps resolve"),
            size: 16,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let period = gpu.queue.get_timestamp_period() as f64;
        let mut samples = Vec::new();
        for _ in 0..reps {
            let t = Instant::now();
            let mut enc = gpu.device.create_command_encoder(&Default::default());
            {
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("raw chain"),
                    timestamp_writes: queries.as_ref().map(|qs| wgpu::ComputePassTimestampWrites {
                        query_set: qs,
                        beginning_of_pass_write_index: Some(0),
                        end_of_pass_write_index: Some(1),
                    }),
                });
                self.record(&mut pass, 1);
            }
            if let Some(qs) = &queries {
                enc.resolve_query_set(qs, 0..2, &resolve, 0);
            }
            let idx = gpu.queue.submit([enc.finish()]);
            gpu.wait(idx)?;
            let host = t.elapsed();
            samples.push(match &queries {
                Some(_) => {
                    let ticks: Vec<u64> =
                        bytemuck::pod_collect_to_vec(&gpu.read_buffer(&resolve, 16)?);
                    Duration::from_nanos((ticks[1].saturating_sub(ticks[0]) as f64 * period) as u64)
                }
                None => host,
            });
        }
        Ok(median_duration(&samples))
    }

    /// Median submit-and-wait round trip of one tiny dispatch.
    fn round_trip(&self) -> Result<Duration, BenchError> {
        let mut samples = Vec::new();
        for _ in 0..50 {
            let t = Instant::now();
            let mut enc = self.gpu.device.create_command_encoder(&Default::default());
            {
                let mut pass = enc.begin_compute_pass(&Default::default());
                let d = &self.dispatches[0];
                pass.set_pipeline(&d.kernel.pipeline);
                pass.set_bind_group(0, &d.bind_group, &[]);
                pass.dispatch_workgroups(d.workgroups[0], d.workgroups[1], d.workgroups[2]);
            }
            let idx = self.gpu.queue.submit([enc.finish()]);
            self.gpu.wait(idx)?;
            samples.push(t.elapsed());
        }
        Ok(median_duration(&samples))
    }
}

fn raw_kernel_source() -> String {
    format!(
        "#import common/index.wgsl\n@group(0) @binding(0) var<storage, read> x: array<f32>;\n@group(0) @binding(1) var<storage, read_write> y: array<f32>;\n@group(0) @binding(2) var<uniform> n: vec4<u32>;\n@compute @workgroup_size({WG_1D})\nfn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {{\n    let i = flat_index(wid, nwg, lid, {WG_1D}u);\n    if (i < n.x) {{ y[i] = 1.0001 * x[i]; }}\n}}\n"
    )
}

fn storage(gpu: &GpuContext, bytes: u64) -> wgpu::Buffer {
    gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("bench"),
        size: bytes.max(16),
        usage: wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}
