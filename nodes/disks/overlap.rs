//! `overlap_correction_round`: one round of S1's overlap correction (section 2.3, eq. 4;
//! Algorithm 2) along the edges of the torus mesh (`mesh.rs` layout): every pair of
//! neighbours closer than sigma is pushed apart along its line of centres, each particle
//! by delta (sigma - r) (the paper's delta* = sigma - r: the whole overlap, "a bounce"),
//! the sum over a particle's edges clamped to length sigma / 4 (S1 section 4.4, the norm:
//! summed corrections that point the same way would overshoot and diverge), then the
//! particle moves and wraps into the box.
//!
//! No float atomics: each particle gathers over its own edges, walking the fan of
//! triangles around it by twins from its lowest corner (`shaders/disks/overlap.wgsl`), so
//! the sums run in a fixed order. The count output is the number of overlapping pairs
//! (along edges) in the positions read: a round that counts 0 moved nothing, which is
//! when a loop stops. The mesh stays fixed while the rounds repeat (S1 section 4.4).
//!
//! **Tolerance.** A pair counts as overlapping below sigma - `overlap_tolerance` (8 f32
//! ulps of the largest coordinate, at least 1e-6 sigma): an overlap smaller than the
//! coordinates' resolution cannot be removed by moving them (the move rounds away), and
//! counting it kept loops going to their cap in dense, forced runs.

use super::flip::{check_mesh_twins, reference_mesh};
use super::mesh::MESH_WORDS;
use super::{minimum_image, wrap};
use crate::gpu::DeviceCaps;
use crate::gpu::{Binding, CompileCtx, CompileError, Dispatch, KernelSpec, NodeIo, WG_1D};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamKind, ParamSpec, PortError, PortSpec, RefCtx,
    Registry, RowError, Signature,
};
use crate::value::{HostArray, HostData, PortType, RefArray, ValueType};

/// The longest fan the kernel walks (`MAX_FAN` in the shader).
const MAX_FAN: usize = 128;

fn overlap_correction_round_kind() -> NodeKind {
    NodeKind::declare(
        "overlap_correction_round",
        "one round of S1's overlap correction along the mesh edges: each particle moves by delta (sigma - r) along the line of centres away from every neighbour closer than sigma, the sum clamped to sigma/4, wrapped into the box; `overlaps` counts the overlapping pairs read (0: nothing moved)",
    )
    .input(PortSpec::new(
        "positions",
        PortType::Particles(Some(2)),
        "positions (N x 2)",
    ))
    .input(PortSpec::new(
        "mesh",
        PortType::Indices,
        "the triangulation of the torus (2N triangles x 6 words, nodes/disks/mesh.rs)",
    ))
    .output(PortSpec::new(
        "positions",
        PortType::Particles(Some(2)),
        "the corrected positions (N x 2)",
    ))
    .output(PortSpec::new(
        "overlaps",
        PortType::Indices,
        "the number of overlapping pairs along edges before the round (1 word)",
    ))
    .param(ParamSpec::f32_positive("sigma", Some(1.0), "disk diameter sigma"))
    .param(ParamSpec::number(
        "delta",
        Some(1.0),
        0.0,
        10.0,
        "each particle of an overlapping pair moves by delta (sigma - r): S1 uses 1 (the whole overlap)",
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
        Ok(Box::new(OverlapCorrectionRound {
            sigma: p.number("sigma"),
            delta: p.number("delta"),
            box_lengths: [b[0], b[1]],
        }))
    })
}

pub struct OverlapCorrectionRound {
    sigma: f64,
    delta: f64,
    box_lengths: [f64; 2],
}

/// The overlap the correction leaves alone: 8 f32 ulps of the largest coordinate (half
/// the box), at least 1e-6 sigma.
pub fn overlap_tolerance(sigma: f64, l: [f64; 2]) -> f64 {
    (8.0 * f32::EPSILON as f64 * 0.5 * l[0].max(l[1])).max(1e-6 * sigma)
}

