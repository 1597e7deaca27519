//! `mpcd_bin_solute`: a second species of mass M (colloids, polymer beads) joins the cell
//! sums of `mpcd_bin`, so that `mpcd_collide` uses mass-weighted cell means
//! u = (m sum v + M sum V) / (m n + M n_s) and, applied to the solute's velocities and
//! cells with the same params, rotates both species by the same rotation of each cell:
//! v' = u + R (v - u), V' = u + R (V - u), conserving each cell's momentum and energy.

use super::{
    Geometry, Rows, SumsLayout, check_rows, geometry_params, grid_shift, key_into, key_of,
    thermal_params, thermal_unit,
};
use crate::gpu::DeviceCaps;
use crate::gpu::{Binding, CompileCtx, CompileError, Dispatch, KernelSpec, NodeIo, WG_1D};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamSpec, PortError, PortSpec, RefCtx, RowError,
    Signature,
};
use crate::nodes::random;
use crate::value::{HostArray, PortType, RefArray, ValueType};

pub(super) fn mpcd_bin_solute_kind() -> NodeKind {
    NodeKind::declare(
        "mpcd_bin_solute",
        "MPCD solute coupling: the cells of a second species of mass M in this step's shifted grid (the solvent's: same seed, stream and box) and the solvent's cell sums with the solute added, weighted by M / m (the mass-weighted cell means of mpcd_collide, its thermostat and virtual particles)",
    )
    .input(PortSpec::new(
        "sums",
        PortType::Indices,
        "the solvent's cell sums (mpcd_bin)",
    ))
    .input(PortSpec::new(
        "positions",
        PortType::Particles(None),
        "solute positions (N_s x d)",
    ))
    .input(PortSpec::new(
        "velocities",
        PortType::Particles(None),
        "solute velocities (N_s x d)",
    ))
    .output(PortSpec::new(
        "cell",
        PortType::Indices,
        "linear cell index per solute particle",
    ))
    .output(PortSpec::new(
        "sums",
        PortType::Indices,
        "mpcd_bin's sums with the solute's M/m-weighted velocity (and, when present, |v|^2) sums added, then the solute count per cell, then the f32 bits of M/m",
    ))
    .params(geometry_params())
    .params(thermal_params())
    .param(ParamSpec::number(
        "solute_mass",
        Some(1.0),
        1.0 / super::F32_SCALE,
        super::F32_SCALE,
        "solute particle mass M: from 1e-30 to 1e30 (f32), and M / m an f32 too",
    ))
    .param(ParamSpec::flag(
        "shift",
        true,
        "random grid shift (as mpcd_bin: give both the same seed and stream)",
    ))
    .param(super::rule_param())
    .param(random::seed_param())
    .param(random::stream_param())
    .build(|p| {
        let geo = Geometry::from_params(p)?;
        thermal_unit(p)?;
        let ratio = p.number("solute_mass") / p.number("mass");
        let r32 = ratio as f32;
        if !(r32.is_finite() && r32 > 0.0) {
            return Err(format!(
                "solute_mass / mass = {ratio} is outside the f32 range"
            ));
        }
        let biased = p.text("rule") == "biased";
        super::check_rule(&geo, biased)?;
        let mut u = geo.thermal_uniform(p);
        u.shift = u32::from(p.flag("shift"));
        u.rule = u32::from(biased);
        u.solute = 1;
        u.ratio = r32;
        key_into(&mut u, p);
        let (seed, stream) = key_of(p);
        Ok(Box::new(MpcdBinSolute {
            geo,
            u,
            seed,
            stream,
        }))
    })
}

struct MpcdBinSolute {
    geo: Geometry,
    u: super::Uniform,
    seed: u64,
    stream: u32,
}

/// round(x) with ties to even (WGSL's `round`).
fn round_even(x: f64) -> i64 {
    x.round_ties_even() as i64
}

