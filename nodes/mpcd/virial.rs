//! `mpcd_virial`: the collisional (non-ideal) pressure of MPCD-BC from the momentum the
//! cell pairs exchange (digest V21: the source's equation of state, S2 Eq. 1.3, gives a
//! non-ideal share P_n / P of 37.1% at A = 0.01, tau = 0.02, M = 5 and 10.6% at A = 0.005,
//! tau = 0.05 with the 1/13 weights of the collision types).
//!
//! A collision step moves momentum m dv_i between the cells of a pair, both inside one
//! supercell; the momentum flux it carries is P = (1 / (d V tau)) sum_i m dv_i . r_i, r_i
//! the position of particle i's cell (any origin: the momentum changes of a supercell sum
//! to zero), here the cell's offset in its supercell, a (i_x & 1, i_y & 1, i_z & 1). SRD
//! and the thermostats change no cell's momentum: they add nothing. With plates the sum
//! also counts the momentum exchanged with the wall's cells.

use super::{
    Geometry, fx_round, geometry_params, rule_param, thermal_params, thermal_unit, value_of,
    words_of,
};
use crate::gpu::DeviceCaps;
use crate::gpu::{Binding, CompileCtx, CompileError, Dispatch, KernelSpec, NodeIo, WG_1D};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamSpec, PortError, PortSpec, RefCtx, Signature,
};
use crate::value::{PortType, RefArray, ValueType};

pub(super) fn mpcd_virial_kind() -> NodeKind {
    NodeKind::declare(
        "mpcd_virial",
        "MPCD collisional pressure: (1 / (d V dt)) sum_i m (v_after - v_before)_i . r_i over the sampled steps (step >= warmup, every `every`), r_i the offset a (i & 1) of particle i's cell in its 2 x 2 (x 2) supercell (MPCD-BC's pairs stay inside one); exact 64-bit sums; its mean",
    )
    .input(PortSpec::new("before", PortType::Particles(None), "velocities before the collision (N x d)"))
    .input(PortSpec::new("after", PortType::Particles(None), "velocities after the collision (N x d)"))
    .input(PortSpec::new("cell", PortType::Indices, "cell per particle (mpcd_bin)"))
    .output(
        PortSpec::new(
            "sums",
            PortType::Indices,
            "u32 words: [0] samples, [1, 2] the 64-bit sum over samples and particles of dv . (i & 1) in units of v_th / 2^24",
        )
        .persistent(),
    )
    .output(PortSpec::new("pressure", PortType::Scalar, "mean collisional pressure (NaN before a sample)"))
    .params(geometry_params())
    .params(thermal_params())
    .param(rule_param())
    .param(ParamSpec::number("dt", Some(0.1), 1e-30, 1e30, "collision interval tau"))
    .params(super::sampling_params())
    .build(|p| {
        let geo = Geometry::from_params(p)?;
        thermal_unit(p)?;
        let mut u = geo.thermal_uniform(p);
        u.set_sampling(p);
        u.mass = p.number("mass") as f32;
        u.dt = p.number("dt") as f32;
        Ok(Box::new(MpcdVirial { geo, u }))
    })
}

struct MpcdVirial {
    geo: Geometry,
    u: super::Uniform,
}

impl MpcdVirial {
    /// The pressure per unit of the sums per sample: m a / (d V dt fix_v).
    fn unit(&self) -> f64 {
        let volume: f64 = self.geo.lengths.iter().product();
        self.u.mass as f64 * self.geo.cell
            / (self.geo.dims() as f64 * volume * self.u.dt as f64 * self.u.fix_v as f64)
    }
}

impl Node for MpcdVirial {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let n = self.geo.particles("before", inputs[0])?;
        if inputs[1] != inputs[0] {
            return Err(PortError::new(
                "after",
                format!("expected {n} rows like before, got {:?}", inputs[1]),
            ));
        }
        if inputs[2] != Some(ValueType::Indices { n }) {
            return Err(PortError::new(
                "cell",
                format!("expected {n} indices, got {:?}", inputs[2]),
            ));
        }
        Ok(Signature::outputs(vec![
            ValueType::Indices { n: 3 },
            ValueType::Scalar,
        ]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], cx: RefCtx) {
        let step = cx.step as u32;
        let d = self.geo.dims();
        let acc = &mut outputs[0].data;
        if self.u.sampled(step) {
            let before = &inputs[0].as_ref().expect("required").data;
            let after = &inputs[1].as_ref().expect("required").data;
            let cell = &inputs[2].as_ref().expect("required").data;
            let (nx, ny) = (self.geo.cells[0], self.geo.cells[1]);
            let mut w = 0i64;
            for (p, &c) in cell.iter().enumerate() {
                let c = c as u32;
                let i = [
                    c % nx,
                    (c / nx) % ny,
                    if d == 3 { c / (nx * ny) } else { 0 },
                ];
                for a in 0..d {
                    if i[a] & 1 == 1 {
                        w += fx_round((after[p * d + a] - before[p * d + a]) * self.u.fix_v as f64);
                    }
                }
            }
            acc[0] += 1.0;
            let t = words_of(value_of(acc[1], acc[2]).wrapping_add(w));
            acc[1..3].copy_from_slice(&t);
        }
        let samples = outputs[0].data[0];
        let total = value_of(outputs[0].data[1], outputs[0].data[2]) as f64;
        outputs[1].data[0] = if samples > 0.0 {
            total * self.unit() / samples
        } else {
            f64::NAN
        };
    }
}

impl GpuKernels for MpcdVirial {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let before = io.inputs[0].expect("required");
        let ValueType::Particles { n, .. } = before.ty else {
            unreachable!()
        };
        let mut u = self.u;
        u.n = n;
        // The pressure unit, in the uniform's `ratio` word (unused here).
        u.ratio = self.unit() as f32;
        let source = cx.shader("mpcd/virial.wgsl")?;
        let bindings = [
            Binding::Uniform,
            Binding::StorageRead,
            Binding::StorageRead,
            Binding::StorageRead,
            Binding::StorageRead,
            Binding::StorageReadWrite,
            Binding::StorageReadWrite,
        ];
        let spec = |entry: &str| {
            KernelSpec::new(format!("mpcd_virial {entry}"), source.clone(), &bindings)
                .entry(entry)
                .constant("DIMS", self.geo.dims() as f64)
        };
        let (particles, finish) = (cx.kernel(&spec("particles"))?, cx.kernel(&spec("finish"))?);
        let params = cx.uniform("mpcd virial", bytemuck::bytes_of(&u));
        let buffers = [
            &params,
            cx.clock,
            before.buffer,
            io.inputs[1].expect("required").buffer,
            io.inputs[2].expect("required").buffer,
            io.outputs[0].buffer,
            io.outputs[1].buffer,
        ];
        Ok(vec![
            cx.dispatch(&particles, &buffers, cx.grid_1d(n as u64, WG_1D)),
            cx.dispatch(&finish, &buffers, [1, 1, 1]),
        ])
    }
}