/// One round in f64, the twin of `shaders/disks/overlap.wgsl`: the corrected positions
/// and the number of overlapping pairs along edges.
pub fn overlap_round(
    mesh: &[u32],
    x: &[f64],
    l: [f64; 2],
    sigma: f64,
    delta: f64,
) -> (Vec<f64>, u32) {
    let n = x.len() / 2;
    let slots = mesh.len() / MESH_WORDS * 3;
    let mut first = vec![usize::MAX; n];
    for c in (0..slots).rev() {
        let v = mesh[MESH_WORDS * (c / 3) + c % 3] as usize;
        if v < n {
            first[v] = c;
        }
    }
    let mut out = vec![0.0; 2 * n];
    let mut count = 0;
    let limit = (sigma - overlap_tolerance(sigma, l)) as f32 as f64;
    for v in 0..n {
        let mut shift = [0.0f64; 2];
        let mut c = first[v];
        for _ in 0..MAX_FAN {
            if c >= slots {
                break;
            }
            let (t, k) = (c / 3, c % 3);
            let w = mesh[MESH_WORDS * t + (k + 1) % 3] as usize;
            let r = [0, 1].map(|a| minimum_image(x[2 * w + a] - x[2 * v + a], l[a]));
            let len = r[0].hypot(r[1]);
            if len < limit && len > 0.0 {
                for a in 0..2 {
                    shift[a] -= delta * (sigma - len) / len * r[a];
                }
                count += (w > v) as u32;
            }
            let u = mesh[MESH_WORDS * t + 3 + (k + 2) % 3] as usize;
            c = 3 * (u / 3) + (u % 3 + 2) % 3;
            if c == first[v] {
                break;
            }
        }
        let s = shift[0].hypot(shift[1]);
        let max_step = 0.25 * sigma;
        if s > max_step {
            shift = shift.map(|d| d * max_step / s);
        }
        for a in 0..2 {
            out[2 * v + a] = wrap(x[2 * v + a] + shift[a], l[a]);
        }
    }
    (out, count)
}

impl Node for OverlapCorrectionRound {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let Some(x @ ValueType::Particles { n, .. }) = inputs[0] else {
            unreachable!("port type checked")
        };
        let Some(ValueType::Indices { n: words }) = inputs[1] else {
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
        Ok(Signature::outputs(vec![x, ValueType::Indices { n: 1 }])
            .with_scratch(vec![4 * n as u64]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn check_input(&self, port: usize, data: &HostArray) -> Result<(), RowError> {
        match (port, &data.data) {
            (1, HostData::U32(mesh)) => check_mesh_twins(mesh),
            _ => Ok(()),
        }
    }

    fn checks_input(&self) -> bool {
        true
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let x = &inputs[0].as_ref().expect("required").data;
        let mesh = reference_mesh(&inputs[1]);
        let (out, count) = overlap_round(&mesh, x, self.box_lengths, self.sigma, self.delta);
        outputs[0].data = out;
        outputs[1].data = vec![count as f64];
    }
}

impl GpuKernels for OverlapCorrectionRound {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let x = io.inputs[0].expect("required");
        let mesh = io.inputs[1].expect("required");
        let ValueType::Particles { n, .. } = x.ty else {
            unreachable!()
        };
        let slots = (mesh.ty.words() / 2) as u32;
        let bindings = [
            Binding::StorageRead,
            Binding::StorageRead,
            Binding::StorageReadWrite,
            Binding::StorageReadWrite,
            Binding::StorageReadWrite,
            Binding::Uniform,
        ];
        let source = cx.shader("disks/overlap.wgsl")?;
        let words: [u32; 8] = [
            n,
            slots,
            (self.sigma as f32).to_bits(),
            (self.delta as f32).to_bits(),
            (self.box_lengths[0] as f32).to_bits(),
            (self.box_lengths[1] as f32).to_bits(),
            ((0.25 * self.sigma) as f32).to_bits(),
            ((self.sigma - overlap_tolerance(self.sigma, self.box_lengths)) as f32).to_bits(),
        ];
        let params = cx.uniform("overlap correction round", bytemuck::cast_slice(&words));
        let buffers = [
            x.buffer,
            mesh.buffer,
            io.outputs[0].buffer,
            io.scratch[0],
            io.outputs[1].buffer,
            &params,
        ];
        let mut out = Vec::new();
        for (entry, items) in [
            ("clear", n as u64),
            ("corners", slots as u64),
            ("correct", n as u64),
        ] {
            let kernel = cx.kernel(
                &KernelSpec::new(format!("overlap_{entry}"), source.clone(), &bindings)
                    .entry(entry),
            )?;
            out.push(cx.dispatch(&kernel, &buffers, cx.grid_1d(items.max(1), WG_1D)));
        }
        Ok(out)
    }
}

pub fn register(r: &mut Registry) {
    r.add(overlap_correction_round_kind());
}
