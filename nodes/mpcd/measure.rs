//! `mpcd_measure` (observables accumulated on the GPU after the warm-up, in a persistent
//! block of exact 64-bit fixed-point sums) and `mpcd_average` (their means).

use super::{
    Geometry, Rows, SUM_V, SumsLayout, check_rows, fx_round, geometry_params, thermal_params,
    thermal_unit, value_of, words_of,
};
use crate::gpu::DeviceCaps;
use crate::gpu::{Binding, CompileCtx, CompileError, Dispatch, KernelSpec, NodeIo, WG_1D};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamSpec, PortError, PortSpec, RefCtx, RowError,
    Signature,
};
use crate::value::{HostArray, PortType, RefArray, ValueType};

/// Words of the accumulator before the profile bins.
const HEAD: usize = 11;
/// Most profile bins (workgroup memory of the measuring kernel).
pub const MAX_BINS: f64 = 1024.0;

fn bins_param() -> ParamSpec {
    ParamSpec::integer(
        "bins",
        Some(16.0),
        1.0,
        MAX_BINS,
        "profile bins: equal slabs along the last axis",
    )
}

pub(super) fn mpcd_measure_kind() -> NodeKind {
    NodeKind::declare(
        "mpcd_measure",
        "MPCD observables summed over the sampled steps (step >= warmup, every `every`): momentum, cell temperature terms, v_x profile along the last axis",
    )
    .input(PortSpec::new(
        "positions",
        PortType::Particles(None),
        "positions (N x d)",
    ))
    .input(PortSpec::new(
        "velocities",
        PortType::Particles(None),
        "velocities (N x d): momentum and profile",
    ))
    .input(PortSpec::new(
        "sums",
        PortType::Indices,
        "cell sums (mpcd_bin): the cell means and counts of the temperature",
    ))
    .input(PortSpec::new(
        "cell",
        PortType::Indices,
        "cell per particle (mpcd_bin)",
    ))
    .input(PortSpec::new(
        "before",
        PortType::Particles(None),
        "velocities before the collision (N x d): temperature from them relative to the cell means",
    ))
    .output(
        PortSpec::new(
            "sums",
            PortType::Indices,
            "u32 words: samples; 64-bit (lo, hi) pairs of sum v_a (3), sum |v - u_c|^2, sum (n_c - 1); per bin sum v_x and count (fixed point of mpcd_bin)",
        )
        .persistent(),
    )
    .params(geometry_params())
    .params(thermal_params())
    .param(bins_param())
    .param(super::rule_param())
    .params(super::sampling_params())
    .build(|p| {
        let geo = Geometry::from_params(p)?;
        let mut u = geo.thermal_uniform(p);
        u.bins = p.number("bins") as u32;
        u.set_sampling(p);
        Ok(Box::new(MpcdMeasure {
            geo,
            u,
            unit: thermal_unit(p)?,
        }))
    })
}

struct MpcdMeasure {
    geo: Geometry,
    u: super::Uniform,
    /// The fixed-point unit v_th of the sums.
    unit: f64,
}

fn add(acc: &mut [f64], i: usize, v: i64) {
    let w = words_of(value_of(acc[i], acc[i + 1]).wrapping_add(v));
    acc[i..i + 2].copy_from_slice(&w);
}

