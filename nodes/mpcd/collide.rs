//! `mpcd_bin` (cells of the shifted grid and exact per-cell sums) and `mpcd_collide` (the
//! SRD rotation with the cell thermostat and virtual particles in wall-cut cells).

use super::{
    CellSums, Geometry, Rows, SUM_V, SumsLayout, check_rows, check_rule, fx_round, geometry_params,
    grid_shift, key_into, key_of, particle_ports, rule_param, thermal_params, thermal_unit,
    value_of,
};
use crate::gpu::DeviceCaps;
use crate::gpu::{Binding, CompileCtx, CompileError, Dispatch, KernelSpec, NodeIo, WG_1D, shaders};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamSpec, Params, PortError, PortSpec, RefCtx, RowError,
    Signature,
};
use crate::nodes::random::{self, philox4x32_10};
use crate::value::{HostArray, PortType, RefArray, ValueType};

fn key_params() -> [ParamSpec; 2] {
    [random::seed_param(), random::stream_param()]
}

fn shift_param() -> ParamSpec {
    ParamSpec::flag(
        "shift",
        true,
        "random grid shift, uniform in [-a/2, a/2) per axis and step (Philox block 0 of (seed, stream) at the step)",
    )
}

pub(super) fn mpcd_bin_kind() -> NodeKind {
    NodeKind::declare(
        "mpcd_bin",
        "MPCD cells of this step's randomly shifted grid, and per cell the count, sum v and, for a thermostat, sum |v|^2 (exact 64-bit fixed point; native 64-bit atomics where the adapter has them)",
    )
    .inputs(particle_ports())
    .output(PortSpec::new(
        "cell",
        PortType::Indices,
        "linear cell index per particle",
    ))
    .output(PortSpec::new(
        "sums",
        PortType::Indices,
        "8 words per cell: (lo, hi) u32 pairs of the 64-bit count and sums of v_x, v_y, v_z (units v_th/2^24); then with a thermostat a pair of sum |v|^2 per cell (units v_th^2/2^16)",
    ))
    .params(geometry_params())
    .params(thermal_params())
    .param(shift_param())
    .param(rule_param())
    .param(thermostat_param(
        "the collision's thermostat: any but none adds the sums of |v|^2 it needs",
    ))
    .param(ParamSpec::choice(
        "atomics",
        "auto",
        &["auto", "int64", "int32"],
        "auto: native 64-bit atomics where the adapter has them (one return-less add per sum), else int32; int32: pairs of 32-bit atomics with a carry (any adapter). Both give the same exact sums",
    ))
    .params(key_params())
    .build(|p| Ok(Box::new(MpcdBin::from_params(p)?)))
}

/// The thermostat choice (mpcd_collide's; mpcd_bin's says whether to sum |v|^2).
fn thermostat_param(doc: &'static str) -> ParamSpec {
    ParamSpec::choice(
        "thermostat",
        "none",
        &["none", "rescale", "monte_carlo"],
        doc,
    )
}

pub(crate) struct MpcdBin {
    geo: Geometry,
    u: super::Uniform,
    seed: u64,
    stream: u32,
    /// Some(true): native 64-bit atomics required; Some(false): 32-bit pairs; None: auto.
    atomics: Option<bool>,
    /// The fixed-point unit v_th of the sums.
    unit: f64,
}

impl MpcdBin {
    pub(crate) fn from_params(p: &Params) -> Result<Self, String> {
        let (seed, stream) = key_of(p);
        let energy = p.text("thermostat") != "none";
        let atomics = match p.text("atomics") {
            "int64" => Some(true),
            "int32" => Some(false),
            _ => None,
        };
        let geo = Geometry::from_params(p)?;
        let unit = thermal_unit(p)?;
        let biased = p.text("rule") == "biased";
        check_rule(&geo, biased)?;
        let mut u = geo.thermal_uniform(p);
        u.shift = u32::from(p.flag("shift"));
        u.rule = u32::from(biased);
        u.energy = u32::from(energy);
        key_into(&mut u, p);
        Ok(MpcdBin {
            geo,
            u,
            seed,
            stream,
            atomics,
            unit,
        })
    }

