//! Harmonic bonds from a bond list kept per particle (compressed rows: `start`, N + 1
//! offsets into `partner`, each bond listed at both its ends, as a host builds it once
//! from a list of pairs): forces and energies by gathering, no atomics.

use crate::gpu::DeviceCaps;
use crate::gpu::{Binding, CompileCtx, CompileError, Dispatch, KernelSpec, NodeIo, WG_1D};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamKind, ParamSpec, PortError, PortSpec, RefCtx,
    Registry, Signature,
};
use crate::value::{PortType, RefArray, ValueType};

fn harmonic_bonds_kind() -> NodeKind {
    NodeKind::declare(
        "harmonic_bonds",
        "harmonic bonds U = k (r - r0)^2 / 2 from each particle's bond list (partner[start[i] .. start[i+1]], every bond listed at both ends): per particle the force sum k (r - r0) (x_j - x_i) / r and half its bonds' energy (minimum image along axes of positive box length; a gather, no atomics)",
    )
    .input(PortSpec::new(
        "positions",
        PortType::Particles(Some(3)),
        "positions (N x 3)",
    ))
    .input(PortSpec::new(
        "start",
        PortType::Indices,
        "N + 1 offsets: particle i's partners are partner[start[i] .. start[i+1]]",
    ))
    .input(PortSpec::new(
        "partner",
        PortType::Indices,
        "the bonded particle of each entry (an index past the last particle is skipped)",
    ))
    .output(PortSpec::new(
        "forces",
        PortType::Particles(Some(3)),
        "the bonds' force on each particle (N x 3)",
    ))
    .output(PortSpec::new(
        "energy",
        PortType::Particles(Some(1)),
        "half the energy of each particle's bonds (N x 1): their sum is the bonds' energy",
    ))
    .param(ParamSpec::f32_nonnegative(
        "stiffness",
        None,
        "spring constant k",
    ))
    .param(ParamSpec::f32_nonnegative(
        "rest_length",
        Some(0.0),
        "rest length r0",
    ))
    .param(ParamSpec {
        name: "box",
        kind: ParamKind::Numbers {
            len: Some(3),
            min: 0.0,
            max: 1e18,
        },
        default: Some(crate::expr::ParamValue::Numbers(vec![0.0, 0.0, 0.0])),
        doc: "box lengths for the minimum image (0: an open axis)",
    })
    .build(|p| {
        let b = p.numbers("box");
        Ok(Box::new(HarmonicBonds {
            stiffness: p.number("stiffness"),
            rest_length: p.number("rest_length"),
            box_lengths: [b[0], b[1], b[2]],
        }))
    })
}

struct HarmonicBonds {
    stiffness: f64,
    rest_length: f64,
    box_lengths: [f64; 3],
}

impl Node for HarmonicBonds {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let Some(ValueType::Particles { n, .. }) = inputs[0] else {
            unreachable!("port type checked")
        };
        let Some(ValueType::Indices { n: offsets }) = inputs[1] else {
            unreachable!("port type checked")
        };
        if offsets != n + 1 {
            return Err(PortError::new(
                "start",
                format!(
                    "expected N + 1 = {} offsets for {n} particles, got {offsets}",
                    n + 1
                ),
            ));
        }
        Ok(Signature::outputs(vec![
            ValueType::Particles { n, k: 3 },
            ValueType::Particles { n, k: 1 },
        ]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let x = &inputs[0].as_ref().expect("required").data;
        let start = &inputs[1].as_ref().expect("required").data;
        let partner = &inputs[2].as_ref().expect("required").data;
        let n = x.len() / 3;
        for i in 0..n {
            let (first, last) = (
                (start[i] as usize).min(partner.len()),
                (start[i + 1] as usize).min(partner.len()),
            );
            let mut f = [0.0; 3];
            let mut e = 0.0;
            for &j in &partner[first..last.max(first)] {
                let j = j as usize;
                if j >= n {
                    continue;
                }
                let r: [f64; 3] = std::array::from_fn(|d| {
                    let l = self.box_lengths[d];
                    let v = x[3 * j + d] - x[3 * i + d];
                    if l > 0.0 { v - l * (v / l).round() } else { v }
                });
                let len = r.iter().map(|v| v * v).sum::<f64>().sqrt();
                let stretch = len - self.rest_length;
                e += 0.25 * self.stiffness * stretch * stretch;
                if len > 0.0 {
                    for d in 0..3 {
                        f[d] += self.stiffness * stretch / len * r[d];
                    }
                }
            }
            outputs[0].data[3 * i..3 * i + 3].copy_from_slice(&f);
            outputs[1].data[i] = e;
        }
    }
}

impl GpuKernels for HarmonicBonds {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let x = io.inputs[0].expect("required");
        let start = io.inputs[1].expect("required");
        let partner = io.inputs[2].expect("required");
        let ValueType::Particles { n, .. } = x.ty else {
            unreachable!()
        };
        let ValueType::Indices { n: partners } = partner.ty else {
            unreachable!()
        };
        let kernel = cx.kernel(&KernelSpec::new(
            "harmonic_bonds",
            cx.shader("bonds/harmonic.wgsl")?,
            &[
                Binding::StorageRead,
                Binding::StorageRead,
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::StorageReadWrite,
                Binding::Uniform,
            ],
        ))?;
        let words: [u32; 8] = [
            n,
            partners,
            (self.stiffness as f32).to_bits(),
            (self.rest_length as f32).to_bits(),
            (self.box_lengths[0] as f32).to_bits(),
            (self.box_lengths[1] as f32).to_bits(),
            (self.box_lengths[2] as f32).to_bits(),
            0,
        ];
        let params = cx.uniform("bond params", bytemuck::cast_slice(&words));
        let groups = cx.grid_1d(n as u64, WG_1D);
        Ok(vec![cx.dispatch(
            &kernel,
            &[
                x.buffer,
                start.buffer,
                partner.buffer,
                io.outputs[0].buffer,
                io.outputs[1].buffer,
                &params,
            ],
            groups,
        )])
    }
}

pub fn register(r: &mut Registry) {
    r.add(harmonic_bonds_kind());
}
