//! `mpcd_stream`: ballistic streaming for one step under a body force along x, with
//! plates (bounce-back or specular) perpendicular to the last axis and a periodic wrap.

use super::{
    F32_SCALE, FAR_IMAGES, Geometry, MAX_VELOCITY, MIN_FREE_PATH, Rows, WALL_PASSES, check_rows,
    geometry_params, mass_param, num, particle_ports, temperature_param, thermal_unit,
};
use crate::gpu::DeviceCaps;
use crate::gpu::{Binding, CompileCtx, CompileError, Dispatch, KernelSpec, NodeIo, WG_1D};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamSpec, Params, PortError, PortSpec, RefCtx, RowError,
    Signature,
};
use crate::value::{HostArray, PortType, RefArray, ValueType};

pub(super) fn mpcd_stream_kind() -> NodeKind {
    NodeKind::declare(
        "mpcd_stream",
        "MPCD streaming: x += v t + g t^2/2, v_x += g t (g = force/mass along x), exact wall crossings (bounce-back or specular plates), periodic wrap",
    )
    .inputs(particle_ports())
    .output(PortSpec::new(
        "positions",
        PortType::Particles(None),
        "positions after the step, wrapped into the box",
    ))
    .output(PortSpec::new(
        "velocities",
        PortType::Particles(None),
        "velocities after the step",
    ))
    .params(geometry_params())
    .param(ParamSpec::choice(
        "wall_bc",
        "no_slip",
        &["no_slip", "slip"],
        "no_slip: bounce-back (v -> -v); slip: specular reflection (v_z -> -v_z)",
    ))
    .param(ParamSpec::number(
        "dt",
        None,
        0.0,
        F32_SCALE,
        "time step: 0 (no streaming), or a mean free path dt v_th (v_th = sqrt(temperature / mass), 1 at temperature 0) that the f32 streaming carries: at least 2^-20 of the largest box length (a step moves a particle by 16 ulps of its position or more), and at most 1024 / 128 = 8 periodic box lengths and, with plates, 14 / 128 of the gap (a particle at 128 v_th, the cell sums' limit, then moves at most 1024 box lengths, where f32 wrapping keeps its place to 2^-13 L, and crosses the gap at most 14 times, within the kernel's 16 passes)",
    ))
    .param(mass_param())
    .param(ParamSpec::number(
        "force",
        Some(0.0),
        -F32_SCALE,
        F32_SCALE,
        "body force per particle along x: from -1e30 to 1e30, and |force| / mass x dt (a step's velocity gain) below 128 v_th, the cell sums' range",
    ))
    .param(ParamSpec::choice(
        "force_shape",
        "constant",
        &["constant", "sine"],
        "constant, or force * sin(2 pi z / L_z) (z the last axis; taken at the start of the step)",
    ))
    .param(temperature_param())
    .build(|p| Ok(Box::new(MpcdStream::from_params(p)?)))
}

pub(crate) struct MpcdStream {
    pub(super) geo: Geometry,
    pub(super) slip: bool,
    pub(super) dt: f64,
    pub(super) accel: f64,
    pub(super) sine: bool,
}

/// Whether the mean free path dt v_th is one the f32 streaming carries (`dt`'s doc): the
/// error names dt, temperature and mass, which set it.
fn check_streaming(geo: &Geometry, dt: f64, vth: f64) -> Result<(), String> {
    if dt == 0.0 {
        return Ok(());
    }
    let free = dt * vth;
    let path = format!(
        "the mean free path dt x v_th = {} x {} = {} (v_th = sqrt(temperature / mass), 1 at temperature 0)",
        num(dt),
        num(vth),
        num(free)
    );
    let longest = geo.lengths.iter().cloned().fold(0.0, f64::max);
    if free < MIN_FREE_PATH * longest {
        return Err(format!(
            "{path} is below 2^-20 of the box length {}: f32 positions would not resolve a step; give a larger dt or temperature, or a smaller mass (or dt 0: no streaming)",
            num(longest)
        ));
    }
    let d = geo.dims();
    for (a, &l) in geo.lengths.iter().enumerate() {
        let walled = geo.walls && a == d - 1;
        let (most, why) = if walled {
            (
                (WALL_PASSES - 2.0) * l / MAX_VELOCITY,
                "a particle at 128 v_th (the cell sums' limit) would cross the gap between the plates more than 14 times in a step, past the streaming kernel's 16 passes",
            )
        } else {
            (
                FAR_IMAGES * l / MAX_VELOCITY,
                "a particle at 128 v_th (the cell sums' limit) would move more than 1024 box lengths in a step, where f32 wrapping loses its place",
            )
        };
        if free > most {
            return Err(format!(
                "{path} is more than {} for the box length {} along axis {a}: {why}; give a smaller dt or temperature, or a larger mass",
                num(most),
                num(l)
            ));
        }
    }
    Ok(())
}

pub(super) fn advance(x: &mut [f64], v: &mut [f64], g: f64, t: f64) {
    for a in 0..x.len() {
        x[a] += v[a] * t;
    }
    x[0] += 0.5 * g * t * t;
    v[0] += g * t;
}

