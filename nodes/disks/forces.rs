//! `nonreciprocal_forces`: the pair forces of S1 eq. 2, F_i = mu_i sum_k alpha_k f(r_i - r_k)
//! with f(r) = r / |r|^3 (long range) or r / |r|^7 (short range, cut off at `cutoff`,
//! 2.5 sigma in the paper), every pair by the minimum image only (no lattice sum: the
//! periodic sum of a 2-D 1/r potential does not converge without a background, and the
//! paper does none). mu_i alpha_k > 0 repels. With alpha = mu for every particle the law is
//! reciprocal and the forces sum to zero.
//!
//! Both laws run all pairs, tiled through workgroup memory (shaders/disks/forces.wgsl);
//! the long-range law without cutoff takes one periodic image per (particle, tile) where
//! the tile's bounding box allows it (a first launch writes the boxes to scratch), so
//! particles in a spatial order run the pair loop without a minimum image (the graphs
//! sort the disks by Morton cell first). Where the particle tiles are too few to fill the
//! GPU, the tiles are split into ranges summed by separate workgroups and added per
//! particle in a fixed order after (`slices`). This node
//! applies the short-range law's cutoff inside the all-pairs loop (O(N^2), exact); the
//! graphs' short range goes through the 2-D cell list instead (`neighbour_sum`'s
//! `nonreciprocal` kernel).

use super::{box_param, minimum_image};
use crate::gpu::DeviceCaps;
use crate::gpu::{Binding, CompileCtx, CompileError, Dispatch, KernelSpec, NodeIo};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamSpec, PortError, PortSpec, RefCtx, Registry,
    Signature,
};
use crate::value::{PortType, RefArray, ValueType};

/// Threads per workgroup and particles per tile (shaders/disks/forces.wgsl).
const WG: u32 = 128;

/// Workgroups the all-pairs launch aims for at least: about what an H100 or H200 holds
/// resident at once (132 multiprocessors x 16 workgroups of 128 threads).
const FILL_WORKGROUPS: u32 = 2048;

/// The ranges the tiles are split into for `n` particles (the shader's `slices`) and the
/// tiles in each: one range where the particle tiles alone fill the GPU, otherwise enough
/// to reach FILL_WORKGROUPS, each range keeping at least 4 tiles (none left empty).
fn slices(n: u32) -> (u32, u32) {
    let tiles = n.div_ceil(WG).max(1);
    let wanted = FILL_WORKGROUPS.div_ceil(tiles).min(tiles / 4).max(1);
    let per_slice = tiles.div_ceil(wanted);
    (tiles.div_ceil(per_slice), per_slice)
}

/// `every_lane`, which shaders/disks/forces.wgsl calls to choose the long-range path: with
/// subgroups, whether the test holds on every lane of the subgroup (a warp whose lanes
/// disagree takes the exact loop together rather than both loops one after the other);
/// without, the thread's own test. Either gives the minimum image of every pair.
pub fn every_lane_source(subgroups: bool) -> &'static str {
    if subgroups {
        "fn every_lane(b: bool) -> bool { return subgroupAll(b); }\n"
    } else {
        "fn every_lane(b: bool) -> bool { return b; }\n"
    }
}

fn nonreciprocal_forces_kind() -> NodeKind {
    NodeKind::declare(
        "nonreciprocal_forces",
        "2-D pair forces F_i = mu_i sum_k alpha_k f(r_i - r_k) (S1 eq. 2), f(r) = r/|r|^3 (law long) or r/|r|^7 (law short), zero from `cutoff` on when it is positive, minimum image; all pairs in workgroup tiles",
    )
    .input(PortSpec::new(
        "positions",
        PortType::Particles(Some(2)),
        "positions (N x 2)",
    ))
    .input(PortSpec::new(
        "charges",
        PortType::Particles(Some(2)),
        "(alpha, mu) per particle (N x 2): alpha makes the field, mu responds to it",
    ))
    .output(PortSpec::new(
        "forces",
        PortType::Particles(Some(2)),
        "forces in velocity units (the mobility is absorbed, S1 eq. 1) (N x 2)",
    ))
    .param(ParamSpec::choice(
        "law",
        "long",
        &["long", "short"],
        "long: f(r) = r / |r|^3; short: f(r) = r / |r|^7",
    ))
    .param(ParamSpec::f32_nonnegative(
        "cutoff",
        Some(0.0),
        "pairs at |r| >= cutoff add nothing (0: no cutoff); S1 cuts the short-range law at 2.5 sigma",
    ))
    .param(box_param())
    .build(|p| {
        let b = p.numbers("box");
        Ok(Box::new(NonreciprocalForces {
            short: p.text("law") == "short",
            cutoff: p.number("cutoff"),
            box_lengths: [b[0], b[1]],
        }))
    })
}

pub struct NonreciprocalForces {
    short: bool,
    cutoff: f64,
    box_lengths: [f64; 2],
}

impl NonreciprocalForces {
    /// f(r) / |r| for a squared distance: the weight of r in the force.
    fn weight(&self, r2: f64) -> f64 {
        if r2 == 0.0 || (self.cutoff > 0.0 && r2 >= self.cutoff * self.cutoff) {
            return 0.0;
        }
        if self.short {
            r2.powf(-3.5)
        } else {
            r2.powf(-1.5)
        }
    }
}

