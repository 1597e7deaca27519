//! The solid spheres' collisional coupling and motion (S2 §5.3.2, §5.4; 3D):
//! `mpcd_sphere_fill` (virtual particles filling each sphere's shell every step, which
//! join the cell sums through `mpcd_bin_solute` at the solvent's mass and collide through
//! a second `mpcd_collide`), `mpcd_sphere_force` (the kinetic impulse of the bounces plus
//! the virtual particles' momentum change, summed exactly; the force, and its mean after
//! the warm-up) and `mpcd_sphere_move` (fixed spheres, or Newton's equations with the
//! sphere's mass; no rotation: the source treats translation only).

use super::spheres::{
    SPHERE_WORDS, SphereUniform, check_sphere_layout, check_sphere_rows, fx_round_wide, impulse_of,
    impulse_words, sphere_bindings, sphere_count, sphere_kernels, sphere_ports, spheres_of,
};
use super::{
    F32_SCALE, Geometry, geometry_params, key_into, key_of, num, thermal_params, thermal_unit,
};
use crate::gpu::DeviceCaps;
use crate::gpu::{CompileCtx, CompileError, Dispatch, NodeIo, WG_1D};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamSpec, Params, PortError, PortRowError, PortSpec,
    RefCtx, RowError, Signature,
};
use crate::nodes::random;
use crate::value::{HostArray, HostData, PortType, RefArray, ValueType};

/// The shell the virtual particles fill reaches 2 sqrt(3) a inside the surface: the body
/// diagonal of a 2 x 2 x 2 supercell (S2 §5.3.2), the farthest a cell cut by the surface
/// reaches into the sphere under either collision rule.
pub const SHELL_CELLS: f64 = 3.464_101_615_137_754_6;

/// Inner radius of a sphere's virtual shell for cell size `a`.
pub fn shell_inner(r: f64, a: f64) -> f64 {
    (r - SHELL_CELLS * a).max(0.0)
}

/// Virtual particles for density `m` in the shell of a sphere of radius `r`.
pub fn shell_count(density: f64, r: f64, a: f64) -> f64 {
    let rin = shell_inner(r, a);
    density * 4.0 / 3.0 * std::f64::consts::PI * (r.powi(3) - rin.powi(3)) / a.powi(3)
}

fn dt_param() -> ParamSpec {
    ParamSpec::number(
        "dt",
        None,
        1.0 / F32_SCALE,
        F32_SCALE,
        "MPCD time step (the collision interval): force = impulse / dt; from 1e-30 to 1e30 (f32)",
    )
}

pub(super) fn mpcd_sphere_fill_kind() -> NodeKind {
    NodeKind::declare(
        "mpcd_sphere_fill",
        "MPCD virtual particles filling solid spheres (S2 §5.3.2, sphere filling; 3D): per sphere `per_sphere` particles uniform in the shell from max(R - 2 sqrt(3) a, 0) to R, Maxwell-Boltzmann velocities about the sphere's velocity, redrawn every step (Philox at the step, streams stream and stream + 1); bin them with mpcd_bin_solute at the solvent's mass and collide them with the solvent's mpcd_collide params",
    )
    .inputs(sphere_ports(
        "sphere velocities (S x 3; absent: at rest): the virtual particles' mean velocity",
    ))
    .output(PortSpec::new(
        "positions",
        PortType::Particles(Some(3)),
        "virtual particle positions (S K x 3, sphere j's rows j K to (j + 1) K), wrapped into the box",
    ))
    .output(PortSpec::new(
        "velocities",
        PortType::Particles(Some(3)),
        "virtual particle velocities (S K x 3)",
    ))
    .params(geometry_params())
    .params(thermal_params())
    .param(ParamSpec::number(
        "density",
        Some(10.0),
        f64::MIN_POSITIVE,
        16_777_216.0,
        "the solvent's mean particles per cell M: each sphere's shell holds M per cell volume",
    ))
    .param(ParamSpec::integer(
        "per_sphere",
        None,
        1.0,
        16_777_216.0,
        "virtual particles per sphere K: M x the shell's volume / a^3 (4/3 pi (R^3 - R_in^3) M / a^3, R_in = max(R - 2 sqrt(3) a, 0)), within 1% or 1 particle for every given radius",
    ))
    .param(random::seed_param())
    .param(random::stream_param())
    .build(|p| {
        let geo = Geometry::from_params(p)?;
        if geo.dims() != 3 {
            return Err("spheres need a 3D box (3 lengths)".into());
        }
        thermal_unit(p)?;
        let mut u = geo.thermal_uniform(p);
        u.kt = p.number("temperature") as f32;
        u.mass = p.number("mass") as f32;
        key_into(&mut u, p);
        let (seed, stream) = key_of(p);
        Ok(Box::new(MpcdSphereFill {
            vth: (p.number("temperature") / p.number("mass")).sqrt(),
            unit: thermal_unit(p)?,
            geo,
            u,
            seed,
            stream,
            density: p.number("density"),
            per: p.number("per_sphere") as u32,
        }))
    })
}