impl MpcdStream {
    pub(crate) fn from_params(p: &Params) -> Result<Self, String> {
        let geo = Geometry::from_params(p)?;
        let vth = thermal_unit(p)?;
        let (dt, force, mass) = (p.number("dt"), p.number("force"), p.number("mass"));
        check_streaming(&geo, dt, vth)?;
        let accel = force / mass;
        if accel.abs() > F32_SCALE || accel.abs() * dt >= MAX_VELOCITY * vth {
            return Err(format!(
                "force / mass = {} / {} = {} gives a velocity gain of {} per step dt = {}, not below 128 v_th = {} (v_th = sqrt(temperature / mass), 1 at temperature 0; the cell sums carry velocities below 128 v_th) or past 1e30: change force, mass or dt",
                num(force),
                num(mass),
                num(accel),
                num(accel.abs() * dt),
                num(dt),
                num(MAX_VELOCITY * vth)
            ));
        }
        Ok(MpcdStream {
            geo,
            slip: p.text("wall_bc") == "slip",
            dt,
            accel,
            sine: p.text("force_shape") == "sine",
        })
    }

    /// Sets the streaming fields of an MPCD parameter block.
    pub(crate) fn uniform_into(&self, u: &mut super::Uniform) {
        u.wall_slip = u32::from(self.slip);
        u.dt = self.dt as f32;
        u.accel = self.accel as f32;
        u.force_shape = u32::from(self.sine);
    }

    /// One particle's step in f64 (the reference of the kernel).
    pub fn step(&self, x: &mut [f64], v: &mut [f64]) {
        let d = self.geo.dims();
        let w = d - 1;
        let l = &self.geo.lengths;
        let g = if self.sine {
            self.accel * (2.0 * std::f64::consts::PI * x[w] / l[w]).sin()
        } else {
            self.accel
        };
        if !self.geo.walls {
            advance(x, v, g, self.dt);
        } else {
            let h = 0.5 * l[w];
            let mut left = self.dt;
            for _ in 0..16 {
                if left <= 0.0 {
                    break;
                }
                let vz = v[w];
                let (hit, wall) = if vz > 0.0 {
                    (((h - x[w]) / vz).max(0.0), h)
                } else if vz < 0.0 {
                    (((-h - x[w]) / vz).max(0.0), -h)
                } else {
                    (left, 0.0)
                };
                if hit >= left {
                    advance(x, v, g, left);
                    left = 0.0;
                } else {
                    advance(x, v, g, hit);
                    x[w] = wall;
                    if self.slip {
                        v[w] = -v[w];
                    } else {
                        v.iter_mut().for_each(|c| *c = -*c);
                    }
                    left -= hit;
                }
            }
            x[w] = x[w].clamp(-h, h);
        }
        for a in 0..d {
            if !self.geo.walls || a != w {
                let mut y = x[a] - l[a] * (x[a] / l[a] + 0.5).floor();
                if y >= 0.5 * l[a] {
                    y -= l[a];
                }
                x[a] = y;
            }
        }
    }
}

impl Node for MpcdStream {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let n = self.geo.particles("positions", inputs[0])?;
        let nv = self.geo.particles("velocities", inputs[1])?;
        if n != nv {
            return Err(PortError::new(
                "velocities",
                format!("has {nv} rows but positions has {n}"),
            ));
        }
        let t = inputs[0].expect("checked");
        Ok(Signature::outputs(vec![t, t]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn checks_input(&self) -> bool {
        true
    }

    fn check_input(&self, port: usize, data: &HostArray) -> Result<(), RowError> {
        let rows = match port {
            0 => Rows::Positions,
            _ => Rows::Velocities(None),
        };
        check_rows(&self.geo, rows, data)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let d = self.geo.dims();
        let x = &inputs[0].as_ref().expect("required").data;
        let v = &inputs[1].as_ref().expect("required").data;
        let (xo, vo) = outputs.split_at_mut(1);
        for p in 0..x.len() / d {
            let mut xp = x[p * d..(p + 1) * d].to_vec();
            let mut vp = v[p * d..(p + 1) * d].to_vec();
            self.step(&mut xp, &mut vp);
            xo[0].data[p * d..(p + 1) * d].copy_from_slice(&xp);
            vo[0].data[p * d..(p + 1) * d].copy_from_slice(&vp);
        }
    }
}

impl GpuKernels for MpcdStream {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let pos = io.inputs[0].expect("required");
        let vel = io.inputs[1].expect("required");
        let ValueType::Particles { n, .. } = pos.ty else {
            unreachable!()
        };
        let mut u = self.geo.uniform();
        u.n = n;
        self.uniform_into(&mut u);
        let kernel = cx.kernel(
            &KernelSpec::new(
                "mpcd_stream",
                cx.shader("mpcd/stream.wgsl")?,
                &[
                    Binding::Uniform,
                    Binding::StorageRead,
                    Binding::StorageRead,
                    Binding::StorageReadWrite,
                    Binding::StorageReadWrite,
                ],
            )
            .constant("DIMS", self.geo.dims() as f64),
        )?;
        let params = cx.uniform("mpcd stream", bytemuck::bytes_of(&u));
        Ok(vec![cx.dispatch(
            &kernel,
            &[
                &params,
                pos.buffer,
                vel.buffer,
                io.outputs[0].buffer,
                io.outputs[1].buffer,
            ],
            cx.grid_1d(n as u64, WG_1D),
        )])
    }
}
