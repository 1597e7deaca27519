//! `mpcd_sphere_profile`: the solvent's velocity tangential to a sphere's surface along a
//! thin cylinder through its centre (S2 §5.5.1, Eqs. 5.14-5.16, Fig. 5.5), accumulated
//! over the sampled steps in exact 64-bit fixed-point sums.
//!
//! The cylinder runs from A = C - (L_C / 2) e to B = C + (L_C / 2) e, C the sphere's centre,
//! e the unit `axis`, radius R_C (`radius`; the source takes 0.1 R). A solvent particle at P
//! (nearest periodic image of P - C) is inside when k = AP . e is in [0, L_C) and its
//! squared distance m^2 = |AP - k e|^2 from the axis is below R_C^2 (Eqs. 5.14-5.15); its
//! bin is b = floor(k per_length) (Eq. 5.16 with alpha = `bins_per_cell` per cell length a:
//! per_length = alpha / a). The source adds "the parallel component" of the velocity: here
//! the component along the unit `tangent` (perpendicular to the axis: where the axis
//! crosses the surface, along its normal, the tangent lies in the surface), relative to
//! the sphere's velocity (moving spheres; zero for fixed ones). The flow of the graphs is
//! along x, so a cylinder along y or z with tangent x reads the flow past the sphere.

use super::spheres::{min_image, sphere_bindings, sphere_kernels, sphere_ports};
use super::{
    Geometry, Rows, check_rows, fx_round, geometry_params, num, thermal_params, value_of, words_of,
};
use crate::expr::ParamValue;
use crate::gpu::DeviceCaps;
use crate::gpu::{CompileCtx, CompileError, Dispatch, NodeIo, WG_1D};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamKind, ParamSpec, PortError, PortSpec, RefCtx,
    RowError, Signature,
};
use crate::value::{HostArray, PortType, RefArray, ValueType};

/// Most bins of a profile.
pub const MAX_PROFILE_BINS: u32 = 4096;

/// The cylinder block of the kernel (`struct Cylinder` of shaders/mpcd/sphere_profile.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct CylinderUniform {
    axis: [f32; 4],
    tangent: [f32; 4],
    length: f32,
    radius: f32,
    per_length: f32,
    sphere: u32,
    bins: u32,
    moving: u32,
    spheres: u32,
    pad: u32,
}

fn unit_vector(p: &crate::node::Params, name: &str) -> Result<[f64; 3], String> {
    let v = p.numbers(name);
    if v.len() != 3 {
        return Err(format!("`{name}` needs 3 components, got {}", v.len()));
    }
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if !(n.is_finite() && n > 0.0) {
        return Err(format!("`{name}` {v:?} has no direction (length {n})"));
    }
    Ok([v[0] / n, v[1] / n, v[2] / n])
}

fn vector_param(name: &'static str, default: [f64; 3], doc: &'static str) -> ParamSpec {
    ParamSpec {
        name,
        kind: ParamKind::Numbers {
            len: Some(3),
            min: -1e18,
            max: 1e18,
        },
        default: Some(ParamValue::Numbers(default.to_vec())),
        doc,
    }
}