    /// A binning kernel's label and source: `main_file` (mpcd/bin.wgsl or
    /// mpcd/stream_bin.wgsl) composed after the cell-sum atomics this adapter takes.
    pub(crate) fn source(
        &self,
        cx: &CompileCtx<'_>,
        main_file: &str,
    ) -> Result<(String, String), CompileError> {
        let native = cx.caps().int64_atomics;
        let int64 = match self.atomics {
            Some(true) if !native => {
                return Err(CompileError::Unsupported(format!(
                    "mpcd_bin: atomics int64 needs 64-bit storage atomics (SHADER_INT64_ATOMIC_ALL_OPS), which {} lacks; use auto or int32",
                    cx.caps().adapter
                )));
            }
            Some(want) => want,
            None => native,
        };
        let sums = if int64 { "int64" } else { "int32" };
        let source = shaders::resolve(&format!(
            "#import mpcd/sums_{sums}.wgsl\n#import {main_file}\n"
        ))
        .map_err(CompileError::Library)?;
        Ok((format!("{main_file} ({sums} atomics)"), source))
    }

    /// The parameter block of the binning (without the particle count).
    pub(crate) fn uniform(&self) -> super::Uniform {
        self.u
    }

    pub(crate) fn dims(&self) -> usize {
        self.geo.dims()
    }

    pub(crate) fn layout(&self) -> SumsLayout {
        SumsLayout {
            ncells: self.geo.ncells(),
            energy: self.u.energy == 1,
            solute: false,
        }
    }
}

impl Node for MpcdBin {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let n = self.geo.particles("positions", inputs[0])?;
        let nv = self.geo.particles("velocities", inputs[1])?;
        if n != nv {
            return Err(PortError::new(
                "velocities",
                format!("has {nv} rows but positions has {n}"),
            ));
        }
        Ok(Signature::outputs(vec![
            ValueType::Indices { n },
            ValueType::Indices {
                n: self.layout().words() as u32,
            },
        ]))
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
            _ => Rows::Velocities(Some(self.unit)),
        };
        check_rows(&self.geo, rows, data)
    }

    fn notes(&self, _: &[Option<ValueType>]) -> Vec<String> {
        vec![format!(
            "{:?} cells of size {}{}",
            self.geo.cells,
            self.geo.cell,
            if self.u.shift == 1 {
                ", randomly shifted"
            } else {
                ""
            }
        )]
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], cx: RefCtx) {
        let d = self.geo.dims();
        let x = &inputs[0].as_ref().expect("required").data;
        let v = &inputs[1].as_ref().expect("required").data;
        let s = if self.u.shift == 1 {
            grid_shift(
                self.geo.cell * (1 + self.u.rule) as f64,
                cx.step,
                self.seed,
                self.stream,
            )
        } else {
            [0.0; 3]
        };
        let nc = self.geo.ncells() as usize;
        let mut sums: Vec<CellSums> = vec![[0; 5]; nc];
        let (cells, rest) = outputs.split_at_mut(1);
        for p in 0..x.len() / d {
            let c = self.geo.cell_of(&x[p * d..(p + 1) * d], &s);
            cells[0].data[p] = c as f64;
            let cs = &mut sums[c as usize];
            cs[0] += 1;
            let mut e = 0.0;
            for a in 0..d {
                let va = v[p * d + a];
                cs[1 + a] += fx_round(va * self.u.fix_v as f64);
                e += va * va;
            }
            cs[4] += (e * self.u.fix_e as f64).min(4_294_967_040.0).round() as i64;
        }
        let layout = self.layout();
        let o = &mut rest[0].data;
        o.fill(0.0);
        for (c, cs) in sums.iter().enumerate() {
            layout.write(o, c, cs);
        }
    }
}

impl GpuKernels for MpcdBin {
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
        let mut u = self.u;
        u.n = n;
        let (label, source) = self.source(cx, "mpcd/bin.wgsl")?;
        let kernel = cx.kernel(
            &KernelSpec::new(
                label,
                source,
                &[
                    Binding::Uniform,
                    Binding::StorageRead,
                    Binding::StorageRead,
                    Binding::StorageRead,
                    Binding::StorageReadWrite,
                    Binding::StorageReadWrite,
                ],
            )
            .constant("DIMS", self.geo.dims() as f64),
        )?;
        let params = cx.uniform("mpcd bin", bytemuck::bytes_of(&u));
        let sums = io.outputs[1].buffer;
        Ok(vec![
            cx.fill(sums, io.outputs[1].ty.words(), 0)?,
            cx.dispatch(
                &kernel,
                &[
                    &params,
                    cx.clock,
                    pos.buffer,
                    vel.buffer,
                    io.outputs[0].buffer,
                    sums,
                ],
                cx.grid_1d(n as u64, WG_1D),
            ),
        ])
    }
}

