//! Solid spheres in the MPCD solvent (S2 Ch. 5; 3D): `mpcd_stream_spheres` (streaming with
//! no-slip bounce-back on the spheres, the momentum each bounce gives its sphere summed
//! exactly) and `mpcd_sphere_exclude` (a drawn solvent moved out of the spheres by
//! rejection: each particle inside one is drawn again, uniform in the box). The
//! spheres are inputs: `sphere_positions` (S x 3), `sphere_radii` (S x 1) and, for moving
//! spheres, `sphere_velocities` (S x 3; absent: at rest).
//!
//! The impulse a sphere receives is a 64-bit fixed-point sum per component, in units of
//! m v_th / 2^24 (the cell sums' velocity unit times the solvent mass), as (lo, hi) u32
//! pairs: 6 words per sphere. Integer sums are exact and independent of the order of the
//! atomics, so the solvent's momentum change and the spheres' impulses balance to the
//! rounding of each bounce's 2 m (v - V) to that unit.

use std::sync::Arc;

use super::stream::{MpcdStream, advance, mpcd_stream_kind};
use super::stream_bin::{reorder_scratch, sort_cells};
use super::{Geometry, Rows, check_rows, fx_round, num, particle_ports, value_of, words_of};
use crate::gpu::DeviceCaps;
use crate::gpu::{
    Binding, CompileCtx, CompileError, Dispatch, Kernel, KernelSpec, NodeIo, Period, WG_1D,
};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamSpec, PortError, PortRowError, PortSpec, RefCtx,
    RowError, Signature,
};
use crate::nodes::random;
use crate::nodes::sort::SortNode;
use crate::value::{HostArray, HostData, PortType, RefArray, ValueType};

/// Words per sphere of a fixed-point impulse: (lo, hi) pairs of x, y, z.
pub const SPHERE_WORDS: u32 = 6;

/// The passes of the streaming kernel: each ends at a plate, at a sphere or at the end of
/// the step (mpcd_stream's WALL_PASSES).
const PASSES: usize = 16;

/// The sphere block of the sphere kernels (`struct Spheres` of shaders/mpcd/spheres.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct SphereUniform {
    pub count: u32,
    pub per: u32,
    pub moving: u32,
    pub warmup: u32,
    pub has_velocity: u32,
    pub has_impulse: u32,
    pub pad: [u32; 2],
}

/// One sphere in f64: centre, radius, velocity.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Sphere {
    pub c: [f64; 3],
    pub r: f64,
    pub v: [f64; 3],
}

/// The spheres of reference inputs (positions, radii, optional velocities).
pub(crate) fn spheres_of(pos: &RefArray, radii: &RefArray, vel: Option<&RefArray>) -> Vec<Sphere> {
    (0..radii.data.len())
        .map(|j| {
            let mut s = Sphere {
                c: [0.0; 3],
                r: radii.data[j],
                v: [0.0; 3],
            };
            for a in 0..3 {
                s.c[a] = pos.data[3 * j + a];
                if let Some(v) = vel {
                    s.v[a] = v.data[3 * j + a];
                }
            }
            s
        })
        .collect()
}

/// The input ports of the spheres, from `first` on: positions, radii, velocities.
pub(crate) fn sphere_ports(moving_doc: &'static str) -> Vec<PortSpec> {
    vec![
        PortSpec::new(
            "sphere_positions",
            PortType::Particles(Some(3)),
            "sphere centres (S x 3), inside the box (between the plates, clear of them)",
        ),
        PortSpec::new(
            "sphere_radii",
            PortType::Particles(Some(1)),
            "sphere radii (S x 1): > 0, a diameter below every box length",
        ),
        PortSpec::new(
            "sphere_velocities",
            PortType::Particles(Some(3)),
            moving_doc,
        )
        .optional(),
    ]
}