pub(super) fn mpcd_sphere_profile_kind() -> NodeKind {
    NodeKind::declare(
        "mpcd_sphere_profile",
        "MPCD solvent velocity tangential to a sphere along a cylinder through its centre (S2 §5.5.1, Eqs. 5.14-5.16): solvent particles within `radius` of the axis C + s e, s in [-length/2, length/2), binned by s in bins of a / bins_per_cell; per bin the sum of (v - V) . tangent and the count over the sampled steps (step >= warmup, every `every`), exact; the profile: bin centre s, mean tangential velocity, solvent number density",
    )
    .input(PortSpec::new(
        "positions",
        PortType::Particles(Some(3)),
        "solvent positions (N x 3)",
    ))
    .input(PortSpec::new(
        "velocities",
        PortType::Particles(Some(3)),
        "solvent velocities (N x 3)",
    ))
    .inputs(
        sphere_ports("sphere velocities (S x 3; absent: at rest): the tangential velocity is relative to the sphere's")
            .into_iter()
            .enumerate()
            .filter(|(i, _)| *i != 1)
            .map(|(_, p)| p),
    )
    .output(
        PortSpec::new(
            "sums",
            PortType::Indices,
            "u32 words: [0] samples, then per bin b (lo, hi) pairs of 64-bit sums at 1 + 4b (tangential velocity, units v_th / 2^24) and 3 + 4b (particle count)",
        )
        .persistent(),
    )
    .output(PortSpec::new(
        "profile",
        PortType::Particles(Some(3)),
        "per bin (bins x 3): s of the bin centre along the axis from the sphere's centre, mean tangential velocity (NaN for a bin no particle entered), mean number density (particles per sample over the bin's volume pi radius^2 a / bins_per_cell; NaN before a sample)",
    ))
    .params(geometry_params())
    .params(thermal_params())
    .param(ParamSpec::integer("sphere", Some(0.0), 0.0, u32::MAX as f64, "the sphere (row of sphere_positions) the cylinder goes through"))
    .param(vector_param("axis", [0.0, 1.0, 0.0], "direction e of the cylinder's axis (normalised)"))
    .param(vector_param("tangent", [1.0, 0.0, 0.0], "direction of the velocity component measured (normalised; perpendicular to axis)"))
    .param(ParamSpec::number("length", None, 1e-18, 1e18, "cylinder length L_C, centred on the sphere's centre; the cylinder within half a box length of the centre along each periodic axis (particles are taken at their nearest image of the centre)"))
    .param(ParamSpec::number("radius", None, 1e-18, 1e18, "cylinder radius R_C (the source: 0.1 R)"))
    .param(ParamSpec::number("bins_per_cell", Some(10.0), 1e-6, 1e6, "bins per cell length a (the source's alpha: 10)"))
    .params(super::sampling_params())
    .build(|p| {
        let geo = Geometry::from_params(p)?;
        if geo.dims() != 3 {
            return Err("spheres need a 3D box (3 lengths)".into());
        }
        let axis = unit_vector(p, "axis")?;
        let tangent = unit_vector(p, "tangent")?;
        let cos = axis.iter().zip(&tangent).map(|(a, b)| a * b).sum::<f64>();
        if cos.abs() > 1e-6 {
            return Err(format!(
                "`tangent` is not perpendicular to `axis` (cosine {}): the velocity along the surface is measured across the axis",
                num(cos)
            ));
        }
        let (length, radius) = (p.number("length"), p.number("radius"));
        // The particles are taken at their nearest image of the sphere's centre: the
        // cylinder must lie within half a box length of it along every periodic axis.
        for (a, &e) in axis.iter().enumerate() {
            if geo.walls && a == 2 {
                continue;
            }
            let extent = 0.5 * length * e.abs() + radius * (1.0 - e * e).max(0.0).sqrt();
            if extent > 0.5 * geo.lengths[a] * (1.0 + 1e-9) {
                return Err(format!(
                    "the cylinder (`length` {}, `radius` {}, `axis` {:?}) reaches {} from the sphere's centre along axis {a}, more than half the box length {}: particles seen by the nearest periodic image of the centre would leave part of it empty",
                    num(length),
                    num(radius),
                    p.numbers("axis"),
                    num(extent),
                    num(geo.lengths[a])
                ));
            }
        }
        let per_length = p.number("bins_per_cell") / geo.cell;
        let bins = (length * per_length).ceil();
        if bins > MAX_PROFILE_BINS as f64 {
            return Err(format!(
                "`length` {} x `bins_per_cell` {} / `cell` {} gives {} bins, more than {MAX_PROFILE_BINS}",
                num(length),
                num(p.number("bins_per_cell")),
                num(geo.cell),
                num(bins)
            ));
        }
        let mut u = geo.thermal_uniform(p);
        u.set_sampling(p);
        let unit = super::thermal_unit(p)?;
        let c = CylinderUniform {
            axis: [axis[0] as f32, axis[1] as f32, axis[2] as f32, 0.0],
            tangent: [tangent[0] as f32, tangent[1] as f32, tangent[2] as f32, 0.0],
            length: length as f32,
            radius: radius as f32,
            per_length: per_length as f32,
            sphere: p.number("sphere") as u32,
            bins: bins as u32,
            ..Default::default()
        };
        Ok(Box::new(MpcdSphereProfile { geo, u, c, unit, axis, tangent, length, radius, per_length }))
    })
}

struct MpcdSphereProfile {
    geo: Geometry,
    u: super::Uniform,
    c: CylinderUniform,
    unit: f64,
    axis: [f64; 3],
    tangent: [f64; 3],
    length: f64,
    radius: f64,
    per_length: f64,
}

impl MpcdSphereProfile {
    /// The bin of a particle at offset `r` (nearest image) from the sphere's centre, if
    /// it is in the cylinder (f64 twin of the kernel's `bin_of`).
    fn bin_of(&self, r: [f64; 3]) -> Option<usize> {
        let ap: [f64; 3] = std::array::from_fn(|a| r[a] + 0.5 * self.length * self.axis[a]);
        let k: f64 = (0..3).map(|a| ap[a] * self.axis[a]).sum();
        let m2: f64 = (0..3).map(|a| (ap[a] - k * self.axis[a]).powi(2)).sum();
        if k >= 0.0 && k < self.length && m2 < self.radius * self.radius {
            Some(((k * self.per_length).floor() as usize).min(self.c.bins as usize - 1))
        } else {
            None
        }
    }
}

fn add(acc: &mut [f64], i: usize, v: i64) {
    let w = words_of(value_of(acc[i], acc[i + 1]).wrapping_add(v));
    acc[i..i + 2].copy_from_slice(&w);
}

