//! A probe node for tests of what the executor runs: `countdown` (`out = x - 1`, `count =
//! (out > 0)` on one value), each launch adding 1 by an atomic to a buffer of its own that
//! the test reads: a side channel no graph has, so that work the executor runs (past a
//! loop's stop, on a step where only outputs read it) can be counted.

use std::sync::{Arc, Mutex};

use mesoflow::gpu::{
    Binding, CompileCtx, CompileError, DeviceCaps, Dispatch, GpuContext, KernelSpec, NodeIo,
};
use mesoflow::node::{
    GpuKernels, Lowering, Node, NodeKind, PortError, PortSpec, RefCtx, Registry, Signature,
};
use mesoflow::value::{PortType, RefArray, ValueType};

use super::registry;

/// The probe: its launches count into `launches`.
struct Countdown {
    launches: Arc<Mutex<Vec<wgpu::Buffer>>>,
}

const COUNTDOWN: &str = r#"
@group(0) @binding(0) var<storage, read> x: array<f32>;
@group(0) @binding(1) var<storage, read_write> out: array<f32>;
@group(0) @binding(2) var<storage, read_write> count: array<u32>;
@group(0) @binding(3) var<storage, read_write> launches: array<atomic<u32>>;

@compute @workgroup_size(1)
fn main() {
    atomicAdd(&launches[0], 1u);
    let v = x[0] - 1.0;
    out[0] = v;
    count[0] = select(0u, 1u, v > 0.0);
}
"#;

impl Node for Countdown {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let x = inputs[0].expect("required");
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
            ],
        ))?;
        let launches = cx.gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("countdown launches"),
            size: 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let d = cx.dispatch(
            &kernel,
            &[
                io.inputs[0].expect("required").buffer,
                io.outputs[0].buffer,
                io.outputs[1].buffer,
                &launches,
            ],
            [1, 1, 1],
        );
        self.launches.lock().expect("not poisoned").push(launches);
        Ok(vec![d])
    }
}

/// The launch counters of every `countdown` node compiled from a registry of
/// [`countdown_registry`].
#[derive(Clone)]
pub struct Launches(Arc<Mutex<Vec<wgpu::Buffer>>>);

impl Launches {
    /// Forgets the counters of the programs compiled so far.
    pub fn clear(&self) {
        self.0.lock().expect("not poisoned").clear();
    }

    /// The launches of every `countdown` node compiled since the last `clear`.
    pub fn count(&self, gpu: &GpuContext) -> u32 {
        self.0
            .lock()
            .expect("not poisoned")
            .iter()
            .map(|b| bytemuck::pod_read_unaligned::<u32>(&gpu.read_buffer(b, 4).unwrap()[..4]))
            .sum()
    }
}

/// The shipped registry with the probe kind `countdown` (input `x`, outputs `out` and
/// `count`), and the counters its nodes' launches add to.
pub fn countdown_registry() -> (Registry, Launches) {
    let launches = Arc::new(Mutex::new(Vec::new()));
    let mut reg = registry().clone();
    let shared = launches.clone();
    reg.add(
        NodeKind::declare("countdown", "test probe: x - 1 and whether it is positive")
            .input(PortSpec::new("x", PortType::RealArray, "the value"))
            .output(PortSpec::new("out", PortType::RealArray, "x - 1"))
            .output(PortSpec::new("count", PortType::Indices, "1 while out > 0"))
            .build(move |_| {
                Ok(Box::new(Countdown {
                    launches: shared.clone(),
                }))
            }),
    );
    (reg, Launches(launches))
}