impl Node for MpcdMeasure {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let n = self.geo.particles("positions", inputs[0])?;
        let nv = self.geo.particles("velocities", inputs[1])?;
        if n != nv {
            return Err(PortError::new(
                "velocities",
                format!("has {nv} rows but positions has {n}"),
            ));
        }
        SumsLayout::of_port(self.geo.ncells(), inputs[2], "mpcd_measure")?;
        if inputs[3] != Some(ValueType::Indices { n }) {
            return Err(PortError::new(
                "cell",
                format!(
                    "expected {n} indices (one per particle), got {:?}",
                    inputs[3]
                ),
            ));
        }
        let nb = self.geo.particles("before", inputs[4])?;
        if nb != n {
            return Err(PortError::new(
                "before",
                format!("has {nb} rows but positions has {n}"),
            ));
        }
        Ok(Signature::outputs(vec![ValueType::Indices {
            n: HEAD as u32 + 4 * self.u.bins,
        }]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn checks_input(&self) -> bool {
        true
    }

    fn check_input(&self, port: usize, data: &HostArray) -> Result<(), RowError> {
        // The velocities are summed in fixed point here, those before the collision
        // were in the cell sums.
        match port {
            0 => check_rows(&self.geo, Rows::Positions, data),
            1 | 4 => check_rows(&self.geo, Rows::Velocities(Some(self.unit)), data),
            _ => Ok(()),
        }
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], cx: RefCtx) {
        let step = cx.step as u32;
        if !self.u.sampled(step) {
            return;
        }
        let d = self.geo.dims();
        let x = &inputs[0].as_ref().expect("required").data;
        let v = &inputs[1].as_ref().expect("required").data;
        let sums = &inputs[2].as_ref().expect("required").data;
        let acc = &mut outputs[0].data;
        let (fix_v, fix_e) = (self.u.fix_v as f64, self.u.fix_e as f64);
        acc[0] += 1.0;
        let cell = &inputs[3].as_ref().expect("required").data;
        let before = &inputs[4].as_ref().expect("required").data;
        let mut dof = 0i64;
        for c in 0..self.geo.ncells() as usize {
            let count = SumsLayout::block(sums, c)[0];
            if count > 0.0 {
                dof += count as i64 - 1;
            }
        }
        let mut rel = 0.0;
        for p in 0..cell.len() {
            let s = SumsLayout::block(sums, cell[p] as usize);
            for a in 0..d {
                let u = value_of(s[SUM_V + 2 * a], s[SUM_V + 1 + 2 * a]) as f64 / (s[0] * fix_v);
                rel += (before[p * d + a] - u).powi(2);
            }
        }
        add(acc, 7, (rel * fix_e).round() as i64);
        add(acc, 9, dof);
        let bins = self.u.bins as usize;
        let w = d - 1;
        for p in 0..x.len() / d {
            for a in 0..d {
                add(acc, 1 + 2 * a, fx_round(v[p * d + a] * fix_v));
            }
            let z = x[p * d + w];
            let b = (((z / self.geo.lengths[w] + 0.5) * bins as f64).floor() as i64)
                .clamp(0, bins as i64 - 1) as usize;
            add(acc, HEAD + 4 * b, fx_round(v[p * d] * fix_v));
            add(acc, HEAD + 4 * b + 2, 1);
        }
    }
}

impl GpuKernels for MpcdMeasure {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let pos = io.inputs[0].expect("required");
        let ValueType::Particles { n, .. } = pos.ty else {
            unreachable!()
        };
        let mut u = self.u;
        u.n = n;
        let bindings = [
            Binding::Uniform,
            Binding::StorageRead,
            Binding::StorageRead,
            Binding::StorageRead,
            Binding::StorageRead,
            Binding::StorageRead,
            Binding::StorageRead,
            Binding::StorageReadWrite,
        ];
        let src = cx.shader("mpcd/measure.wgsl")?;
        let d = self.geo.dims() as f64;
        let cells = cx.kernel(
            &KernelSpec::new("mpcd_measure cells", src.clone(), &bindings)
                .entry("cells")
                .constant("DIMS", d),
        )?;
        let particles = cx.kernel(
            &KernelSpec::new("mpcd_measure particles", src, &bindings)
                .entry("particles")
                .constant("DIMS", d),
        )?;
        let params = cx.uniform("mpcd measure", bytemuck::bytes_of(&u));
        let buffers = [
            &params,
            cx.clock,
            pos.buffer,
            io.inputs[1].expect("required").buffer,
            io.inputs[2].expect("required").buffer,
            io.inputs[3].expect("required").buffer,
            io.inputs[4].expect("required").buffer,
            io.outputs[0].buffer,
        ];
        Ok(vec![
            cx.dispatch(&cells, &buffers, cx.grid_1d(u.ncells as u64, WG_1D)),
            cx.dispatch(&particles, &buffers, cx.grid_1d(n as u64, WG_1D)),
        ])
    }
}