impl Node for MpcdBinSolute {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let ncells = self.geo.ncells();
        let solvent = match inputs[0] {
            Some(ValueType::Indices { n }) => SumsLayout::of_words(ncells, n as u64),
            _ => None,
        }
        .filter(|l| !l.solute);
        let Some(solvent) = solvent else {
            return Err(PortError::new(
                "sums",
                format!(
                    "expected mpcd_bin's sums for {ncells} cells ({} or {} words), got {}; do mpcd_bin and mpcd_bin_solute have the same box, cell and walls?",
                    SumsLayout::all(ncells)[0].words(),
                    SumsLayout::all(ncells)[1].words(),
                    inputs[0].map_or("nothing".to_string(), |t| t.to_string())
                ),
            ));
        };
        let n = self.geo.particles("positions", inputs[1])?;
        let nv = self.geo.particles("velocities", inputs[2])?;
        if n != nv {
            return Err(PortError::new(
                "velocities",
                format!("has {nv} rows but positions has {n}"),
            ));
        }
        let words = SumsLayout {
            solute: true,
            ..solvent
        }
        .words();
        if words > u32::MAX as u64 {
            return Err(PortError::new(
                "sums",
                format!("{words} words are too many"),
            ));
        }
        Ok(Signature::outputs(vec![
            ValueType::Indices { n },
            ValueType::Indices { n: words as u32 },
        ]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn checks_input(&self) -> bool {
        true
    }

    fn check_input(&self, port: usize, data: &HostArray) -> Result<(), RowError> {
        // Solute velocities enter the sums scaled by M / m as 64-bit fixed point (no
        // tighter range than f32's): finite.
        match port {
            1 => check_rows(&self.geo, Rows::Positions, data),
            2 => check_rows(&self.geo, Rows::Velocities(None), data),
            _ => Ok(()),
        }
    }

    fn notes(&self, _: &[Option<ValueType>]) -> Vec<String> {
        vec![format!("solute mass M = {} m", self.u.ratio)]
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], cx: RefCtx) {
        let d = self.geo.dims();
        let solvent = &inputs[0].as_ref().expect("required").data;
        let x = &inputs[1].as_ref().expect("required").data;
        let v = &inputs[2].as_ref().expect("required").data;
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
        let layout = SumsLayout::of_words(nc as u32, solvent.len() as u64 + nc as u64 + 1)
            .expect("checked in infer");
        let mut sums: Vec<_> = (0..nc).map(|c| layout.read(solvent, c)).collect();
        let mut counts = vec![0u32; nc];
        let ratio = self.u.ratio as f64;
        let (cells, rest) = outputs.split_at_mut(1);
        for p in 0..x.len() / d {
            let c = self.geo.cell_of(&x[p * d..(p + 1) * d], &s);
            cells[0].data[p] = c as f64;
            counts[c as usize] += 1;
            let cs = &mut sums[c as usize];
            let mut e = 0.0;
            for a in 0..d {
                let va = v[p * d + a];
                // The kernel's f32 products (v fix_v) ratio, exact here as in the kernel.
                let q = (va as f32 * self.u.fix_v) * self.u.ratio;
                cs[1 + a] += round_even(q as f64);
                e += va * va;
            }
            cs[4] += round_even(e * self.u.fix_e as f64 * ratio);
        }
        let o = &mut rest[0].data;
        o.fill(0.0);
        for (c, cs) in sums.iter().enumerate() {
            layout.write(o, c, cs);
            o[layout.solute_word(c)] = counts[c] as f64;
        }
        o[layout.solute_word(nc)] = self.u.ratio.to_bits() as f64;
    }
}

impl GpuKernels for MpcdBinSolute {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let solvent = io.inputs[0].expect("required");
        let pos = io.inputs[1].expect("required");
        let vel = io.inputs[2].expect("required");
        let ValueType::Particles { n, .. } = pos.ty else {
            unreachable!()
        };
        let mut u = self.u;
        u.n = n;
        u.energy = u32::from(
            SumsLayout::of_words(self.geo.ncells(), solvent.ty.words())
                .expect("checked in infer")
                .energy,
        );
        let bindings = [
            Binding::Uniform,
            Binding::StorageRead,
            Binding::StorageRead,
            Binding::StorageRead,
            Binding::StorageRead,
            Binding::StorageReadWrite,
            Binding::StorageReadWrite,
        ];
        let source = cx.shader("mpcd/bin_solute.wgsl")?;
        let dims = self.geo.dims() as f64;
        let copy = cx.kernel(
            &KernelSpec::new("mpcd_bin_solute_copy", source.clone(), &bindings)
                .entry("copy")
                .constant("DIMS", dims),
        )?;
        let add = cx.kernel(
            &KernelSpec::new("mpcd_bin_solute", source, &bindings).constant("DIMS", dims),
        )?;
        let params = cx.uniform("mpcd bin solute", bytemuck::bytes_of(&u));
        let buffers = [
            &params,
            cx.clock,
            pos.buffer,
            vel.buffer,
            solvent.buffer,
            io.outputs[0].buffer,
            io.outputs[1].buffer,
        ];
        Ok(vec![
            cx.dispatch(&copy, &buffers, cx.grid_1d(io.outputs[1].ty.words(), WG_1D)),
            cx.dispatch(&add, &buffers, cx.grid_1d(n as u64, WG_1D)),
        ])
    }
}