pub(super) fn mpcd_collide_kind() -> NodeKind {
    NodeKind::declare(
        "mpcd_collide",
        "MPCD collision: SRD v <- u_c + S R(angle, random axis per cell) (v - u_c) with a cell thermostat S and virtual particles in wall-cut cells, or biased collisions between cell pairs (MPCD-BC). With mpcd_bin_solute's sums u_c is the mass-weighted mean of solvent and solute, the thermostat counts both species, MPCD-BC takes the cells' masses (units of m) for n1 and n2, and the node run with the same params on the solute's velocities and cells rotates (or reflects) and scales the solute by the same rotation (or pair reflection) and factor of each cell",
    )
    .input(PortSpec::new(
        "velocities",
        PortType::Particles(None),
        "velocities (N x d)",
    ))
    .input(PortSpec::new(
        "cell",
        PortType::Indices,
        "cell per particle (mpcd_bin)",
    ))
    .input(PortSpec::new(
        "sums",
        PortType::Indices,
        "cell sums (mpcd_bin, or mpcd_bin_solute with a solute)",
    ))
    .output(PortSpec::new(
        "velocities",
        PortType::Particles(None),
        "velocities after the collision",
    ))
    .params(geometry_params())
    .params(thermal_params())
    .param(ParamSpec::flag(
        "shift",
        true,
        "whether mpcd_bin shifts the grid (with walls, the first and last layers are then cut cells)",
    ))
    .param(rule_param())
    .param(ParamSpec::integer(
        "shift_stream",
        Some(-1.0),
        -1.0,
        u32::MAX as f64,
        "rule biased with plates: the `stream` of the mpcd_bin whose sums this node reads (its grid shift says which layers the plates cut); -1: not given (refused there)",
    ))
    .param(ParamSpec::number(
        "acceptance",
        Some(0.01),
        0.0,
        super::F32_SCALE,
        "MPCD-BC acceptance parameter A: a cell pair collides with probability tanh(A du n1 n2); at most 1e30 (f32)",
    ))
    .param(ParamSpec::number(
        "angle",
        Some(130.0),
        0.0,
        180.0,
        "rotation angle in degrees",
    ))
    .param(ParamSpec::number(
        "density",
        Some(10.0),
        f64::MIN_POSITIVE,
        16_777_216.0,
        "mean particles per cell M (the fill level of virtual particles); at most 2^24 (the kernel compares it with cell counts in f32, exact to 2^24)",
    ))
    .param(ParamSpec::flag(
        "ghosts",
        true,
        "with walls: fill wall-cut cells holding fewer than M particles with virtual particles (Lamura et al.)",
    ))
    .param(thermostat_param(
        "none; rescale: relative velocities of every cell scaled to kT; monte_carlo: Hecht's cell scaling (give mpcd_bin the same: it then sums |v|^2)",
    ))
    .param(ParamSpec::number(
        "mc_scale",
        Some(0.3),
        0.0,
        10.0,
        "Monte-Carlo thermostat: scale factor drawn from [1, 1 + c) or its inverse",
    ))
    .params(key_params())
    .build(|p| {
        let geo = Geometry::from_params(p)?;
        thermal_unit(p)?;
        let thermostat = match p.text("thermostat") {
            "none" => 0,
            "rescale" => 1,
            _ => 2,
        };
        if thermostat != 0 && p.number("temperature") <= 0.0 {
            return Err("a thermostat needs temperature > 0".into());
        }
        let angle = p.number("angle").to_radians();
        let biased = p.text("rule") == "biased";
        check_rule(&geo, biased)?;
        let mut u = geo.thermal_uniform(p);
        u.rule = u32::from(biased);
        u.accept_a = p.number("acceptance") as f32;
        u.shift = u32::from(p.flag("shift"));
        u.kt = p.number("temperature") as f32;
        u.mass = p.number("mass") as f32;
        (u.cos_a, u.sin_a) = unit_pair(angle);
        (u.half_cos, u.half_sin) = unit_pair(angle / 2.0);
        u.density = p.number("density") as f32;
        u.ghosts = u32::from(p.flag("ghosts"));
        u.thermostat = thermostat;
        u.mc_c = p.number("mc_scale") as f32;
        let shift_stream = p.number("shift_stream");
        if biased && geo.walls && u.shift == 1 && shift_stream < 0.0 {
            return Err("rule `biased` with plates needs `shift_stream`: the `stream` of the mpcd_bin whose sums this node reads (its grid shift says which cell layers the plates cut)".into());
        }
        u.shift_stream = shift_stream.max(0.0) as u32;
        key_into(&mut u, p);
        let (seed, stream) = key_of(p);
        Ok(Box::new(MpcdCollide {
            geo,
            u,
            seed,
            stream,
            kt: p.number("temperature"),
            mass: p.number("mass"),
            density: p.number("density"),
        }))
    })
}