pub(super) fn mpcd_average_kind() -> NodeKind {
    NodeKind::declare(
        "mpcd_average",
        "MPCD averages of mpcd_measure's sums: mean v_x per profile bin, temperature m sum|v - u_c|^2 / (d sum(n_c - 1)), mean total momentum",
    )
    .input(PortSpec::new(
        "sums",
        PortType::Indices,
        "mpcd_measure's sums",
    ))
    .output(PortSpec::new(
        "profile",
        PortType::Particles(Some(1)),
        "mean v_x per bin (bins x 1; NaN for a bin never sampled)",
    ))
    .output(PortSpec::new(
        "temperature",
        PortType::Scalar,
        "mean kT (NaN before a sample)",
    ))
    .output(PortSpec::new(
        "momentum",
        PortType::Particles(None),
        "mean total momentum (1 x d; NaN before a sample)",
    ))
    .params(geometry_params())
    .params(thermal_params())
    .param(bins_param())
    .build(|p| {
        let geo = Geometry::from_params(p)?;
        thermal_unit(p)?;
        let mut u = geo.thermal_uniform(p);
        u.mass = p.number("mass") as f32;
        u.bins = p.number("bins") as u32;
        Ok(Box::new(MpcdAverage { geo, u }))
    })
}

struct MpcdAverage {
    geo: Geometry,
    u: super::Uniform,
}

impl Node for MpcdAverage {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let want = HEAD as u32 + 4 * self.u.bins;
        if inputs[0] != Some(ValueType::Indices { n: want }) {
            return Err(PortError::new(
                "sums",
                format!(
                    "expected {want} words ({} bins), got {:?}; do mpcd_measure and mpcd_average have the same bins?",
                    self.u.bins, inputs[0]
                ),
            ));
        }
        Ok(Signature::outputs(vec![
            ValueType::Particles {
                n: self.u.bins,
                k: 1,
            },
            ValueType::Scalar,
            ValueType::Particles {
                n: 1,
                k: self.geo.dims() as u32,
            },
        ]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let acc = &inputs[0].as_ref().expect("required").data;
        let (fix_v, fix_e) = (self.u.fix_v as f64, self.u.fix_e as f64);
        let mass = self.u.mass as f64;
        let pair = |i: usize| value_of(acc[i], acc[i + 1]) as f64;
        for b in 0..self.u.bins as usize {
            let n = pair(HEAD + 4 * b + 2);
            outputs[0].data[b] = if n > 0.0 {
                pair(HEAD + 4 * b) / (n * fix_v)
            } else {
                f64::NAN
            };
        }
        let d = self.geo.dims();
        let dof = pair(9);
        outputs[1].data[0] = if dof > 0.0 {
            mass * (pair(7) / fix_e / (d as f64 * dof))
        } else {
            f64::NAN
        };
        for a in 0..d {
            outputs[2].data[a] = if acc[0] > 0.0 {
                mass * (pair(1 + 2 * a) / fix_v / acc[0])
            } else {
                f64::NAN
            };
        }
    }
}

impl GpuKernels for MpcdAverage {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let kernel = cx.kernel(
            &KernelSpec::new(
                "mpcd_average",
                cx.shader("mpcd/average.wgsl")?,
                &[
                    Binding::Uniform,
                    Binding::StorageRead,
                    Binding::StorageReadWrite,
                    Binding::StorageReadWrite,
                    Binding::StorageReadWrite,
                ],
            )
            .constant("DIMS", self.geo.dims() as f64),
        )?;
        let params = cx.uniform("mpcd average", bytemuck::bytes_of(&self.u));
        Ok(vec![cx.dispatch(
            &kernel,
            &[
                &params,
                io.inputs[0].expect("required").buffer,
                io.outputs[0].buffer,
                io.outputs[1].buffer,
                io.outputs[2].buffer,
            ],
            cx.grid_1d(self.u.bins as u64, WG_1D),
        )])
    }
}