/// Checks the types of the sphere ports at `inputs[first..]`: the sphere count S.
pub(crate) fn sphere_count(inputs: &[Option<ValueType>], first: usize) -> Result<u32, PortError> {
    let s = match inputs[first] {
        Some(ValueType::Particles { n, k: 3 }) if n > 0 => n,
        other => {
            return Err(PortError::new(
                "sphere_positions",
                format!("expected S x 3 sphere centres (S >= 1), got {other:?}"),
            ));
        }
    };
    match inputs[first + 1] {
        Some(ValueType::Particles { n, k: 1 }) if n == s => {}
        other => {
            return Err(PortError::new(
                "sphere_radii",
                format!("expected {s} x 1 radii (one per sphere), got {other:?}"),
            ));
        }
    }
    match inputs.get(first + 2).copied().flatten() {
        None => {}
        Some(ValueType::Particles { n, k: 3 }) if n == s => {}
        other => {
            return Err(PortError::new(
                "sphere_velocities",
                format!("expected {s} x 3 velocities (one per sphere), got {other:?}"),
            ));
        }
    }
    Ok(s)
}

/// Checks given sphere data: `which` 0 positions, 1 radii, 2 velocities (`vth` the
/// fixed-point unit the velocities must stay below 128 of).
pub(crate) fn check_sphere_rows(
    geo: &Geometry,
    which: usize,
    data: &HostArray,
    vth: f64,
) -> Result<(), RowError> {
    match which {
        0 => check_rows(geo, Rows::Positions, data),
        2 => check_rows(geo, Rows::Velocities(Some(vth)), data),
        _ => {
            let HostData::F32(values) = &data.data else {
                return Ok(());
            };
            // A sphere must not meet its own periodic image (nor fill the gap between
            // the plates): a diameter below every box length.
            let shortest = geo.lengths.iter().cloned().fold(f64::MAX, f64::min);
            for (row, &r) in values.iter().enumerate() {
                if !(r.is_finite() && r > 0.0) {
                    return Err(RowError::new(
                        row,
                        format!("radius {r} is not a positive finite number"),
                    ));
                }
                if 2.0 * r as f64 >= shortest {
                    return Err(RowError::new(
                        row,
                        format!(
                            "radius {r} gives a diameter not below the shortest box length {}: the sphere would meet its own periodic image (or both plates)",
                            num(shortest)
                        ),
                    ));
                }
            }
            Ok(())
        }
    }
}