struct MpcdCollide {
    geo: Geometry,
    u: super::Uniform,
    seed: u64,
    stream: u32,
    kt: f64,
    mass: f64,
    density: f64,
}

/// (cos, sin) of `angle` as an f32 pair within 64 ulps of each (an angle error below
/// 1e-5 rad) for which the f32 rotation keeps |v - u| on average: 1 - cos is exact in f32
/// (the kernel computes it; a rounded 1 - cos scales the component along the axis by
/// 1 + eps in every collision) and c^2 + s^2 is the closest to 1 (else the components
/// across the axis scale by it, 2.5e-8 per collision at 130 degrees for the nearest
/// pair). Either bias, the same in every collision, heats or cools the fluid steadily.
fn unit_pair(angle: f64) -> (f32, f32) {
    let near = |x: f32| {
        (-64i32..=64).filter_map(move |k| {
            let b = x.to_bits() as i64 + k as i64;
            (0..=u32::MAX as i64)
                .contains(&b)
                .then(|| f32::from_bits(b as u32))
        })
    };
    let (c0, s0) = (angle.cos() as f32, angle.sin() as f32);
    let mut best = (f64::MAX, c0, s0);
    for c in near(c0).filter(|&c| ((1.0 - c as f64) as f32) as f64 == 1.0 - c as f64) {
        for s in near(s0) {
            let e = ((c as f64).powi(2) + (s as f64).powi(2) - 1.0).abs();
            if e < best.0 {
                best = (e, c, s);
            }
        }
    }
    (best.1, best.2)
}

fn unit(w: u32) -> f64 {
    (w >> 8) as f64 / 16_777_216.0
}

fn open01(w: u32) -> f64 {
    ((w >> 8) as f64 + 1.0) / 16_777_216.0
}

/// R d for the SRD rotation whose angle has cosine and sine (`ca`, `sa`) (the f32 pair
/// the kernel uses, see `unit_pair`), drawn from the cell's Philox words `w` (f64 twin of
/// the kernel's): 3D about the axis (sqrt(1 - c^2) cos phi, sqrt(1 - c^2) sin phi, c) with
/// c = 2 u0 - 1, phi = 2 pi u1 (right-handed, Rodrigues' formula; the kernel composes two
/// reflections, the same rotation in exact arithmetic); 2D by -angle when the top bit of w0
/// is set, else +angle.
pub fn srd_rotation(dims: usize, ca: f64, sa: f64, w: [u32; 4], d: [f64; 3]) -> [f64; 3] {
    if dims == 3 {
        let cz = 2.0 * unit(w[0]) - 1.0;
        let phi = 2.0 * std::f64::consts::PI * unit(w[1]);
        let sz = (1.0 - cz * cz).max(0.0).sqrt();
        let k = [sz * phi.cos(), sz * phi.sin(), cz];
        let kd = k[0] * d[0] + k[1] * d[1] + k[2] * d[2];
        let kxd = [
            k[1] * d[2] - k[2] * d[1],
            k[2] * d[0] - k[0] * d[2],
            k[0] * d[1] - k[1] * d[0],
        ];
        let mut r = [0.0; 3];
        for a in 0..3 {
            r[a] = d[a] * ca + kxd[a] * sa + k[a] * kd * (1.0 - ca);
        }
        r
    } else {
        let s = if w[0] & 0x8000_0000 != 0 { -sa } else { sa };
        [d[0] * ca - d[1] * s, d[0] * s + d[1] * ca, 0.0]
    }
}

