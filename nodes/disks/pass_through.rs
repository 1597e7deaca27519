//! `pass_through_count`: S1 section 4.3's check of a move (step 2a): the mesh edges whose
//! end points passed through each other, r0 . r1 < 0 for the edge vector before and
//! after (minimum image). Physically impossible, it means the time step was too large:
//! S1 redoes such a step with a smaller dt. Here the count is an output per step for the
//! caller to act on (graphs/bd_delaunay.json reports it); the flips cannot repair such a
//! mesh in general.

use super::flip::{check_mesh_twins, reference_mesh};
use super::mesh::MESH_WORDS;
use super::minimum_image;
use crate::gpu::DeviceCaps;
use crate::gpu::{Binding, CompileCtx, CompileError, Dispatch, KernelSpec, NodeIo, WG_1D};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamKind, ParamSpec, PortError, PortSpec, RefCtx,
    Registry, RowError, Signature,
};
use crate::value::{HostArray, HostData, PortType, RefArray, ValueType};

fn pass_through_count_kind() -> NodeKind {
    NodeKind::declare(
        "pass_through_count",
        "S1's pass-through check of a move: the number of mesh edges whose end points passed through each other (r0 . r1 < 0 for the edge vector before and after, minimum image); nonzero means the step was too large",
    )
    .input(PortSpec::new(
        "before",
        PortType::Particles(Some(2)),
        "positions before the move (N x 2)",
    ))
    .input(PortSpec::new(
        "after",
        PortType::Particles(Some(2)),
        "positions after the move (N x 2)",
    ))
    .input(PortSpec::new(
        "mesh",
        PortType::Indices,
        "the triangulation of the torus (2N triangles x 6 words, nodes/disks/mesh.rs)",
    ))
    .output(PortSpec::new(
        "count",
        PortType::Indices,
        "the edges passed through (1 word)",
    ))
    .param(ParamSpec {
        name: "box",
        kind: ParamKind::Numbers {
            len: Some(2),
            min: 1e-18,
            max: 1e18,
        },
        default: None,
        doc: "box lengths (Lx, Ly) of the torus",
    })
    .build(|p| {
        let b = p.numbers("box");
        Ok(Box::new(PassThroughCount {
            box_lengths: [b[0], b[1]],
        }))
    })
}

pub struct PassThroughCount {
    box_lengths: [f64; 2],
}

/// The f64 count: edges (each once) with r0 . r1 < 0.
pub fn pass_throughs(mesh: &[u32], before: &[f64], after: &[f64], l: [f64; 2]) -> u32 {
    let mut count = 0;
    for s in 0..mesh.len() / MESH_WORDS * 3 {
        let (t, k) = (s / 3, s % 3);
        if (mesh[MESH_WORDS * t + 3 + k] as usize) <= s {
            continue;
        }
        let b = mesh[MESH_WORDS * t + (k + 1) % 3] as usize;
        let c = mesh[MESH_WORDS * t + (k + 2) % 3] as usize;
        let r = |x: &[f64]| [0, 1].map(|a| minimum_image(x[2 * c + a] - x[2 * b + a], l[a]));
        let (r0, r1) = (r(before), r(after));
        count += (r0[0] * r1[0] + r0[1] * r1[1] < 0.0) as u32;
    }
    count
}

impl Node for PassThroughCount {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let (Some(before), Some(after)) = (inputs[0], inputs[1]) else {
            unreachable!("required")
        };
        if before != after {
            return Err(PortError::new(
                "after",
                format!("is {after} but before is {before}: the same particles"),
            ));
        }
        let ValueType::Particles { n, .. } = before else {
            unreachable!("port type checked")
        };
        let Some(ValueType::Indices { n: words }) = inputs[2] else {
            unreachable!("port type checked")
        };
        if words as u64 != 2 * MESH_WORDS as u64 * n as u64 {
            return Err(PortError::new(
                "mesh",
                format!(
                    "has {words} words; a triangulation of the torus over {n} points has 2N = {} triangles of {MESH_WORDS} words",
                    2 * n as u64
                ),
            ));
        }
        Ok(Signature::outputs(vec![ValueType::Indices { n: 1 }]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn check_input(&self, port: usize, data: &HostArray) -> Result<(), RowError> {
        match (port, &data.data) {
            (2, HostData::U32(mesh)) => check_mesh_twins(mesh),
            _ => Ok(()),
        }
    }

    fn checks_input(&self) -> bool {
        true
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let before = &inputs[0].as_ref().expect("required").data;
        let after = &inputs[1].as_ref().expect("required").data;
        let mesh = reference_mesh(&inputs[2]);
        outputs[0].data = vec![pass_throughs(&mesh, before, after, self.box_lengths) as f64];
    }
}

impl GpuKernels for PassThroughCount {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let before = io.inputs[0].expect("required");
        let after = io.inputs[1].expect("required");
        let mesh = io.inputs[2].expect("required");
        let slots = (mesh.ty.words() / 2) as u32;
        let kernel = cx.kernel(&KernelSpec::new(
            "pass_through_count",
            cx.shader("disks/pass_through.wgsl")?,
            &[
                Binding::StorageRead,
                Binding::StorageRead,
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::Uniform,
            ],
        ))?;
        let words: [u32; 4] = [
            slots,
            0,
            (self.box_lengths[0] as f32).to_bits(),
            (self.box_lengths[1] as f32).to_bits(),
        ];
        let params = cx.uniform("pass through", bytemuck::cast_slice(&words));
        let clear = cx.fill(io.outputs[0].buffer, 1, 0)?;
        Ok(vec![
            clear,
            cx.dispatch(
                &kernel,
                &[
                    before.buffer,
                    after.buffer,
                    mesh.buffer,
                    io.outputs[0].buffer,
                    &params,
                ],
                cx.grid_1d(slots as u64, WG_1D),
            ),
        ])
    }
}

pub fn register(r: &mut Registry) {
    r.add(pass_through_count_kind());
}