/// The f64 sum of S1 eq. 2 for these positions and (alpha, mu) rows.
pub fn forces_reference(
    x: &[f64],
    charges: &[f64],
    short: bool,
    cutoff: f64,
    box_lengths: [f64; 2],
) -> Vec<f64> {
    let node = NonreciprocalForces {
        short,
        cutoff,
        box_lengths,
    };
    let n = x.len() / 2;
    let mut out = vec![0.0; 2 * n];
    for i in 0..n {
        let mut f = [0.0; 2];
        for k in 0..n {
            let r: [f64; 2] = std::array::from_fn(|d| {
                minimum_image(x[2 * i + d] - x[2 * k + d], node.box_lengths[d])
            });
            let w = charges[2 * k] * node.weight(r[0] * r[0] + r[1] * r[1]);
            f[0] += w * r[0];
            f[1] += w * r[1];
        }
        out[2 * i] = charges[2 * i + 1] * f[0];
        out[2 * i + 1] = charges[2 * i + 1] * f[1];
    }
    out
}

impl Node for NonreciprocalForces {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let (Some(x), Some(q)) = (inputs[0], inputs[1]) else {
            unreachable!("required")
        };
        if x != q {
            return Err(PortError::new(
                "charges",
                format!("is {q} but positions are {x}: one (alpha, mu) row per particle"),
            ));
        }
        let tiles = match x {
            ValueType::Particles { n, .. } => n.div_ceil(WG) as u64,
            _ => 1,
        };
        let n = match x {
            ValueType::Particles { n, .. } => n,
            _ => 1,
        };
        // Each tile's bounding box (shaders/disks/forces.wgsl `bounds`), and the slices'
        // partial sums where there are several.
        let partials = if slices(n).0 > 1 {
            8 * slices(n).0 as u64 * n as u64
        } else {
            8
        };
        Ok(Signature::outputs(vec![x]).with_scratch(vec![16 * tiles.max(1), partials]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn notes(&self, inputs: &[Option<ValueType>]) -> Vec<String> {
        let n = match inputs[0] {
            Some(ValueType::Particles { n, .. }) => n,
            _ => 0,
        };
        vec![format!(
            "all {n} x {n} pairs in tiles of {WG} ({} slices), law r/|r|^{}{}",
            slices(n).0,
            if self.short { 7 } else { 3 },
            if self.cutoff > 0.0 {
                format!(", cut at {}", self.cutoff)
            } else {
                String::new()
            }
        )]
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let x = &inputs[0].as_ref().expect("required").data;
        let q = &inputs[1].as_ref().expect("required").data;
        outputs[0].data = forces_reference(x, q, self.short, self.cutoff, self.box_lengths);
    }
}

impl GpuKernels for NonreciprocalForces {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let x = io.inputs[0].expect("required");
        let q = io.inputs[1].expect("required");
        let ValueType::Particles { n, .. } = x.ty else {
            unreachable!()
        };
        let bindings = [
            Binding::StorageRead,
            Binding::StorageRead,
            Binding::StorageReadWrite,
            Binding::Uniform,
            Binding::StorageReadWrite,
            Binding::StorageReadWrite,
        ];
        let source = format!(
            "{}{}",
            every_lane_source(cx.caps().subgroups.is_some()),
            cx.shader("disks/forces.wgsl")?
        );
        let kernel = cx.kernel(&KernelSpec::new(
            "nonreciprocal_forces",
            source.clone(),
            &bindings,
        ))?;
        let cutoff2 = (self.cutoff * self.cutoff) as f32;
        let (slices, tiles_per_slice) = slices(n);
        let tiles = n.div_ceil(WG);
        let words: [u32; 8] = [
            n,
            self.short as u32,
            cutoff2.to_bits(),
            0, // zero: the shader reads its 0 from here (minimum_image)
            (self.box_lengths[0] as f32).to_bits(),
            (self.box_lengths[1] as f32).to_bits(),
            slices,
            tiles_per_slice,
        ];
        let params = cx.uniform("nonreciprocal forces", bytemuck::cast_slice(&words));
        let buffers = [
            x.buffer,
            q.buffer,
            io.outputs[0].buffer,
            &params,
            io.scratch[0],
            io.scratch[1],
        ];
        let mut out = Vec::new();
        // The tile boxes serve the long-range law without cutoff only (the shader's `fast`).
        if !self.short && cutoff2 <= 0.0 {
            let bounds = cx.kernel(
                &KernelSpec::new("nonreciprocal_forces bounds", source.clone(), &bindings)
                    .entry("bounds"),
            )?;
            out.push(cx.dispatch(&bounds, &buffers, cx.grid_1d(n.div_ceil(WG) as u64, WG)));
        }
        out.push(cx.dispatch(
            &kernel,
            &buffers,
            cx.grid_1d(tiles as u64 * slices as u64 * WG as u64, WG),
        ));
        if slices > 1 {
            let combine = cx.kernel(
                &KernelSpec::new("nonreciprocal_forces combine", source, &bindings)
                    .entry("combine"),
            )?;
            out.push(cx.dispatch(&combine, &buffers, cx.grid_1d(n as u64, WG)));
        }
        Ok(out)
    }
}

pub fn register(r: &mut Registry) {
    r.add(nonreciprocal_forces_kind());
}