impl MpcdCollide {
    fn block(&self, c: u32, step: u64, j: u32) -> [u32; 4] {
        philox4x32_10(
            [c, step as u32, (self.seed >> 32) as u32, 0],
            [self.seed as u32, self.stream.wrapping_add(j)],
        )
    }

    /// Whether the plates cut cell c at `step` (f64 twin of the kernel's `wall_cut`).
    fn wall_cut(&self, c: u32, step: u64) -> bool {
        if !self.geo.walls || self.u.shift == 0 {
            return false;
        }
        let d = self.geo.dims();
        let layer = self.geo.layer(c);
        let last = self.geo.cells[d - 1] - 1;
        if self.u.rule == 0 {
            return layer == 0 || layer == last;
        }
        let s = grid_shift(2.0 * self.geo.cell, step, self.seed, self.u.shift_stream)[d - 1]
            / self.geo.cell;
        let lo = layer as f64 - 1.0 - s;
        lo < 0.0 || lo + 1.0 > (last - 1) as f64
    }

    /// Cell c's mean `u` and mass `mass` (units of m) with the virtual particles of a
    /// wall-cut cell holding fewer than `density` solvent particles (f64 twin of the
    /// kernel's `filled`).
    fn filled(&self, c: u32, step: u64, sums: &[f64], u: [f64; 3], mass: f64) -> ([f64; 3], f64) {
        let count = SumsLayout::block(sums, c as usize)[0];
        if self.u.ghosts == 0 || count >= self.density || !self.wall_cut(c, step) {
            return (u, mass);
        }
        let g = self.block(c, step, 2);
        let r0 = (-2.0 * open01(g[0]).ln()).sqrt();
        let r1 = (-2.0 * open01(g[2]).ln()).sqrt();
        let t0 = 2.0 * std::f64::consts::PI * open01(g[1]);
        let t1 = 2.0 * std::f64::consts::PI * open01(g[3]);
        let sd = (self.kt / (self.mass * (self.density - count))).sqrt();
        let q = [r0 * t0.cos() * sd, r0 * t0.sin() * sd, r1 * t1.cos() * sd];
        let extra = self.density - count;
        let mut out = [0.0; 3];
        for a in 0..self.geo.dims() {
            out[a] = (mass * u[a] + extra * q[a]) / (mass + extra);
        }
        (out, mass + extra)
    }

    /// Cell c's mean velocity and mass in units of m (the count, plus M/m times the
    /// solute count with a solute: `solute` is (M/m, the solute counts)).
    fn mean(&self, c: u32, sums: &[f64], solute: Option<(f64, &[f64])>) -> ([f64; 3], f64) {
        let s = SumsLayout::block(sums, c as usize);
        let mass = match solute {
            Some((ratio, ns)) => s[0] + ratio * ns[c as usize],
            None => s[0],
        };
        let mut u = [0.0; 3];
        for a in 0..self.geo.dims() {
            u[a] = value_of(s[SUM_V + 2 * a], s[SUM_V + 1 + 2 * a]) as f64
                / (if mass > 0.0 { mass } else { 1.0 } * self.u.fix_v as f64);
        }
        (u, mass)
    }

