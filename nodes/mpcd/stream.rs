//! `mpcd_stream`: ballistic streaming for one step under a body force along x, with
//! plates (bounce-back or specular) perpendicular to the last axis and a periodic wrap.

use super::{Geometry, Rows, check_rows, geometry_params, particle_ports};
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
    .param(ParamSpec::number("dt", None, 0.0, f64::MAX, "time step"))
    .param(ParamSpec::number(
        "mass",
        Some(1.0),
        f64::MIN_POSITIVE,
        f64::MAX,
        "particle mass m",
    ))
    .param(ParamSpec::number(
        "force",
        Some(0.0),
        f64::MIN,
        f64::MAX,
        "body force per particle along x",
    ))
    .param(ParamSpec::choice(
        "force_shape",
        "constant",
        &["constant", "sine"],
        "constant, or force * sin(2 pi z / L_z) (z the last axis; taken at the start of the step)",
    ))
    .build(|p| Ok(Box::new(MpcdStream::from_params(p)?)))
}

pub(crate) struct MpcdStream {
    geo: Geometry,
    slip: bool,
    dt: f64,
    accel: f64,
    sine: bool,
}

fn advance(x: &mut [f64], v: &mut [f64], g: f64, t: f64) {
    for a in 0..x.len() {
        x[a] += v[a] * t;
    }
    x[0] += 0.5 * g * t * t;
    v[0] += g * t;
}

impl MpcdStream {
    pub(crate) fn from_params(p: &Params) -> Result<Self, String> {
        Ok(MpcdStream {
            geo: Geometry::from_params(p)?,
            slip: p.text("wall_bc") == "slip",
            dt: p.number("dt"),
            accel: p.number("force") / p.number("mass"),
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