/// Checks given spheres together (`Node::check_inputs_together` of every sphere node):
/// `data[first]` the centres (S x 3), `data[first + 1]` the radii (S x 1), where both
/// are given. Refuses two spheres that overlap (centres, by the nearest periodic image,
/// closer than the sum of their radii: the solvent between them, the bounces and the
/// virtual particles of both would be wrong) and, with plates, a sphere that reaches
/// through a plate (centre closer to it than its radius). The error names the spheres
/// (rows) and the distance; it blames the centres' port, the later sphere's row.
pub(crate) fn check_sphere_layout(
    geo: &Geometry,
    data: &[Option<&HostArray>],
    first: usize,
) -> Result<(), PortRowError> {
    let (Some(Some(centres)), Some(Some(radii))) = (data.get(first), data.get(first + 1)) else {
        return Ok(());
    };
    let (HostData::F32(c), HostData::F32(r)) = (&centres.data, &radii.data) else {
        return Ok(());
    };
    let s = r.len().min(c.len() / 3);
    let centre = |j: usize| -> [f64; 3] { std::array::from_fn(|a| c[3 * j + a] as f64) };
    let refuse = |row: usize, message: String| PortRowError {
        port: first,
        row,
        message,
    };
    if geo.walls {
        let h = 0.5 * geo.lengths[2];
        for (j, &rj) in r.iter().enumerate().take(s) {
            let (z, rj) = (centre(j)[2], rj as f64);
            let gap = h - z.abs();
            if gap < rj {
                return Err(refuse(
                    j,
                    format!(
                        "sphere {j} (centre z = {}, radius {}) reaches through the plate at z = {}: its centre is {} from the plate, less than its radius",
                        num(z),
                        num(rj),
                        num(if z < 0.0 { -h } else { h }),
                        num(gap)
                    ),
                ));
            }
        }
    }
    for j in 1..s {
        for i in 0..j {
            let d = min_image(geo, std::array::from_fn(|a| centre(j)[a] - centre(i)[a]));
            let dist = dot(d, d).sqrt();
            let reach = r[i] as f64 + r[j] as f64;
            if dist < reach {
                return Err(refuse(
                    j,
                    format!(
                        "spheres {i} and {j} overlap: their centres are {} apart (nearest periodic image), less than the sum of their radii {} + {} = {}",
                        num(dist),
                        num(r[i] as f64),
                        num(r[j] as f64),
                        num(reach)
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// The minimum image of a displacement on the periodic axes (f64 twin of `min_image`).
pub(crate) fn min_image(geo: &Geometry, r: [f64; 3]) -> [f64; 3] {
    let mut w = r;
    for a in 0..3 {
        if !(geo.walls && a == 2) {
            let l = geo.lengths[a];
            w[a] = r[a] - l * (r[a] / l + 0.5).floor();
        }
    }
    w
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The earliest sphere hit on the chord `dx` from `x` over time `left`, `now` into the step
/// (f64 twin of `first_hit`): (f1, sphere).
fn first_hit(
    geo: &Geometry,
    spheres: &[Sphere],
    x: [f64; 3],
    dx: [f64; 3],
    now: f64,
    left: f64,
) -> Option<(f64, usize)> {
    let mut best = (1.0, None);
    for (j, s) in spheres.iter().enumerate() {
        let r = min_image(geo, std::array::from_fn(|a| x[a] - s.c[a] - s.v[a] * now));
        let e: [f64; 3] = std::array::from_fn(|a| dx[a] - s.v[a] * left);
        if (0..3).any(|a| r[a].abs() - e[a].abs() > s.r) {
            continue;
        }
        let (qa, qb, qc) = (dot(e, e), 2.0 * dot(e, r), dot(r, r) - s.r * s.r);
        let disc = qb * qb - 4.0 * qa * qc;
        if qb < 0.0 && qc > 0.0 && disc > 0.0 {
            let f = 2.0 * qc / (-qb + disc.sqrt());
            if f < best.0 {
                best = (f, Some(j));
            }
        }
    }
    best.1.map(|j| (best.0, j))
}

/// One particle's step among the spheres in f64 (the reference of the kernel): x, v
/// updated, each bounce's 2 m (v - V) added to `impulse[sphere]` rounded to the unit
/// m / `fix_v` as the kernel adds it.
pub(crate) fn stream_with_spheres(
    st: &MpcdStream,
    spheres: &[Sphere],
    fix_v: f64,
    x: &mut [f64; 3],
    v: &mut [f64; 3],
    impulse: &mut [[i64; 3]],
) {
    let geo = &st.geo;
    let l = &geo.lengths;
    let g = if st.sine {
        st.accel * (2.0 * std::f64::consts::PI * x[2] / l[2]).sin()
    } else {
        st.accel
    };
    let h = 0.5 * l[2];
    let mut left = st.dt;
    for _ in 0..PASSES {
        if left <= 0.0 {
            break;
        }
        let (mut hit, mut wall) = (left, 0.0);
        if geo.walls {
            if v[2] > 0.0 {
                (hit, wall) = (((h - x[2]) / v[2]).max(0.0), h);
            } else if v[2] < 0.0 {
                (hit, wall) = (((-h - x[2]) / v[2]).max(0.0), -h);
            }
        }
        let (mut x2, mut v2) = (*x, *v);
        advance(&mut x2, &mut v2, g, left);
        let dx: [f64; 3] = std::array::from_fn(|a| x2[a] - x[a]);
        let found = first_hit(geo, spheres, *x, dx, st.dt - left, left);
        match found {
            Some((f, j)) if f * left < hit => {
                let ts = f * left;
                for a in 0..3 {
                    x[a] += f * dx[a];
                }
                v[0] += g * ts;
                for a in 0..3 {
                    let out = 2.0 * spheres[j].v[a] - v[a];
                    impulse[j][a] += fx_round_wide((v[a] - out) * fix_v);
                    v[a] = out;
                }
                left -= ts;
            }
            _ if hit >= left => {
                (*x, *v) = (x2, v2);
                left = 0.0;
            }
            _ => {
                advance(x, v, g, hit);
                x[2] = wall;
                if st.slip {
                    v[2] = -v[2];
                } else {
                    v.iter_mut().for_each(|c| *c = -*c);
                }
                left -= hit;
            }
        }
    }
    if geo.walls {
        x[2] = x[2].clamp(-h, h);
    }
    for a in 0..3 {
        if !(geo.walls && a == 2) {
            let mut y = x[a] - l[a] * (x[a] / l[a] + 0.5).floor();
            if y >= 0.5 * l[a] {
                y -= l[a];
            }
            x[a] = y;
        }
    }
}

/// Sphere impulses (units m v_th / 2^24) as (lo, hi) words, 6 a sphere.
pub(crate) fn impulse_words(out: &mut [f64], impulse: &[[i64; 3]]) {
    for (j, q) in impulse.iter().enumerate() {
        for (a, &c) in q.iter().enumerate() {
            let k = SPHERE_WORDS as usize * j + 2 * a;
            out[k..k + 2].copy_from_slice(&words_of(c));
        }
    }
}

/// The bindings of an MPCD sphere kernel: its parameter block and the sphere block
/// (uniforms), then `reads` read-only and `writes` read-write storage buffers.
pub(super) fn sphere_bindings(reads: usize, writes: usize) -> Vec<Binding> {
    let mut b = vec![Binding::Uniform; 2];
    b.extend(std::iter::repeat_n(Binding::StorageRead, reads));
    b.extend(std::iter::repeat_n(Binding::StorageReadWrite, writes));
    b
}

/// The 3D kernels of one sphere shader (`shaders/` path) with these bindings, one per entry
/// point: `main` labelled `label`, others `label entry`.
pub(super) fn sphere_kernels<const N: usize>(
    cx: &mut CompileCtx<'_>,
    label: &str,
    shader: &str,
    bindings: &[Binding],
    entries: [&str; N],
) -> Result<[Arc<Kernel>; N], CompileError> {
    let source = cx.shader(shader)?;
    let kernels = entries
        .iter()
        .map(|&entry| {
            let spec = if entry == "main" {
                KernelSpec::new(label, source.clone(), bindings)
            } else {
                KernelSpec::new(format!("{label} {entry}"), source.clone(), bindings).entry(entry)
            };
            cx.kernel(&spec.constant("DIMS", 3.0))
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(kernels
        .try_into()
        .unwrap_or_else(|_| unreachable!("one kernel per entry")))
}

/// Sphere j's impulse components from impulse words (units m v_th / 2^24).
pub fn impulse_of(words: &[f64], j: usize) -> [i64; 3] {
    let k = SPHERE_WORDS as usize * j;
    std::array::from_fn(|a| value_of(words[k + 2 * a], words[k + 2 * a + 1]))
}

pub(super) fn mpcd_stream_spheres_kind() -> NodeKind {
    let stream = mpcd_stream_kind();
    NodeKind::declare(
        "mpcd_stream_spheres",
        "MPCD streaming with solid spheres (3D): mpcd_stream's motion plus no-slip bounce-back on each sphere's surface at the exact crossing of the step's chord (S2 Eqs. 5.3-5.6, periodic images, spheres moving at their velocity through the step), v -> 2V - v; the impulse 2 m (v - V) of every bounce summed exactly per sphere (64-bit fixed point)",
    )
    .inputs(particle_ports())
    .inputs(sphere_ports(
        "sphere velocities (S x 3; absent: spheres at rest), constant through the step",
    ))
    .outputs(stream.outputs().iter().cloned())
    .output(PortSpec::new(
        "impulse",
        PortType::Indices,
        "momentum the bounced particles gave each sphere in the step: per sphere (lo, hi) u32 pairs of the 64-bit sums of x, y, z in units of m v_th / 2^24 (v_th = sqrt(temperature / mass))",
    ))
    .params(stream.params().iter().cloned())
    .param(ParamSpec::integer(
        "sort_every",
        Some(0.0),
        0.0,
        u32::MAX as f64,
        "reorder the particles by (unshifted) cell on steps 0, K, 2K, ... (stable sort; outputs in cell order), so the binning and collision after it touch the cell sums in order and each workgroup's sphere list is short; 0: never",
    ))
    .build(|p| {
        let stream = MpcdStream::from_params(p)?;
        if stream.geo.dims() != 3 {
            return Err("spheres need a 3D box (3 lengths)".into());
        }
        let mut u = stream.geo.thermal_uniform(p);
        stream.uniform_into(&mut u);
        let bits = (stream.geo.ncells() as f64).log2().ceil().max(1.0) as u32;
        Ok(Box::new(MpcdStreamSpheres {
            vth: super::thermal_unit(p)?,
            stream,
            u,
            sort_every: p.number("sort_every") as u64,
            sorter: SortNode::radix(bits),
        }))
    })
}

struct MpcdStreamSpheres {
    stream: MpcdStream,
    u: super::Uniform,
    vth: f64,
    /// 0: never reorder.
    sort_every: u64,
    sorter: SortNode,
}

impl Node for MpcdStreamSpheres {
    fn infer(
        &self,
        inputs: &[Option<ValueType>],
        caps: &DeviceCaps,
    ) -> Result<Signature, PortError> {
        let moved = self.stream.infer(&inputs[..2], caps)?.outputs;
        let s = sphere_count(inputs, 2)?;
        let mut sig = Signature::outputs(vec![
            moved[0],
            moved[1],
            ValueType::Indices {
                n: SPHERE_WORDS * s,
            },
        ]);
        if self.sort_every > 0 {
            let ValueType::Particles { n, .. } = moved[0] else {
                unreachable!("mpcd_stream's positions are particles")
            };
            let cells = ValueType::Indices { n };
            reorder_scratch(&mut sig, &self.sorter, moved[0], moved[1], cells, caps)?;
        }
        Ok(sig)
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn checks_input(&self) -> bool {
        true
    }

    fn check_input(&self, port: usize, data: &HostArray) -> Result<(), RowError> {
        // Bounce impulses are summed in fixed point: velocities in its range.
        match port {
            0 => check_rows(&self.stream.geo, Rows::Positions, data),
            1 => check_rows(&self.stream.geo, Rows::Velocities(Some(self.vth)), data),
            _ => check_sphere_rows(&self.stream.geo, port - 2, data, self.vth),
        }
    }

    fn checks_inputs_together(&self) -> bool {
        true
    }

    fn check_inputs_together(&self, data: &[Option<&HostArray>]) -> Result<(), PortRowError> {
        check_sphere_layout(&self.stream.geo, data, 2)
    }

    fn notes(&self, inputs: &[Option<ValueType>]) -> Vec<String> {
        match sphere_count(inputs, 2) {
            Ok(s) => vec![format!(
                "{s} spheres, {}",
                if inputs[4].is_some() {
                    "moving"
                } else {
                    "at rest"
                }
            )],
            Err(_) => Vec::new(),
        }
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let x = &inputs[0].as_ref().expect("required").data;
        let v = &inputs[1].as_ref().expect("required").data;
        let spheres = spheres_of(
            inputs[2].as_ref().expect("required"),
            inputs[3].as_ref().expect("required"),
            inputs[4].as_ref(),
        );
        let mut fixed = vec![[0i64; 3]; spheres.len()];
        let fix_v = self.u.fix_v as f64;
        for p in 0..x.len() / 3 {
            let mut xp: [f64; 3] = std::array::from_fn(|a| x[3 * p + a]);
            let mut vp: [f64; 3] = std::array::from_fn(|a| v[3 * p + a]);
            stream_with_spheres(&self.stream, &spheres, fix_v, &mut xp, &mut vp, &mut fixed);
            outputs[0].data[3 * p..3 * p + 3].copy_from_slice(&xp);
            outputs[1].data[3 * p..3 * p + 3].copy_from_slice(&vp);
        }
        impulse_words(&mut outputs[2].data, &fixed);
    }
}

/// round(x) for |x| < 2^63 (the kernels' `fx_of_signed`).
pub(crate) fn fx_round_wide(x: f64) -> i64 {
    if x.abs() < 2_147_483_520.0 {
        fx_round(x)
    } else {
        x.round() as i64
    }
}

impl GpuKernels for MpcdStreamSpheres {
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
        let moving = io.inputs[4];
        let su = SphereUniform {
            count: s,
            moving: u32::from(moving.is_some()),
            ..Default::default()
        };
        // main binds 0-9; stream_cell and gather also the cells (10) and permutation (11).
        let mut bindings = sphere_bindings(5, 3);
        let label = "mpcd_stream_spheres";
        let shader = "mpcd/stream_spheres.wgsl";
        let [kernel] = sphere_kernels(cx, label, shader, &bindings, ["main"])?;
        let params = cx.uniform("mpcd stream spheres", bytemuck::bytes_of(&u));
        let sphere_params = cx.uniform("mpcd spheres", bytemuck::bytes_of(&su));
        let impulse = io.outputs[2];
        let (vel, radii) = (
            io.inputs[1].expect("required").buffer,
            io.inputs[3].expect("required").buffer,
        );
        let sphere_vel = moving.map_or(centres.buffer, |m| m.buffer);
        let (x, v) = (io.outputs[0].buffer, io.outputs[1].buffer);
        let grid = cx.grid_1d(n as u64, WG_1D);
        // The bindings both streaming entries share, before their outputs.
        let inputs = [
            &params,
            &sphere_params,
            pos.buffer,
            vel,
            centres.buffer,
            radii,
            sphere_vel,
        ];
        let main = cx.dispatch(
            &kernel,
            &[&inputs[..], &[x, v, impulse.buffer]].concat(),
            grid,
        );
        let mut out = vec![cx.fill(impulse.buffer, impulse.ty.words(), 0)?];
        if self.sort_every == 0 {
            out.push(main);
            return Ok(out);
        }
        let missing = || CompileError::Unsupported("mpcd_stream_spheres: scratch missing".into());
        let [xt, vt, ct, sorted, perm, sort_scratch @ ..] = io.scratch.as_slice() else {
            return Err(missing());
        };
        bindings.extend([Binding::StorageReadWrite, Binding::StorageRead]);
        let [stream_cell, gather] =
            sphere_kernels(cx, label, shader, &bindings, ["stream_cell", "gather"])?;
        let on = Period {
            every: self.sort_every,
            on: true,
        };
        out.push(
            cx.dispatch(
                &stream_cell,
                &[&inputs[..], &[*xt, *vt, impulse.buffer, *ct, *perm]].concat(),
                grid,
            )
            .on_steps(on),
        );
        let cells = ValueType::Indices { n };
        let sort = [*ct, *sorted, *perm];
        out.extend(sort_cells(
            cx,
            &self.sorter,
            io,
            cells,
            sort,
            sort_scratch,
            on,
        )?);
        out.push(
            cx.dispatch(
                &gather,
                &[
                    &params,
                    &sphere_params,
                    xt,
                    vt,
                    centres.buffer,
                    radii,
                    sphere_vel,
                    x,
                    v,
                    impulse.buffer,
                    ct,
                    perm,
                ],
                grid,
            )
            .on_steps(on),
        );
        out.push(main.on_steps(Period { on: false, ..on }));
        Ok(out)
    }
}

/// Draws a particle inside a sphere takes at most (`EXCLUDE_TRIES` of the kernel): with
/// spheres filling at most half the box, one left inside has odds below 2^-64.
const EXCLUDE_TRIES: u64 = 64;

/// The largest fraction of the box the spheres may fill for `mpcd_sphere_exclude`.
const MAX_SPHERE_FRACTION: f64 = 0.5;

pub(super) fn mpcd_sphere_exclude_kind() -> NodeKind {
    NodeKind::declare(
        "mpcd_sphere_exclude",
        "MPCD solvent outside solid spheres (3D): each particle inside a sphere (nearest periodic image) is drawn again uniformly in the box, from Philox steps 1, 2, ... of (seed, stream), until outside every sphere (at most 64 draws); others are copied. The particle count is kept, so the solvent outside the spheres is denser than `density` by V_box / (V_box - V_spheres)",
    )
    .input(PortSpec::new(
        "positions",
        PortType::Particles(Some(3)),
        "solvent positions (N x 3), e.g. mpcd_init's",
    ))
    .inputs(sphere_ports("unused").into_iter().take(2))
    .output(PortSpec::new(
        "positions",
        PortType::Particles(Some(3)),
        "positions, none inside a sphere",
    ))
    .params(super::geometry_params())
    .param(random::seed_param())
    .param(random::stream_param())
    .build(|p| {
        let geo = Geometry::from_params(p)?;
        if geo.dims() != 3 {
            return Err("spheres need a 3D box (3 lengths)".into());
        }
        let mut u = geo.uniform();
        super::key_into(&mut u, p);
        let (seed, stream) = super::key_of(p);
        Ok(Box::new(MpcdSphereExclude {
            geo,
            u,
            seed,
            stream,
        }))
    })
}

struct MpcdSphereExclude {
    geo: Geometry,
    u: super::Uniform,
    seed: u64,
    stream: u32,
}

fn inside_any(geo: &Geometry, spheres: &[Sphere], x: [f64; 3]) -> bool {
    spheres.iter().any(|s| {
        let r = min_image(geo, std::array::from_fn(|a| x[a] - s.c[a]));
        dot(r, r) < s.r * s.r
    })
}

impl Node for MpcdSphereExclude {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let n = self.geo.particles("positions", inputs[0])?;
        sphere_count(inputs, 1)?;
        Ok(Signature::outputs(vec![ValueType::Particles { n, k: 3 }]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn checks_input(&self) -> bool {
        true
    }

    fn check_input(&self, port: usize, data: &HostArray) -> Result<(), RowError> {
        if port == 0 {
            return check_rows(&self.geo, Rows::Positions, data);
        }
        check_sphere_rows(&self.geo, port - 1, data, 1.0)?;
        if let (2, HostData::F32(radii)) = (port, &data.data) {
            let volume: f64 = self.geo.lengths.iter().product();
            let filled: f64 = radii
                .iter()
                .map(|&r| 4.0 / 3.0 * std::f64::consts::PI * (r as f64).powi(3))
                .sum();
            if filled > MAX_SPHERE_FRACTION * volume {
                return Err(RowError::new(
                    radii.len() - 1,
                    format!(
                        "the spheres fill {} of the box volume {}, more than half: drawing the solvent outside them by rejection would take too many draws",
                        num(filled),
                        num(volume)
                    ),
                ));
            }
        }
        Ok(())
    }

    fn checks_inputs_together(&self) -> bool {
        true
    }

    fn check_inputs_together(&self, data: &[Option<&HostArray>]) -> Result<(), PortRowError> {
        check_sphere_layout(&self.geo, data, 1)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let x = &inputs[0].as_ref().expect("required").data;
        let spheres = spheres_of(
            inputs[1].as_ref().expect("required"),
            inputs[2].as_ref().expect("required"),
            None,
        );
        let l = &self.geo.lengths;
        for p in 0..x.len() / 3 {
            let mut xp: [f64; 3] = std::array::from_fn(|a| x[3 * p + a]);
            let mut k = 1;
            while k <= EXCLUDE_TRIES && inside_any(&self.geo, &spheres, xp) {
                for a in 0..3 {
                    let u = random::uniform((3 * p + a) as u64, k, self.seed, self.stream);
                    xp[a] = ((u - 0.5) * l[a]).min(0.5 * l[a]);
                }
                k += 1;
            }
            outputs[0].data[3 * p..3 * p + 3].copy_from_slice(&xp);
        }
    }
}

impl GpuKernels for MpcdSphereExclude {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let pos = io.inputs[0].expect("required");
        let ValueType::Particles { n, .. } = pos.ty else {
            unreachable!()
        };
        let centres = io.inputs[1].expect("required");
        let ValueType::Particles { n: s, .. } = centres.ty else {
            unreachable!()
        };
        let mut u = self.u;
        u.n = n;
        let su = SphereUniform {
            count: s,
            ..Default::default()
        };
        let [kernel] = sphere_kernels(
            cx,
            "mpcd_sphere_exclude",
            "mpcd/sphere_exclude.wgsl",
            &sphere_bindings(4, 1),
            ["main"],
        )?;
        let params = cx.uniform("mpcd sphere exclude", bytemuck::bytes_of(&u));
        let sphere_params = cx.uniform("mpcd spheres", bytemuck::bytes_of(&su));
        Ok(vec![cx.dispatch(
            &kernel,
            &[
                &params,
                &sphere_params,
                pos.buffer,
                centres.buffer,
                io.inputs[2].expect("required").buffer,
                centres.buffer,
                io.outputs[0].buffer,
            ],
            cx.grid_1d(n as u64, WG_1D),
        )])
    }
}