struct MpcdSphereFill {
    geo: Geometry,
    u: super::Uniform,
    seed: u64,
    stream: u32,
    vth: f64,
    unit: f64,
    density: f64,
    per: u32,
}

impl Node for MpcdSphereFill {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let s = sphere_count(inputs, 0)?;
        let n = s as u64 * self.per as u64;
        if 3 * n > u32::MAX as u64 {
            return Err(PortError::new(
                "sphere_positions",
                format!(
                    "{s} spheres x {} virtual particles are too many (3 S K below 2^32)",
                    self.per
                ),
            ));
        }
        let t = ValueType::Particles { n: n as u32, k: 3 };
        Ok(Signature::outputs(vec![t, t]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn checks_input(&self) -> bool {
        true
    }

    fn check_input(&self, port: usize, data: &HostArray) -> Result<(), RowError> {
        check_sphere_rows(&self.geo, port, data, self.unit)?;
        if let (1, HostData::F32(radii)) = (port, &data.data) {
            for (row, &r) in radii.iter().enumerate() {
                let want = shell_count(self.density, r as f64, self.geo.cell);
                let k = self.per as f64;
                if (k - want).abs() > (0.01 * want).max(1.0) {
                    return Err(RowError::new(
                        row,
                        format!(
                            "radius {r} needs {} virtual particles (density {} x the shell's {} cells: 4/3 pi (R^3 - R_in^3) / a^3, R_in = {}), but per_sphere is {}: give per_sphere = {} (all spheres of a graph share it, within 1% or 1)",
                            num(want.round()),
                            num(self.density),
                            num(want / self.density),
                            num(shell_inner(r as f64, self.geo.cell)),
                            self.per,
                            num(want.round())
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    fn checks_inputs_together(&self) -> bool {
        true
    }

    fn check_inputs_together(&self, data: &[Option<&HostArray>]) -> Result<(), PortRowError> {
        check_sphere_layout(&self.geo, data, 0)
    }

    fn notes(&self, _: &[Option<ValueType>]) -> Vec<String> {
        vec![format!("{} virtual particles per sphere", self.per)]
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], cx: RefCtx) {
        let spheres = spheres_of(
            inputs[0].as_ref().expect("required"),
            inputs[1].as_ref().expect("required"),
            inputs[2].as_ref(),
        );
        let k = self.per as usize;
        let (seed, stream, step) = (self.seed, self.stream, cx.step);
        let l = &self.geo.lengths;
        for (j, s) in spheres.iter().enumerate() {
            let rin = shell_inner(s.r, self.geo.cell);
            for i in 0..k {
                let q = (j * k + i) as u64;
                let theta = 2.0 * std::f64::consts::PI * random::uniform(3 * q, step, seed, stream);
                let z0 = 2.0 * random::uniform(3 * q + 1, step, seed, stream) - 1.0;
                let u = random::uniform(3 * q + 2, step, seed, stream);
                let r = (rin.powi(3) + u * (s.r.powi(3) - rin.powi(3))).cbrt();
                let s0 = (1.0 - z0 * z0).max(0.0).sqrt();
                let dir = [s0 * theta.cos(), s0 * theta.sin(), z0];
                for a in 0..3 {
                    let mut y = s.c[a] + r * dir[a];
                    if !(self.geo.walls && a == 2) {
                        y -= l[a] * (y / l[a] + 0.5).floor();
                        if y >= 0.5 * l[a] {
                            y -= l[a];
                        }
                    }
                    let e = 3 * q as usize + a;
                    outputs[0].data[e] = y;
                    outputs[1].data[e] = s.v[a]
                        + self.vth
                            * random::normal(3 * q + a as u64, step, seed, stream.wrapping_add(1));
                }
            }
        }
    }
}

impl GpuKernels for MpcdSphereFill {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let centres = io.inputs[0].expect("required");
        let ValueType::Particles { n: s, .. } = centres.ty else {
            unreachable!()
        };
        let moving = io.inputs[2];
        let su = SphereUniform {
            count: s,
            per: self.per,
            moving: u32::from(moving.is_some()),
            ..Default::default()
        };
        let [kernel] = sphere_kernels(
            cx,
            "mpcd_sphere_fill",
            "mpcd/sphere_fill.wgsl",
            &sphere_bindings(4, 2),
            ["main"],
        )?;
        let params = cx.uniform("mpcd sphere fill", bytemuck::bytes_of(&self.u));
        let sphere_params = cx.uniform("mpcd spheres", bytemuck::bytes_of(&su));
        Ok(vec![cx.dispatch(
            &kernel,
            &[
                &params,
                &sphere_params,
                cx.clock,
                centres.buffer,
                io.inputs[1].expect("required").buffer,
                moving.map_or(centres.buffer, |m| m.buffer),
                io.outputs[0].buffer,
                io.outputs[1].buffer,
            ],
            cx.grid_1d(s as u64 * self.per as u64, WG_1D),
        )])
    }
}

pub(super) fn mpcd_sphere_force_kind() -> NodeKind {
    NodeKind::declare(
        "mpcd_sphere_force",
        "MPCD force on solid spheres (S2 Eqs. 5.10-5.13): the kinetic impulse of the bounces (mpcd_stream_spheres) plus the collisional one, m (v_after - v_before) summed over each sphere's virtual particles (mpcd_sphere_fill, through mpcd_collide), exactly in 64-bit fixed point; the force impulse / dt, and its mean over the steps from `warmup` on",
    )
    .input(PortSpec::new(
        "kinetic",
        PortType::Indices,
        "the bounces' impulse per sphere (mpcd_stream_spheres' impulse: 6 words a sphere)",
    ))
    .input(PortSpec::new(
        "before",
        PortType::Particles(Some(3)),
        "virtual particle velocities before the collision (mpcd_sphere_fill's; S K x 3)",
    ))
    .input(PortSpec::new(
        "after",
        PortType::Particles(Some(3)),
        "the same after the collision (mpcd_collide's)",
    ))
    .output(PortSpec::new(
        "impulse",
        PortType::Indices,
        "momentum the solvent gave each sphere in the step: (lo, hi) u32 pairs of the 64-bit sums of x, y, z in units of m v_th / 2^24",
    ))
    .output(PortSpec::new(
        "forces",
        PortType::Particles(Some(3)),
        "force on each sphere in the step, impulse / dt (S x 3)",
    ))
    .output(
        PortSpec::new(
            "totals",
            PortType::Indices,
            "impulse summed over the steps from warmup on (6 words a sphere, as impulse), then the number of those steps",
        )
        .persistent(),
    )
    .output(PortSpec::new(
        "mean_forces",
        PortType::Particles(Some(3)),
        "mean force per sphere over the steps from warmup on (S x 3; zero before)",
    ))
    .params(thermal_params())
    .param(dt_param())
    .param(ParamSpec::integer(
        "warmup",
        Some(0.0),
        0.0,
        u32::MAX as f64,
        "steps before the mean force's first sample",
    ))
    .build(|p| {
        thermal_unit(p)?;
        let mut u = super::Uniform::default();
        (u.fix_v, u.fix_e) = super::fixed_scales(p.number("temperature"), p.number("mass"));
        u.mass = p.number("mass") as f32;
        u.dt = p.number("dt") as f32;
        Ok(Box::new(MpcdSphereForce {
            u,
            warmup: p.number("warmup") as u32,
        }))
    })
}

struct MpcdSphereForce {
    u: super::Uniform,
    warmup: u32,
}

impl MpcdSphereForce {
    /// (S, K) of these input types.
    fn shape(inputs: &[Option<ValueType>]) -> Result<(u32, u32), PortError> {
        let s = match inputs[0] {
            Some(ValueType::Indices { n }) if n > 0 && n % SPHERE_WORDS == 0 => n / SPHERE_WORDS,
            other => {
                return Err(PortError::new(
                    "kinetic",
                    format!(
                        "expected mpcd_stream_spheres' impulse ({SPHERE_WORDS} words a sphere), got {other:?}"
                    ),
                ));
            }
        };
        let n = match inputs[1] {
            Some(ValueType::Particles { n, k: 3 }) if n > 0 && n % s == 0 => n,
            other => {
                return Err(PortError::new(
                    "before",
                    format!(
                        "expected K virtual particles (x 3) for each of {s} spheres, got {other:?}"
                    ),
                ));
            }
        };
        if inputs[2] != inputs[1] {
            return Err(PortError::new(
                "after",
                format!("expected {n} x 3 like `before`, got {:?}", inputs[2]),
            ));
        }
        Ok((s, n / s))
    }
}

impl Node for MpcdSphereForce {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let (s, _) = Self::shape(inputs)?;
        let per_sphere = ValueType::Particles { n: s, k: 3 };
        Ok(Signature::outputs(vec![
            ValueType::Indices {
                n: SPHERE_WORDS * s,
            },
            per_sphere,
            ValueType::Indices {
                n: SPHERE_WORDS * s + 1,
            },
            per_sphere,
        ]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], cx: RefCtx) {
        let kinetic = &inputs[0].as_ref().expect("required").data;
        let before = &inputs[1].as_ref().expect("required").data;
        let after = &inputs[2].as_ref().expect("required").data;
        let s = kinetic.len() / SPHERE_WORDS as usize;
        let k = before.len() / 3 / s;
        let fix_v = self.u.fix_v as f64;
        let mut impulse: Vec<[i64; 3]> = (0..s).map(|j| impulse_of(kinetic, j)).collect();
        for q in 0..s * k {
            for a in 0..3 {
                impulse[q / k][a] += fx_round_wide((after[3 * q + a] - before[3 * q + a]) * fix_v);
            }
        }
        impulse_words(&mut outputs[0].data, &impulse);
        let unit = self.u.mass as f64 / (fix_v * self.u.dt as f64);
        let sample = cx.step >= self.warmup as u64;
        let totals = &mut outputs[2].data;
        let samples = totals[SPHERE_WORDS as usize * s] + if sample { 1.0 } else { 0.0 };
        let mut sums = vec![[0i64; 3]; s];
        for j in 0..s {
            let t = impulse_of(totals, j);
            for a in 0..3 {
                sums[j][a] = if sample {
                    t[a].wrapping_add(impulse[j][a])
                } else {
                    t[a]
                };
            }
        }
        impulse_words(totals, &sums);
        totals[SPHERE_WORDS as usize * s] = samples;
        for j in 0..s {
            for a in 0..3 {
                outputs[1].data[3 * j + a] = impulse[j][a] as f64 * unit;
                outputs[3].data[3 * j + a] = sums[j][a] as f64 * unit / samples.max(1.0);
            }
        }
    }
}

impl GpuKernels for MpcdSphereForce {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let types: Vec<Option<ValueType>> = io.inputs.iter().map(|i| i.map(|s| s.ty)).collect();
        let (s, k) = Self::shape(&types)
            .map_err(|e| CompileError::Unsupported(format!("mpcd_sphere_force: {e:?}")))?;
        let su = SphereUniform {
            count: s,
            per: k,
            warmup: self.warmup,
            ..Default::default()
        };
        let [start, gather, finish, count] = sphere_kernels(
            cx,
            "mpcd_sphere_force",
            "mpcd/sphere_force.wgsl",
            &sphere_bindings(4, 4),
            ["start", "gather", "finish", "count"],
        )?;
        let params = cx.uniform("mpcd sphere force", bytemuck::bytes_of(&self.u));
        let sphere_params = cx.uniform("mpcd spheres", bytemuck::bytes_of(&su));
        let input = |i: usize| io.inputs[i].expect("required").buffer;
        let buffers = [
            &params,
            &sphere_params,
            cx.clock,
            input(0),
            input(1),
            input(2),
            io.outputs[0].buffer,
            io.outputs[1].buffer,
            io.outputs[2].buffer,
            io.outputs[3].buffer,
        ];
        Ok(vec![
            cx.dispatch(
                &start,
                &buffers,
                cx.grid_1d((SPHERE_WORDS * s) as u64, WG_1D),
            ),
            cx.dispatch(&gather, &buffers, cx.grid_1d(s as u64 * k as u64, WG_1D)),
            cx.dispatch(&finish, &buffers, cx.grid_1d(s as u64, WG_1D)),
            cx.dispatch(&count, &buffers, [1, 1, 1]),
        ])
    }
}

pub(super) fn mpcd_sphere_move_kind() -> NodeKind {
    NodeKind::declare(
        "mpcd_sphere_move",
        "MPCD solid spheres' motion (3D): fixed (positions kept, velocities zero) or moving (with this step's impulse from mpcd_sphere_force: x += V dt wrapped into the box, then V += impulse / M; without one, the initial state: positions and given velocities, or zero, copied). Translation only",
    )
    .input(PortSpec::new(
        "positions",
        PortType::Particles(Some(3)),
        "sphere centres (S x 3)",
    ))
    .input(
        PortSpec::new(
            "velocities",
            PortType::Particles(Some(3)),
            "sphere velocities (S x 3; absent: zero)",
        )
        .optional(),
    )
    .input(
        PortSpec::new(
            "masses",
            PortType::Particles(Some(1)),
            "sphere masses (S x 1, > 0): needed to move with an impulse",
        )
        .optional(),
    )
    .input(
        PortSpec::new(
            "impulse",
            PortType::Indices,
            "this step's impulse per sphere (mpcd_sphere_force's); absent: the initial state",
        )
        .optional(),
    )
    .output(PortSpec::new(
        "positions",
        PortType::Particles(Some(3)),
        "sphere centres after the step (S x 3)",
    ))
    .output(PortSpec::new(
        "velocities",
        PortType::Particles(Some(3)),
        "sphere velocities after the step (S x 3)",
    ))
    .params(geometry_params())
    .params(thermal_params())
    .param(dt_param())
    .param(ParamSpec::choice(
        "mode",
        "fixed",
        &["fixed", "moving"],
        "fixed: spheres held in place at rest; moving: Newton's equations with each sphere's mass",
    ))
    .build(|p| Ok(Box::new(MpcdSphereMove::from_params(p)?)))
}

struct MpcdSphereMove {
    geo: Geometry,
    u: super::Uniform,
    moving: bool,
    /// The fixed-point unit v_th: sphere velocities stay below 128 of it.
    unit: f64,
}

impl MpcdSphereMove {
    fn from_params(p: &Params) -> Result<Self, String> {
        let geo = Geometry::from_params(p)?;
        if geo.dims() != 3 {
            return Err("spheres need a 3D box (3 lengths)".into());
        }
        let unit = thermal_unit(p)?;
        let mut u = geo.thermal_uniform(p);
        u.mass = p.number("mass") as f32;
        u.dt = p.number("dt") as f32;
        Ok(MpcdSphereMove {
            geo,
            u,
            moving: p.text("mode") == "moving",
            unit,
        })
    }
}

impl Node for MpcdSphereMove {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let s = match inputs[0] {
            Some(ValueType::Particles { n, k: 3 }) if n > 0 => n,
            other => {
                return Err(PortError::new(
                    "positions",
                    format!("expected S x 3 sphere centres, got {other:?}"),
                ));
            }
        };
        let want = |port: &'static str, t: Option<ValueType>, ok: ValueType| match t {
            None => Ok(()),
            Some(t) if t == ok => Ok(()),
            Some(t) => Err(PortError::new(
                port,
                format!("expected {ok} (one row per sphere), got {t}"),
            )),
        };
        want("velocities", inputs[1], ValueType::Particles { n: s, k: 3 })?;
        want("masses", inputs[2], ValueType::Particles { n: s, k: 1 })?;
        want(
            "impulse",
            inputs[3],
            ValueType::Indices {
                n: SPHERE_WORDS * s,
            },
        )?;
        if self.moving && inputs[3].is_some() && inputs[2].is_none() {
            return Err(PortError::new(
                "masses",
                "is required for moving spheres (mode moving): Newton's equations need each sphere's mass",
            ));
        }
        let t = ValueType::Particles { n: s, k: 3 };
        Ok(Signature::outputs(vec![t, t]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn checks_input(&self) -> bool {
        true
    }

    fn check_input(&self, port: usize, data: &HostArray) -> Result<(), RowError> {
        match (port, &data.data) {
            (0, _) => check_sphere_rows(&self.geo, 0, data, self.unit),
            // Given velocities: finite, in the fixed point's range (the bounces sum
            // 2 m (v - V)).
            (1, _) => check_sphere_rows(&self.geo, 2, data, self.unit),
            (2, HostData::F32(masses)) => {
                for (row, &mass) in masses.iter().enumerate() {
                    if !(mass.is_finite() && mass as f64 >= 1.0 / F32_SCALE) {
                        return Err(RowError::new(
                            row,
                            format!("mass {mass} is not a finite number of at least 1e-30"),
                        ));
                    }
                }
                Ok(())
            }
            _ => Ok(()),
        }
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let x = &inputs[0].as_ref().expect("required").data;
        let s = x.len() / 3;
        let l = &self.geo.lengths;
        let fix_v = self.u.fix_v as f64;
        for j in 0..s {
            let mut xj: [f64; 3] = std::array::from_fn(|a| x[3 * j + a]);
            let mut vj = [0.0; 3];
            if self.moving {
                if let Some(v) = &inputs[1] {
                    vj = std::array::from_fn(|a| v.data[3 * j + a]);
                }
                if let Some(imp) = &inputs[3] {
                    let mass = inputs[2].as_ref().expect("checked in infer").data[j];
                    let q = impulse_of(&imp.data, j);
                    for a in 0..3 {
                        xj[a] += vj[a] * self.u.dt as f64;
                        vj[a] += q[a] as f64 * self.u.mass as f64 / (fix_v * mass);
                        if !(self.geo.walls && a == 2) {
                            xj[a] -= l[a] * (xj[a] / l[a] + 0.5).floor();
                            if xj[a] >= 0.5 * l[a] {
                                xj[a] -= l[a];
                            }
                        }
                    }
                }
            }
            outputs[0].data[3 * j..3 * j + 3].copy_from_slice(&xj);
            outputs[1].data[3 * j..3 * j + 3].copy_from_slice(&vj);
        }
    }
}

impl GpuKernels for MpcdSphereMove {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let x = io.inputs[0].expect("required");
        let ValueType::Particles { n: s, .. } = x.ty else {
            unreachable!()
        };
        let su = SphereUniform {
            count: s,
            moving: u32::from(self.moving),
            has_velocity: u32::from(io.inputs[1].is_some()),
            has_impulse: u32::from(io.inputs[3].is_some()),
            ..Default::default()
        };
        let [kernel] = sphere_kernels(
            cx,
            "mpcd_sphere_move",
            "mpcd/sphere_move.wgsl",
            &sphere_bindings(4, 2),
            ["main"],
        )?;
        let params = cx.uniform("mpcd sphere move", bytemuck::bytes_of(&self.u));
        let sphere_params = cx.uniform("mpcd spheres", bytemuck::bytes_of(&su));
        let or_x = |i: usize| io.inputs[i].map_or(x.buffer, |b| b.buffer);
        Ok(vec![cx.dispatch(
            &kernel,
            &[
                &params,
                &sphere_params,
                x.buffer,
                or_x(1),
                or_x(2),
                or_x(3),
                io.outputs[0].buffer,
                io.outputs[1].buffer,
            ],
            cx.grid_1d(s as u64, 64),
        )])
    }
}
