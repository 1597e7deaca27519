//! Test probe kinds for loops and in-place outputs: `countdown` computes
//! `out = x - 1 (+ y where given)` and `count = (out[0] > 0)`, each launch adding 1 by an
//! atomic to a buffer of its own that the test reads ([`Launches`]): a side channel no
//! graph has, so that work the executor runs past a loop's stop can be seen.
//! `countdown_in_place` is the same with `out` declared in place of `x`
//! (`PortSpec::in_place_of`): where the plan gives both one buffer it reads `x` from
//! `out`, where not it reads `x`, so a wrong aliasing shows in its results.

use std::path::Path;
use std::sync::{Arc, Mutex};

use mesoflow::gpu::{
    Binding, CompileCtx, CompileError, DeviceCaps, Dispatch, GpuContext, KernelSpec, NodeIo,
};
use mesoflow::graph::Graph;
use mesoflow::node::{
    GpuKernels, Lowering, Node, NodeKind, PortError, PortSpec, RefCtx, Registry, Signature,
};
use mesoflow::value::{PortType, RefArray, ValueType};

use super::{load_with_registry, write_graph};

/// The launch counters of the probes compiled since the last [`Launches::clear`].
#[derive(Clone, Default)]
pub struct Launches(Arc<Mutex<Vec<wgpu::Buffer>>>);

impl Launches {
    pub fn clear(&self) {
        self.0.lock().expect("not poisoned").clear();
    }

    /// The launches of every probe compiled since the last clear, summed.
    pub fn total(&self, gpu: &GpuContext) -> u32 {
        self.0
            .lock()
            .expect("not poisoned")
            .iter()
            .map(|b| bytemuck::pod_read_unaligned::<u32>(&gpu.read_buffer(b, 4).unwrap()[..4]))
            .sum()
    }
}

struct Countdown {
    launches: Launches,
}

const COUNTDOWN: &str = r#"
struct Params { n: u32, has_y: u32, in_place: u32 }

@group(0) @binding(0) var<storage, read> x: array<f32>;
@group(0) @binding(1) var<storage, read_write> out: array<f32>;
@group(0) @binding(2) var<storage, read_write> count: array<u32>;
@group(0) @binding(3) var<storage, read_write> launches: array<atomic<u32>>;
@group(0) @binding(4) var<storage, read> y: array<f32>;
@group(0) @binding(5) var<uniform> params: Params;

@compute @workgroup_size(1)
fn main() {
    atomicAdd(&launches[0], 1u);
    for (var i = 0u; i < params.n; i++) {
        var v = 0.0;
        if (params.in_place == 1u) {
            v = out[i];
        } else {
            v = x[i];
        }
        v = v - 1.0;
        if (params.has_y == 1u) {
            v = v + y[i];
        }
        out[i] = v;
    }
    count[0] = select(0u, 1u, out[0] > 0.0);
}
"#;

impl Node for Countdown {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let x = inputs[0].expect("required");
        if inputs[1].is_some_and(|y| y != x) {
            return Err(PortError::new("y", "must have x's type"));
        }
        Ok(Signature::outputs(vec![x, ValueType::Indices { n: 1 }]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, _: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        for o in outputs {
            o.data.fill(f64::NAN);
        }
    }
}

impl GpuKernels for Countdown {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let kernel = cx.kernel(&KernelSpec::new(
            "countdown probe",
            COUNTDOWN,
            &[
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::StorageReadWrite,
                Binding::StorageReadWrite,
                Binding::StorageRead,
                Binding::Uniform,
            ],
        ))?;
        let launches = cx.gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("countdown launches"),
            size: 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let x = io.inputs[0].expect("required");
        // In place, x is read from `out` and a stand-in takes its read-only binding (wgpu
        // refuses one buffer bound read-only and read-write in a dispatch).
        let in_place = io.in_place(0, 0);
        let stand_in = cx.table("countdown stand-in", &[0; 16]);
        let y = io.inputs[1].map_or(&stand_in, |y| y.buffer);
        let params = cx.uniform(
            "countdown params",
            bytemuck::cast_slice(&[
                x.ty.words() as u32,
                io.inputs[1].is_some() as u32,
                in_place as u32,
            ]),
        );
        let d = cx.dispatch(
            &kernel,
            &[
                if in_place { &stand_in } else { x.buffer },
                io.outputs[0].buffer,
                io.outputs[1].buffer,
                &launches,
                y,
                &params,
            ],
            [1, 1, 1],
        );
        self.launches.0.lock().expect("not poisoned").push(launches);
        Ok(vec![d])
    }
}

/// The kind `countdown`, or `countdown_in_place` with `out` in place of `x`.
fn countdown_kind(in_place: bool, launches: &Launches) -> NodeKind {
    let out = PortSpec::new("out", PortType::RealArray, "x - 1 (+ y)");
    let (name, out) = if in_place {
        ("countdown_in_place", out.in_place_of("x"))
    } else {
        ("countdown", out)
    };
    let launches = launches.clone();
    NodeKind::declare(
        name,
        "test probe: x - 1 (+ y) and whether its first word is positive",
    )
    .input(PortSpec::new("x", PortType::RealArray, "the value"))
    .input(PortSpec::new("y", PortType::RealArray, "added").optional())
    .output(out)
    .output(PortSpec::new(
        "count",
        PortType::Indices,
        "1 while out[0] > 0",
    ))
    .build(move |_| {
        Ok(Box::new(Countdown {
            launches: launches.clone(),
        }))
    })
}

/// The standard registry with `countdown` and `countdown_in_place`, their launches
/// counted in `launches`.
pub fn probe_registry(launches: &Launches) -> Registry {
    let mut reg = super::registry().clone();
    reg.add(countdown_kind(false, launches));
    reg.add(countdown_kind(true, launches));
    reg
}

/// [`probe_registry`] with counters of its own.
pub fn countdown_registry() -> (Registry, Launches) {
    let launches = Launches::default();
    (probe_registry(&launches), launches)
}

/// `json` written to `dir` as `name` and loaded with the probe kinds, for the tests that
/// plan or run a probe graph without reading how often its probes launched.
pub fn load_probe_graph(dir: &Path, name: &str, json: &str) -> Graph {
    let reg = probe_registry(&Launches::default());
    load_with_registry(&write_graph(dir, name, json), &reg)
}