impl Node for MpcdSphereProfile {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let n = self.geo.particles("positions", inputs[0])?;
        if inputs[1] != inputs[0] {
            return Err(PortError::new(
                "velocities",
                format!("expected {n} x 3 like positions, got {:?}", inputs[1]),
            ));
        }
        let s = match inputs[2] {
            Some(ValueType::Particles { n, k: 3 }) if n > 0 => n,
            other => {
                return Err(PortError::new(
                    "sphere_positions",
                    format!("expected S x 3 sphere centres (S >= 1), got {other:?}"),
                ));
            }
        };
        match inputs[3] {
            None => {}
            Some(ValueType::Particles { n, k: 3 }) if n == s => {}
            other => {
                return Err(PortError::new(
                    "sphere_velocities",
                    format!("expected {s} x 3 velocities, got {other:?}"),
                ));
            }
        }
        if self.c.sphere >= s {
            return Err(PortError::new(
                "sphere_positions",
                format!(
                    "has {s} spheres, but the param `sphere` is {}",
                    self.c.sphere
                ),
            ));
        }
        let bins = self.c.bins;
        Ok(Signature::outputs(vec![
            ValueType::Indices { n: 1 + 4 * bins },
            ValueType::Particles { n: bins, k: 3 },
        ]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn checks_input(&self) -> bool {
        true
    }

    fn check_input(&self, port: usize, data: &HostArray) -> Result<(), RowError> {
        // Tangential velocities are summed in fixed point: in its range.
        match port {
            0 | 2 => check_rows(&self.geo, Rows::Positions, data),
            _ => check_rows(&self.geo, Rows::Velocities(Some(self.unit)), data),
        }
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], cx: RefCtx) {
        let step = cx.step as u32;
        let bins = self.c.bins as usize;
        let acc = &mut outputs[0].data;
        if self.u.sampled(step) {
            let x = &inputs[0].as_ref().expect("required").data;
            let v = &inputs[1].as_ref().expect("required").data;
            let c = &inputs[2].as_ref().expect("required").data;
            let j = self.c.sphere as usize;
            let centre: [f64; 3] = std::array::from_fn(|a| c[3 * j + a]);
            let vs: [f64; 3] = match &inputs[3] {
                Some(sv) => std::array::from_fn(|a| sv.data[3 * j + a]),
                None => [0.0; 3],
            };
            acc[0] += 1.0;
            let fix_v = self.u.fix_v as f64;
            for p in 0..x.len() / 3 {
                let r = min_image(&self.geo, std::array::from_fn(|a| x[3 * p + a] - centre[a]));
                if let Some(b) = self.bin_of(r) {
                    let vt: f64 = (0..3)
                        .map(|a| (v[3 * p + a] - vs[a]) * self.tangent[a])
                        .sum();
                    add(acc, 1 + 4 * b, fx_round(vt * fix_v));
                    add(acc, 3 + 4 * b, 1);
                }
            }
        }
        let samples = acc[0];
        let volume = std::f64::consts::PI * self.radius * self.radius / self.per_length;
        let acc = outputs[0].data.clone();
        let out = &mut outputs[1].data;
        for b in 0..bins {
            let n = value_of(acc[3 + 4 * b], acc[4 + 4 * b]) as f64;
            out[3 * b] = (b as f64 + 0.5) / self.per_length - 0.5 * self.length;
            out[3 * b + 1] = if n > 0.0 {
                value_of(acc[1 + 4 * b], acc[2 + 4 * b]) as f64 / (n * self.u.fix_v as f64)
            } else {
                f64::NAN
            };
            out[3 * b + 2] = if samples > 0.0 {
                n / samples / volume
            } else {
                f64::NAN
            };
        }
    }
}

impl GpuKernels for MpcdSphereProfile {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let pos = io.inputs[0].expect("required");
        let ValueType::Particles { n, .. } = pos.ty else {
            unreachable!()
        };
        let centres = io.inputs[2].expect("required");
        let ValueType::Particles { n: s, .. } = centres.ty else {
            unreachable!()
        };
        let mut u = self.u;
        u.n = n;
        let moving = io.inputs[3];
        let c = CylinderUniform {
            moving: u32::from(moving.is_some()),
            spheres: s,
            ..self.c
        };
        let [particles, finish, count] = sphere_kernels(
            cx,
            "mpcd_sphere_profile",
            "mpcd/sphere_profile.wgsl",
            &sphere_bindings(5, 2),
            ["particles", "finish", "count"],
        )?;
        let params = cx.uniform("mpcd sphere profile", bytemuck::bytes_of(&u));
        let cylinder = cx.uniform("mpcd sphere profile cylinder", bytemuck::bytes_of(&c));
        let buffers = [
            &params,
            &cylinder,
            cx.clock,
            pos.buffer,
            io.inputs[1].expect("required").buffer,
            centres.buffer,
            moving.map_or(centres.buffer, |m| m.buffer),
            io.outputs[0].buffer,
            io.outputs[1].buffer,
        ];
        Ok(vec![
            cx.dispatch(&count, &buffers, [1, 1, 1]),
            cx.dispatch(&particles, &buffers, cx.grid_1d(n as u64, WG_1D)),
            cx.dispatch(&finish, &buffers, cx.grid_1d(self.c.bins as u64, WG_1D)),
        ])
    }
}