    /// MPCD-BC update of one particle (f64 twin of `biased` in shaders/mpcd/collide.wgsl):
    /// its cell has mean u1 and mass n1 (units of m).
    #[allow(clippy::too_many_arguments)]
    fn biased(
        &self,
        c: u32,
        step: u64,
        u1: [f64; 3],
        n1: f64,
        v: [f64; 3],
        sums: &[f64],
        solute: Option<(f64, &[f64])>,
    ) -> [f64; 3] {
        let d = self.geo.dims();
        let (nx, ny) = (self.geo.cells[0], self.geo.cells[1]);
        let i = [
            c % nx,
            (c / nx) % ny,
            if d == 3 { c / (nx * ny) } else { 0 },
        ];
        let sc = (i[0] >> 1) + (nx >> 1) * ((i[1] >> 1) + (ny >> 1) * (i[2] >> 1));
        let t = unit(self.block(sc, step, 3)[0]);
        let flip: [u32; 3] = if d == 3 {
            let k = t * 13.0;
            if k < 1.0 {
                [1, 0, 0]
            } else if k < 2.0 {
                [0, 1, 0]
            } else if k < 3.0 {
                [0, 0, 1]
            } else if k < 5.0 {
                [1, 1, 0]
            } else if k < 7.0 {
                [1, 0, 1]
            } else if k < 9.0 {
                [0, 1, 1]
            } else {
                [1, 1, 1]
            }
        } else if t < 0.25 {
            [1, 0, 0]
        } else if t < 0.5 {
            [0, 1, 0]
        } else {
            [1, 1, 0]
        };
        let j: Vec<u32> = (0..3).map(|a| i[a] ^ flip[a]).collect();
        let cp = j[0] + nx * (j[1] + ny * j[2]);
        let mut s = [0.0; 3];
        for a in 0..3 {
            s[a] = (1.0 - 2.0 * (i[a] & 1) as f64) * flip[a] as f64;
        }
        let norm = (s.iter().map(|x| x * x).sum::<f64>()).sqrt();
        s.iter_mut().for_each(|x| *x /= norm);
        let (u2, n2) = self.mean(cp, sums, solute);
        let (u2, n2) = self.filled(cp, step, sums, u2, n2);
        let du: f64 = (0..3).map(|a| s[a] * (u1[a] - u2[a])).sum();
        let p = if du > 0.0 && n2 > 0.0 {
            (self.u.accept_a as f64 * du * n1 * n2).tanh()
        } else {
            0.0
        };
        if unit(self.block(c.min(cp), step, 4)[0]) < p {
            let mut up = [0.0; 3];
            for a in 0..3 {
                up[a] = (n1 * u1[a] + n2 * u2[a]) / (n1 + n2);
            }
            let proj: f64 = (0..3).map(|a| s[a] * (up[a] - v[a])).sum();
            let mut out = v;
            for a in 0..3 {
                out[a] += 2.0 * s[a] * proj;
            }
            return out;
        }
        v
    }
}

