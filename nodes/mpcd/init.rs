//! `mpcd_init`: the initial MPCD state from params (it reads no input, so a graph's state
//! can start from it): round(density x cells) particles uniform in the box, velocities
//! Maxwell-Boltzmann at kT with the mean velocity (summed in exact fixed point) removed.

use super::{
    Geometry, Rows, check_rows, geometry_params, key_into, key_of, thermal_params, thermal_unit,
};
use crate::gpu::DeviceCaps;
use crate::gpu::{Binding, CompileCtx, CompileError, Dispatch, KernelSpec, NodeIo, WG_1D};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamSpec, PortError, PortSpec, RefCtx, RowError,
    Signature,
};
use crate::nodes::random;
use crate::value::{HostArray, PortType, RefArray, ValueType};

pub(super) fn mpcd_init_kind() -> NodeKind {
    NodeKind::declare(
        "mpcd_init",
        "MPCD initial state: round(density x cells) particles uniform in the box, Maxwell-Boltzmann velocities with zero mean (Philox at step 0 of streams stream and stream + 1), or copies of given positions and velocities",
    )
    .input(
        PortSpec::new(
            "positions",
            PortType::Particles(None),
            "given initial positions (N x d; with `velocities`): copied instead of drawn",
        )
        .optional(),
    )
    .input(
        PortSpec::new(
            "velocities",
            PortType::Particles(None),
            "given initial velocities (N x d; with `positions`), copied as they are",
        )
        .optional(),
    )
    .output(PortSpec::new(
        "positions",
        PortType::Particles(None),
        "positions (N x d)",
    ))
    .output(PortSpec::new(
        "velocities",
        PortType::Particles(None),
        "velocities (N x d)",
    ))
    .params(geometry_params())
    .params(thermal_params())
    .param(ParamSpec::number(
        "density",
        Some(10.0),
        f64::MIN_POSITIVE,
        f64::MAX,
        "mean particles per cell",
    ))
    .param(random::seed_param())
    .param(random::stream_param())
    .build(|p| {
        let geo = Geometry::from_params(p)?;
        let unit = thermal_unit(p)?;
        let volume_cells: f64 = geo.lengths.iter().map(|l| (l / geo.cell).round()).product();
        let n = (p.number("density") * volume_cells).round();
        if !(1.0..=u32::MAX as f64 / 3.0).contains(&n) {
            return Err(format!(
                "density {} x {volume_cells} cells gives {} particles (1 to 2^32/3 allowed)",
                super::num(p.number("density")),
                super::num(n)
            ));
        }
        let mut u = geo.thermal_uniform(p);
        u.n = n as u32;
        u.kt = p.number("temperature") as f32;
        u.mass = p.number("mass") as f32;
        key_into(&mut u, p);
        let (seed, stream) = key_of(p);
        Ok(Box::new(MpcdInit {
            geo,
            u,
            seed,
            stream,
            vth: (p.number("temperature") / p.number("mass")).sqrt(),
            unit,
        }))
    })
}

struct MpcdInit {
    geo: Geometry,
    u: super::Uniform,
    seed: u64,
    stream: u32,
    vth: f64,
    /// The fixed-point unit of the cell sums the given velocities will enter.
    unit: f64,
}

impl MpcdInit {
    /// The type of the given state: both inputs or neither, matching the box.
    fn given(&self, inputs: &[Option<ValueType>]) -> Result<Option<ValueType>, PortError> {
        match (inputs[0], inputs[1]) {
            (None, None) => Ok(None),
            (Some(_), None) => Err(PortError::new(
                "velocities",
                "is needed with `positions` (give both or neither)",
            )),
            (None, Some(_)) => Err(PortError::new(
                "positions",
                "is needed with `velocities` (give both or neither)",
            )),
            (x, v) => {
                let n = self.geo.particles("positions", x)?;
                let nv = self.geo.particles("velocities", v)?;
                if n != nv {
                    return Err(PortError::new(
                        "velocities",
                        format!("has {nv} rows but positions has {n}"),
                    ));
                }
                Ok(x)
            }
        }
    }
}

impl Node for MpcdInit {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        if let Some(given) = self.given(inputs)? {
            return Ok(Signature::outputs(vec![given, given]));
        }
        let t = ValueType::Particles {
            n: self.u.n,
            k: self.geo.dims() as u32,
        };
        Ok(Signature::outputs(vec![t, t]).with_scratch(vec![32]))
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

    fn notes(&self, inputs: &[Option<ValueType>]) -> Vec<String> {
        match self.given(inputs) {
            Ok(Some(t)) => vec![format!("given state {t}")],
            _ => vec![format!("{} particles", self.u.n)],
        }
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        if let (Some(x), Some(v)) = (&inputs[0], &inputs[1]) {
            outputs[0].data.copy_from_slice(&x.data);
            outputs[1].data.copy_from_slice(&v.data);
            return;
        }
        let d = self.geo.dims();
        let n = self.u.n as usize;
        let mut mean = [0.0; 3];
        for e in 0..n * d {
            let l = self.geo.lengths[e % d];
            let key = e as u64;
            outputs[0].data[e] = (random::uniform(key, 0, self.seed, self.stream) - 0.5) * l;
            let v = self.vth * random::normal(key, 0, self.seed, self.stream.wrapping_add(1));
            outputs[1].data[e] = v;
            mean[e % d] += v / n as f64;
        }
        for (e, v) in outputs[1].data.iter_mut().enumerate() {
            *v -= mean[e % d];
        }
    }
}

impl GpuKernels for MpcdInit {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        if let (Some(x), Some(v)) = (io.inputs[0], io.inputs[1]) {
            let copy = cx.kernel(&KernelSpec::new(
                "copy",
                cx.shader("engine/copy.wgsl")?,
                &[
                    Binding::StorageRead,
                    Binding::StorageReadWrite,
                    Binding::Uniform,
                ],
            ))?;
            let words = x.ty.words();
            let shape = cx.uniform("mpcd init copy", bytemuck::cast_slice(&[words as u32]));
            let groups = cx.grid_1d(words, WG_1D);
            return Ok(vec![
                cx.dispatch(&copy, &[x.buffer, io.outputs[0].buffer, &shape], groups),
                cx.dispatch(&copy, &[v.buffer, io.outputs[1].buffer, &shape], groups),
            ]);
        }
        let bindings = [
            Binding::Uniform,
            Binding::StorageReadWrite,
            Binding::StorageReadWrite,
            Binding::StorageReadWrite,
        ];
        let src = cx.shader("mpcd/init.wgsl")?;
        let d = self.geo.dims() as f64;
        let draw = cx.kernel(
            &KernelSpec::new("mpcd_init draw", src.clone(), &bindings)
                .entry("draw")
                .constant("DIMS", d),
        )?;
        let center = cx.kernel(
            &KernelSpec::new("mpcd_init center", src, &bindings)
                .entry("center")
                .constant("DIMS", d),
        )?;
        let params = cx.uniform("mpcd init", bytemuck::bytes_of(&self.u));
        let total = io.scratch[0];
        let buffers = [&params, io.outputs[0].buffer, io.outputs[1].buffer, total];
        let groups = cx.grid_1d(self.u.n as u64, WG_1D);
        Ok(vec![
            cx.fill(total, 8, 0)?,
            cx.dispatch(&draw, &buffers, groups),
            cx.dispatch(&center, &buffers, groups),
        ])
    }
}