impl Node for MpcdCollide {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let n = self.geo.particles("velocities", inputs[0])?;
        match inputs[1] {
            Some(ValueType::Indices { n: nc }) if nc == n => {}
            other => {
                return Err(PortError::new(
                    "cell",
                    format!("expected {n} indices (one per particle), got {other:?}"),
                ));
            }
        }
        let layout = SumsLayout::of_port(self.geo.ncells(), inputs[2], "mpcd_collide")?;
        if self.u.thermostat != 0 && !layout.energy {
            return Err(PortError::new(
                "sums",
                "carries no sums of |v|^2, which the thermostat needs: give mpcd_bin the same `thermostat`",
            ));
        }
        Ok(Signature::outputs(vec![inputs[0].expect("checked")]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn checks_input(&self) -> bool {
        true
    }

    fn check_input(&self, port: usize, data: &HostArray) -> Result<(), RowError> {
        // The velocities only (`cell` and `sums` come from mpcd_bin): finite.
        match port {
            0 => check_rows(&self.geo, Rows::Velocities(None), data),
            _ => Ok(()),
        }
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], cx: RefCtx) {
        let d = self.geo.dims();
        let v = &inputs[0].as_ref().expect("required").data;
        let cells = &inputs[1].as_ref().expect("required").data;
        let sums = &inputs[2].as_ref().expect("required").data;
        let (fix_v, fix_e) = (self.u.fix_v as f64, self.u.fix_e as f64);
        let layout =
            SumsLayout::of_words(self.geo.ncells(), sums.len() as u64).expect("checked in infer");
        // With a solute: M / m and the solute count per cell (mpcd_bin_solute's layout).
        let solute = layout.solute.then(|| {
            (
                f32::from_bits(sums[sums.len() - 1] as u32) as f64,
                &sums[layout.solute_word(0)..sums.len() - 1],
            )
        });
        for p in 0..cells.len() {
            let c = cells[p] as u32;
            let s = SumsLayout::block(sums, c as usize);
            let count = s[0];
            let (mass_n, count_all) = match solute {
                Some((ratio, ns)) => (count + ratio * ns[c as usize], count + ns[c as usize]),
                None => (count, count),
            };
            let mut u = [0.0; 3];
            for a in 0..d {
                u[a] = value_of(s[SUM_V + 2 * a], s[SUM_V + 1 + 2 * a]) as f64 / (mass_n * fix_v);
            }
            let uu: f64 = u.iter().map(|x| x * x).sum();
            let rel = if layout.energy {
                let e = layout.energy_word(c as usize);
                (value_of(sums[e], sums[e + 1]) as f64 / fix_e - mass_n * uu).max(0.0)
            } else {
                0.0
            };
            let mut scale = 1.0;
            let mut mass_eff = mass_n;
            if self.u.ghosts == 1 && count < self.density && self.wall_cut(c, cx.step) {
                (u, mass_eff) = self.filled(c, cx.step, sums, u, mass_n);
            } else if self.u.thermostat != 0 && count_all >= 2.0 && rel > 0.0 {
                let dof = d as f64 * (count_all - 1.0);
                if self.u.thermostat == 1 {
                    scale = (dof * self.kt / (self.mass * rel)).sqrt();
                } else {
                    let t = self.block(c, cx.step, 1);
                    let psi = 1.0 + self.u.mc_c as f64 * unit(t[0]);
                    let sc = if unit(t[1]) < 0.5 { psi } else { 1.0 / psi };
                    let log_accept =
                        dof * sc.ln() - 0.5 * self.mass / self.kt * rel * (sc * sc - 1.0);
                    if open01(t[2]).ln() < log_accept {
                        scale = sc;
                    }
                }
            }
            let mut dv = [0.0; 3];
            for a in 0..d {
                dv[a] = v[p * d + a] - u[a];
            }
            if self.u.rule == 1 {
                let mut vt = [0.0; 3];
                for a in 0..d {
                    vt[a] = u[a] + scale * dv[a];
                }
                let out = self.biased(c, cx.step, u, mass_eff, vt, sums, solute);
                outputs[0].data[p * d..(p + 1) * d].copy_from_slice(&out[..d]);
                continue;
            }
            let (ca, sa) = if d == 3 {
                // The half angle: two reflections (see the kernel).
                let (ch, sh) = (self.u.half_cos as f64, self.u.half_sin as f64);
                (ch * ch - sh * sh, 2.0 * ch * sh)
            } else {
                (self.u.cos_a as f64, self.u.sin_a as f64)
            };
            let r = srd_rotation(d, ca, sa, self.block(c, cx.step, 0), dv);
            for a in 0..d {
                outputs[0].data[p * d + a] = u[a] + scale * r[a];
            }
        }
    }
}

impl GpuKernels for MpcdCollide {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let vel = io.inputs[0].expect("required");
        let ValueType::Particles { n, .. } = vel.ty else {
            unreachable!()
        };
        let mut u = self.u;
        u.n = n;
        let layout = SumsLayout::of_words(
            self.geo.ncells(),
            io.inputs[2].expect("required").ty.words(),
        )
        .expect("checked in infer");
        u.solute = u32::from(layout.solute);
        u.energy = u32::from(layout.energy);
        let kernel = cx.kernel(
            &KernelSpec::new(
                "mpcd_collide",
                cx.shader("mpcd/collide.wgsl")?,
                &[
                    Binding::Uniform,
                    Binding::StorageRead,
                    Binding::StorageRead,
                    Binding::StorageRead,
                    Binding::StorageRead,
                    Binding::StorageReadWrite,
                ],
            )
            .constant("DIMS", self.geo.dims() as f64),
        )?;
        let params = cx.uniform("mpcd collide", bytemuck::bytes_of(&u));
        Ok(vec![cx.dispatch(
            &kernel,
            &[
                &params,
                cx.clock,
                vel.buffer,
                io.inputs[1].expect("required").buffer,
                io.inputs[2].expect("required").buffer,
                io.outputs[0].buffer,
            ],
            cx.grid_1d(n as u64, WG_1D),
        )])
    }
}
