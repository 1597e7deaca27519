//! Spreading (particles to grid) and interpolation (grid to particles) with a separable
//! window from the library in `window.rs`.
//!
//! Conventions (UAMMD thesis section 21, digest section 1.2): spreading adds the window
//! times the value, f_j = sum_i delta(r_j - q_i) F_i; interpolation integrates against it,
//! u_i = sum_j delta(q_i - r_j) v_j dV_j with dV the cell volume or per-cell quadrature
//! weights. Both nodes build their stencil from the same [`GridWindow`], so
//! <S F, v>_dV = <F, J v> by construction. Grid cells are centred at -L/2 + (j + 1/2) h.

pub mod boxgen;
pub mod fixed;
pub mod interpgen;
pub mod strategy;
pub mod tilegen;
pub mod window;

use crate::expr::ParamValue;
use crate::gpu::{
    Binding, Choice, CompileCtx, CompileError, DeviceCaps, Dispatch, KernelSpec, NodeIo, Slot,
};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamKind, ParamSpec, Params, PortError, PortSpec,
    RefCtx, Registry, Signature,
};
use crate::value::{PortType, RefArray, ValueType};
use strategy::{
    Add, InterpolatePlan, InterpolateStrategy, SpreadPlan, SpreadStrategy, TileLaunch, TileMode,
    Variant, box_run,
};
use window::Window;

/// Components one dispatch carries; more go in several dispatches.
pub const CHUNK_COMPS: u32 = 4;

/// A periodic grid over a box centred at the origin, with the window used on it.
#[derive(Clone, Debug, PartialEq)]
pub struct GridWindow {
    pub lengths: Vec<f64>,
    pub cells: Vec<u32>,
    pub window: Window,
    /// Threads per workgroup of the kernels (64, 128 or 256): a tuning knob.
    pub workgroup: u32,
    /// Serve particles in input order (for input sorted in space: concurrent workgroups
    /// then share cache lines of a grid too large for the cache) instead of in
    /// interleaved runs.
    pub contiguous: bool,
    /// Decide `contiguous` from the grid's size.
    pub auto_order: bool,
    /// Per-particle kernels with a segment of subgroup lanes per particle (interpgen.rs)
    /// where the adapter and the support allow; false: the workgroup-table kernels.
    pub lanes: bool,
    /// Gaussian window: the fewest cells its standard deviation may span (0: no check).
    /// Checked when the node is planned, not built, so an unused node never fails.
    pub min_width_cells: f64,
}

/// Grids whose components take more than this (about the GPU's last-level cache) are
/// served in input order, so that particles sorted in space touch the grid with locality;
/// smaller ones stay in cache whatever the order. FCM sorts particles above it too.
pub const LARGE_GRID_BYTES: u64 = 32 << 20;

impl GridWindow {
    pub fn dims(&self) -> usize {
        self.cells.len()
    }

    pub fn h(&self, a: usize) -> f64 {
        self.lengths[a] / self.cells[a] as f64
    }

    /// Interleaved runs of particles (see shaders/spread/stencil.wgsl) for `count`
    /// particles and `comps` components, or 1 (input order).
    pub fn chunks(&self, count: u32, comps: u32) -> u32 {
        let big = self.cell_count() as u64 * comps as u64 * 4 > LARGE_GRID_BYTES;
        if self.contiguous || (self.auto_order && big) {
            1
        } else {
            chunks(count)
        }
    }

    /// The accuracy guard `min_width_cells` for a Gaussian window on this grid.
    pub fn check_resolution(&self, port: &str) -> Result<(), PortError> {
        let Window::Gaussian { sigma, .. } = self.window else {
            return Ok(());
        };
        let h = (0..self.dims()).map(|a| self.h(a)).fold(0.0, f64::max);
        if sigma / h < self.min_width_cells {
            return Err(PortError::new(
                port,
                format!(
                    "the Gaussian window (sigma = {sigma:.6}) spans {:.4} cells of {h:.6}, fewer than min_width_cells = {:.4}: the grid is too coarse for this window at the accuracy asked for",
                    sigma / h,
                    self.min_width_cells
                ),
            ));
        }
        Ok(())
    }

    /// The grid as a value type with `comps` components (nz = 1 in 2D).
    pub fn grid_type(&self, comps: u32) -> ValueType {
        let mut dims = [1u32; 3];
        dims[..self.dims()].copy_from_slice(&self.cells);
        ValueType::RealGrid { dims, comps }
    }

    /// First support cell (unwrapped) and the window weights (per unit length) along axis
    /// `a` for coordinate x, in f64: the reference twin of the kernels' stencil.
    pub fn stencil(&self, x: f64, a: usize) -> (i64, Vec<f64>) {
        let l = self.lengths[a];
        let h = self.h(a);
        let ns = self.window.support() as f64;
        let folded = x - l * (x / l + 0.5).floor();
        let t = (folded + 0.5 * l) / h - 0.5;
        let j0 = (t - 0.5 * ns).floor() + 1.0;
        let w = (0..self.window.support())
            .map(|k| self.window.phi(j0 + k as f64 - t, h) / h)
            .collect();
        (j0 as i64, w)
    }

    /// Every support cell of a particle at `q` with its weight delta(r_cell - q).
    pub fn support(&self, q: &[f64]) -> Vec<(usize, f64)> {
        let d = self.dims();
        let st: Vec<(i64, Vec<f64>)> = (0..d).map(|a| self.stencil(q[a], a)).collect();
        let ns = self.window.support() as usize;
        let count = ns.pow(d as u32);
        let mut out = Vec::with_capacity(count);
        for j in 0..count {
            let idx = [j % ns, (j / ns) % ns, j / (ns * ns)];
            let mut w = 1.0;
            let mut cell = 0usize;
            for a in (0..d).rev() {
                let n = self.cells[a] as i64;
                let c = (st[a].0 + idx[a] as i64).rem_euclid(n) as usize;
                cell = cell * n as usize + c;
                w *= st[a].1[idx[a]];
            }
            out.push((cell, w));
        }
        out
    }

    fn cell_count(&self) -> usize {
        self.cells.iter().map(|&c| c as usize).product()
    }

    fn cell_volume(&self) -> f64 {
        (0..self.dims()).map(|a| self.h(a)).product()
    }
}

fn grid_params() -> Vec<ParamSpec> {
    vec![
        ParamSpec {
            name: "box",
            kind: ParamKind::Numbers {
                len: None,
                min: f64::MIN_POSITIVE,
                max: f64::MAX,
            },
            default: None,
            doc: "box lengths per axis (2 or 3 values), centred at the origin, periodic",
        },
        ParamSpec {
            name: "grid",
            kind: ParamKind::Numbers {
                len: None,
                min: 1.0,
                max: 65536.0,
            },
            default: None,
            doc: "cells per axis",
        },
        ParamSpec::choice(
            "window",
            "gaussian",
            window::NAMES,
            "the window (smoothing kernel)",
        ),
        ParamSpec::f32_nonnegative(
            "width",
            Some(0.0),
            "Gaussian: standard deviation (length units); ES: its half-width (length units; 0: support / 2 cells, tied to the cell)",
        ),
        ParamSpec::integer(
            "support",
            Some(0.0),
            0.0,
            window::MAX_SUPPORT as f64,
            "cells per axis (0: from the tolerance; fixed for Peskin windows); may exceed the grid's cells, the window then wraps around the periodic grid",
        ),
        ParamSpec::number(
            "beta",
            Some(0.0),
            0.0,
            f64::MAX,
            "ES: shape parameter (0: 2.3 x the cells the window spans)",
        ),
        ParamSpec::number(
            "tolerance",
            Some(1e-3),
            1e-15,
            0.5,
            "Gaussian and ES: truncation tolerance that sets the support",
        ),
        ParamSpec::choice(
            "order",
            "auto",
            &["auto", "interleaved", "contiguous"],
            "order particles are served in: interleaved runs (concurrent workgroups far apart: no contention), contiguous (for input sorted in space: cache locality on grids larger than the cache), auto: contiguous when the grid's components take more than 32 MiB",
        ),
        ParamSpec::number(
            "min_width_cells",
            Some(0.0),
            0.0,
            f64::MAX,
            "Gaussian: fail at planning when sigma spans fewer cells than this (an accuracy guard; 0: none)",
        ),
        ParamSpec::choice(
            "workgroup",
            "256",
            &["64", "128", "256"],
            "threads per workgroup (tuning: the workgroup-table kernels serve workgroup / support^2 particles per workgroup, the lane kernels workgroup / lanes per particle)",
        ),
        ParamSpec::choice(
            "lanes",
            "auto",
            &["auto", "off"],
            "per-particle kernels: auto: a segment of subgroup lanes per particle, no workgroup memory, where the adapter has subgroups at least as wide as the support; off: the workgroup-table kernels",
        ),
        ParamSpec::choice(
            "variant",
            "auto",
            &["auto", "atomic", "portable"],
            "spreading: float atomics, or compare-and-swap for adapters without them (auto: atomics when available); deterministic runs (--deterministic) take 64-bit fixed-point adds whatever this says",
        ),
    ]
}

fn grid_window(p: &Params) -> Result<GridWindow, String> {
    let lengths = p.numbers("box").to_vec();
    let grid = p.numbers("grid");
    if !(2..=3).contains(&lengths.len()) || grid.len() != lengths.len() {
        return Err(format!(
            "`box` and `grid` need 2 or 3 values each, got {} and {}",
            lengths.len(),
            grid.len()
        ));
    }
    if grid.iter().any(|g| g.fract() != 0.0) {
        return Err(format!(
            "`grid` must be whole numbers of cells, got {grid:?}"
        ));
    }
    let cells: Vec<u32> = grid.iter().map(|&g| g as u32).collect();
    let h_min = lengths
        .iter()
        .zip(&cells)
        .map(|(l, &n)| l / n as f64)
        .fold(f64::INFINITY, f64::min);
    let window = Window::from_params(
        p.text("window"),
        p.number("width"),
        p.number("support") as u32,
        p.number("beta"),
        p.number("tolerance"),
        h_min,
    )?;
    // A support wider than the grid is legal arithmetic: the window wraps around the
    // periodic grid more than once, every kernel path wraps each support cell on its own
    // (`wrap_cell`, as `GridWindow::support` does with rem_euclid) and adds with atomics.
    Ok(GridWindow {
        lengths,
        cells,
        window,
        // The choice list admits only 64, 128 and 256.
        workgroup: p.text("workgroup").parse().unwrap_or(256),
        min_width_cells: p.number("min_width_cells"),
        contiguous: p.text("order") == "contiguous",
        auto_order: p.text("order") == "auto",
        lanes: p.text("lanes") == "auto",
    })
}

/// Layout of `Geometry` in shaders/spread/geometry.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct GeometryUniform {
    n: [u32; 4],
    inv_h: [f32; 4],
    box_len: [f32; 4],
    inv_box: [f32; 4],
    win: [[f32; 4]; 3],
    count: u32,
    dv: f32,
    comp_offset: u32,
    run: u32,
}

fn geometry(gw: &GridWindow, count: u32) -> GeometryUniform {
    let mut u = GeometryUniform {
        n: [1, 1, 1, gw.cell_count() as u32],
        inv_h: [1.0; 4],
        box_len: [1.0; 4],
        inv_box: [1.0; 4],
        win: [[0.0; 4]; 3],
        count,
        dv: gw.cell_volume() as f32,
        comp_offset: 0,
        run: box_run(count, gw.cell_count() as u64),
    };
    for a in 0..gw.dims() {
        u.n[a] = gw.cells[a];
        u.inv_h[a] = (1.0 / gw.h(a)) as f32;
        u.box_len[a] = gw.lengths[a] as f32;
        u.inv_box[a] = (1.0 / gw.lengths[a]) as f32;
        u.win[a] = gw.window.gpu_params(gw.h(a));
    }
    u
}

/// The geometry uniform of one dispatch over `count` particles, for the components from
/// `comp_offset` on.
fn geometry_buffer(
    cx: &CompileCtx,
    label: &str,
    gw: &GridWindow,
    count: u32,
    comp_offset: u32,
) -> wgpu::Buffer {
    cx.uniform(
        label,
        bytemuck::bytes_of(&GeometryUniform {
            comp_offset,
            ..geometry(gw, count)
        }),
    )
}

/// Interleaved runs the particles are served in (see shaders/spread/stencil.wgsl): up to
/// 65536, more than the slots a large GPU runs at once, so concurrent workgroups work far
/// apart; at least 4 particles a run, so small problems launch no empty workgroups.
fn chunks(count: u32) -> u32 {
    (count / 4).clamp(1, 65536)
}

/// Threads per particle of the workgroup-table kernels (shaders/spread/stencil.wgsl):
/// support^2 rounded up to a power of two, at most 64.
fn table_segment(support: u32) -> u32 {
    (support * support).next_power_of_two().min(64)
}

/// Dispatch shape of the per-particle kernels (the workgroup-table kernels and the lane
/// kernels of interpgen.rs) for `count` particles served in `chunks` interleaved runs
/// (shaders/spread/slots.wgsl) by workgroups of `wg` threads, `seg` threads a particle.
fn slot_groups(cx: &CompileCtx, count: u32, chunks: u32, seg: u32, wg: u32) -> [u32; 3] {
    let c = chunks as u64;
    let slots = c * (count as u64).div_ceil(c);
    cx.grid_1d(slots.div_ceil((wg / seg) as u64), 1)
}

/// A generated kernel's WGSL (its imports resolved) after `prefix`, the shader files it
/// is composed with (the window, the add).
fn composed(prefix: &str, generated: &str) -> Result<String, CompileError> {
    let text = crate::gpu::shaders::resolve(generated).map_err(CompileError::Library)?;
    Ok(format!("{prefix}{text}"))
}

fn check_positions(gw: &GridWindow, t: Option<ValueType>) -> Result<u32, PortError> {
    let Some(ValueType::Particles { n, k }) = t else {
        unreachable!("port type checked")
    };
    if k as usize != gw.dims() {
        return Err(PortError::new(
            "positions",
            format!("has {k} columns but the box has {} axes", gw.dims()),
        ));
    }
    Ok(n)
}

fn spread_kind() -> NodeKind {
    NodeKind::declare(
        "spread",
        "spread particle values onto a periodic grid with a window: f_j = sum_i delta(r_j - q_i) F_i",
    )
    .input(PortSpec::new(
        "positions",
        PortType::Particles(None),
        "positions (N x 2 or N x 3)",
    ))
    .input(PortSpec::new(
        "values",
        PortType::Particles(None),
        "values per particle (N x C)",
    ))
    .output(PortSpec::new(
        "out",
        PortType::RealGrid,
        "the grid, C components",
    ))
    .params(grid_params())
    .param(ParamSpec {
        name: "sorted_input",
        kind: ParamKind::Bool,
        default: Some(ParamValue::Bool(false)),
        doc: "spreading: particles come sorted in space (Morton order of cells best); where they are dense (at least 0.5 per cell) and the support is 6 to 16 cells, spread box by box: runs of up to 64 particles summed in registers over the block of cells their supports cover, one grid atomic per box cell (runs whose box exceeds 16 cells per axis go direct). Interpolation ignores it",
    })
    .param(ParamSpec::choice(
        "tiles",
        "auto",
        &["auto", "on", "off"],
        "spreading (3D): tile by tile in workgroup memory (cuFINUFFT's shared-memory method): bin_sort's counting sort files each particle under the 8^3-cell tile of its first support cell, one workgroup per tile sums its particles into the padded tile as fixed-point integers (scaled per tile so no sum overflows: each add exact to 2^-30 of the tile's sum of |value| x the window's peak) and adds each padded cell to the grid once. Any input order; 20 bytes of scratch per particle. auto: where it pays (particles per cell x support^3 at least 32, and not where sorted_input spreads box by box) and the adapter has subgroups and the workgroup memory; on: always (an error where the adapter cannot); off: never",
    ))
    .build(|p| {
        Ok(Box::new(Spread {
            gw: grid_window(p)?,
            tiles: TileMode::parse(p.text("tiles")),
            sorted_input: p.flag("sorted_input"),
            variant: Variant::parse(p.text("variant")),
        }))
    })
}

struct Spread {
    gw: GridWindow,
    tiles: TileMode,
    sorted_input: bool,
    variant: Variant,
}

impl Spread {
    /// Scratch of tiled spreading, by role: per particle its tile (the sort key) and its
    /// anchor inside the tile, then bin_sort's outputs (the particles tile by tile, the
    /// sorted keys, each tile's count and first slot) and bin_sort's own scratch.
    fn tile_scratch(&self, n: u32) -> Vec<u64> {
        let tiles = self.tile_count() as u64;
        let n = n as u64;
        let mut s = vec![4 * n, 4 * n, 4 * n, 4 * n, 4 * tiles, 4 * tiles];
        s.extend(crate::nodes::bin_sort::scratch_bytes(n, tiles));
        s
    }

    /// Tiles of the grid.
    fn tile_count(&self) -> u32 {
        tilegen::tiles_per_axis(&self.gw.cells).iter().product()
    }
}

impl Node for Spread {
    fn infer(
        &self,
        inputs: &[Option<ValueType>],
        caps: &DeviceCaps,
    ) -> Result<Signature, PortError> {
        let n = check_positions(&self.gw, inputs[0])?;
        let Some(ValueType::Particles { n: m, k: comps }) = inputs[1] else {
            unreachable!("port type checked")
        };
        if m != n {
            return Err(PortError::new(
                "values",
                format!("has {m} rows for {n} positions"),
            ));
        }
        self.gw.check_resolution("values")?;
        let decision = strategy::spread(
            &self.gw,
            self.tiles,
            self.sorted_input,
            self.variant,
            n,
            comps,
            caps,
        );
        // The fixed-point grid of deterministic runs first, then the strategy's own.
        let mut scratch = match decision.0 {
            Ok(SpreadPlan {
                add: Add::FixedPoint { .. },
                ..
            }) => vec![4 * fixed::fixed_words(self.gw.grid_type(comps).words())],
            _ => Vec::new(),
        };
        if let Ok(SpreadPlan {
            strategy: SpreadStrategy::Tiles(_),
            ..
        }) = decision.0
        {
            scratch.extend(self.tile_scratch(n));
        }
        Ok(Signature::outputs(vec![self.gw.grid_type(comps)])
            .with_scratch(scratch)
            .with_plan(decision))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn notes(&self, _: &[Option<ValueType>]) -> Vec<String> {
        vec![format!(
            "{} on a {:?} grid of cells {:?}",
            self.gw.window.describe(),
            self.gw.cells,
            (0..self.gw.dims())
                .map(|a| self.gw.h(a))
                .collect::<Vec<_>>()
        )]
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let pos = &inputs[0].as_ref().expect("required").data;
        let vals = inputs[1].as_ref().expect("required");
        let ValueType::Particles { n, k } = vals.ty else {
            unreachable!()
        };
        let d = self.gw.dims();
        let cells = self.gw.cell_count();
        outputs[0].data.fill(0.0);
        for i in 0..n as usize {
            for (cell, w) in self.gw.support(&pos[i * d..(i + 1) * d]) {
                for c in 0..k as usize {
                    outputs[0].data[c * cells + cell] += w * vals.data[i * k as usize + c];
                }
            }
        }
    }
}

impl GpuKernels for Spread {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let (pos, vals, out, n, comps) = spread_ports(io);
        let plan = *io.plan::<Choice<SpreadPlan>>().get()?;
        let add = plan.add.shader();
        let ns = self.gw.window.support();
        let accumulate = Accumulate::of(plan.add, io, out);
        let (boxed, lanes) = match plan.strategy {
            SpreadStrategy::Tiles(launch) => {
                return self.compile_tiles(cx, io, add, launch, accumulate);
            }
            SpreadStrategy::Boxes { run } => (Some(run), None),
            SpreadStrategy::Lanes { seg } => (None, Some(seg)),
            SpreadStrategy::Table => (None, None),
        };
        let prefix = format!("{}{}", cx.shader(self.gw.window.shader())?, cx.shader(add)?);
        // The workgroup-table kernel's source, where neither generated kernel serves.
        let plain = if boxed.is_some() || lanes.is_some() {
            String::new()
        } else {
            format!("{prefix}{}", cx.shader("spread/spread.wgsl")?)
        };
        let mut dispatches = accumulate.begin(cx, vals, out)?;
        let chunks = plan.chunks;
        for first in (0..comps).step_by(CHUNK_COMPS as usize) {
            let chunk = CHUNK_COMPS.min(comps - first);
            let bindings = [
                Binding::StorageRead,
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::Uniform,
            ];
            let name = |how: &str| format!("spread ({}{how})", self.gw.window.shader());
            let generated = |text: String| composed(&prefix, &text);
            let (spec, groups) = if let Some(run) = boxed {
                let text = boxgen::spread_source(ns, self.gw.dims() as u32, chunk, comps);
                (
                    KernelSpec::new(name(", boxes"), generated(text)?, &bindings),
                    cx.grid_1d((n as u64).div_ceil(run as u64), 1),
                )
            } else if let Some(seg) = lanes {
                let text = interpgen::spread_source(
                    ns,
                    self.gw.dims() as u32,
                    chunk,
                    comps,
                    seg,
                    self.gw.workgroup,
                );
                let spec = KernelSpec::new(name(", lanes"), generated(text)?, &bindings)
                    .constant("CHUNKS", chunks as f64);
                (spec, slot_groups(cx, n, chunks, seg, self.gw.workgroup))
            } else {
                (
                    KernelSpec::new(name(""), plain.clone(), &bindings)
                        .constant("NS", ns as f64)
                        .constant("DIMS", self.gw.dims() as f64)
                        .constant("TOTAL", comps as f64)
                        .constant("COMPS", chunk as f64)
                        .constant("CHUNKS", chunks as f64)
                        .constant("WG", self.gw.workgroup as f64),
                    slot_groups(cx, n, chunks, table_segment(ns), self.gw.workgroup),
                )
            };
            let kernel = cx.kernel(&accumulate.constants(spec, out))?;
            let geo = geometry_buffer(cx, "spread geometry", &self.gw, n, first);
            dispatches.push(cx.dispatch(
                &kernel,
                &[pos.buffer, vals.buffer, accumulate.grid, &geo],
                groups,
            ));
        }
        dispatches.extend(accumulate.finish(cx, out)?);
        Ok(dispatches)
    }
}

/// Where the spreading kernels add: the f32 grid itself, or in deterministic runs the
/// fixed-point grid (fixed.rs, the first scratch buffer) converted to it at the end.
struct Accumulate<'a> {
    grid: &'a wgpu::Buffer,
    fixed_exp: Option<i32>,
}

impl<'a> Accumulate<'a> {
    fn of(add: Add, io: &NodeIo<'a>, out: Slot<'a>) -> Self {
        match add {
            Add::FixedPoint { exp } => Accumulate {
                grid: io.scratch[0],
                fixed_exp: Some(exp),
            },
            _ => Accumulate {
                grid: out.buffer,
                fixed_exp: None,
            },
        }
    }

    /// Scratch buffers before the strategy's own.
    fn scratch_offset(&self) -> usize {
        usize::from(self.fixed_exp.is_some())
    }

    fn begin(
        &self,
        cx: &mut CompileCtx<'_>,
        vals: Slot<'_>,
        out: Slot<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        match self.fixed_exp {
            Some(_) => fixed::begin(cx, self.grid, vals.buffer, vals.ty.words(), out.ty.words()),
            None => Ok(vec![cx.fill(out.buffer, out.ty.words(), 0)?]),
        }
    }

    fn constants(&self, spec: KernelSpec, out: Slot<'_>) -> KernelSpec {
        match self.fixed_exp {
            Some(exp) => fixed::with_constants(spec, out.ty.words(), exp),
            None => spec,
        }
    }

    fn finish(
        &self,
        cx: &mut CompileCtx<'_>,
        out: Slot<'_>,
    ) -> Result<Option<Dispatch>, CompileError> {
        self.fixed_exp
            .map(|exp| fixed::finish(cx, self.grid, out.buffer, out.ty.words(), exp))
            .transpose()
    }
}

/// The spread node's ports: positions, values, the grid, and the particle count and
/// components per particle.
fn spread_ports<'a>(io: &NodeIo<'a>) -> (Slot<'a>, Slot<'a>, Slot<'a>, u32, u32) {
    let pos = io.inputs[0].expect("required");
    let vals = io.inputs[1].expect("required");
    let ValueType::Particles { n, k: comps } = vals.ty else {
        unreachable!("port type checked")
    };
    (pos, vals, io.outputs[0], n, comps)
}

/// Layout of `Tiles` in shaders/spread/tiles.wgsl and the tile kernel.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct TilesUniform {
    nt: [u32; 4],
}

impl Spread {
    /// Tiled spreading: the counting sort by tile (fill, rank, scan, place), then the
    /// tile kernel for `launch.per_dispatch` components at a time.
    fn compile_tiles(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
        add: &str,
        launch: TileLaunch,
        accumulate: Accumulate<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let (pos, vals, out, n, comps) = spread_ports(io);
        let [
            keys,
            local,
            order,
            keys_out,
            count,
            start,
            counter,
            rank,
            scan_scratch @ ..,
        ] = &io.scratch[accumulate.scratch_offset()..]
        else {
            unreachable!("scratch from infer")
        };
        let ns = self.gw.window.support();
        let per_axis = tilegen::tiles_per_axis(&self.gw.cells);
        let mut nt = [1u32; 4];
        nt[..3].copy_from_slice(&per_axis);
        nt[3] = self.tile_count();
        let tiles = cx.uniform("spread tiles", bytemuck::bytes_of(&TilesUniform { nt }));
        let geo = geometry_buffer(cx, "spread geometry", &self.gw, n, 0);
        let window = cx.shader(self.gw.window.shader())?;
        let mut dispatches = accumulate.begin(cx, vals, out)?;
        let spec = KernelSpec::new(
            "spread tiles: keys",
            cx.shader("spread/tiles.wgsl")?,
            &[
                Binding::StorageRead,
                Binding::Uniform,
                Binding::Uniform,
                Binding::StorageReadWrite,
                Binding::StorageReadWrite,
            ],
        )
        .constant("NS", ns as f64)
        .constant("TILE", tilegen::TILE as f64);
        let kernel = cx.kernel(&spec)?;
        dispatches.push(cx.dispatch(
            &kernel,
            &[pos.buffer, &geo, &tiles, keys, local],
            cx.grid_1d(n as u64, 256),
        ));
        // The particles listed tile by tile: the counting sort of bin_sort.
        dispatches.extend(crate::nodes::bin_sort::record(
            cx,
            &launch.sort,
            nt[3],
            n as u64,
            &crate::nodes::bin_sort::BinSortBuffers {
                keys,
                perm: order,
                keys_out,
                count,
                start,
                counter,
                rank,
                scan_scratch,
            },
        )?);
        let prefix = format!("{window}{}", cx.shader(add)?);
        let peak: f64 = (0..3)
            .map(|a| tilegen::peak_weight(&self.gw.window, self.gw.h(a)))
            .product();
        for first in (0..comps).step_by(launch.per_dispatch as usize) {
            let chunk = launch.per_dispatch.min(comps - first);
            let text = tilegen::spread_source(ns, chunk, comps, launch.seg, launch.min_subgroup);
            let spec = KernelSpec::new(
                format!("spread ({}, tiles)", self.gw.window.shader()),
                composed(&prefix, &text)?,
                &[
                    Binding::StorageRead,
                    Binding::StorageRead,
                    Binding::StorageReadWrite,
                    Binding::Uniform,
                    Binding::Uniform,
                    Binding::StorageRead,
                    Binding::StorageRead,
                    Binding::StorageRead,
                    Binding::StorageRead,
                ],
            )
            .constant("PEAK", peak);
            let kernel = cx.kernel(&accumulate.constants(spec, out))?;
            let geo = geometry_buffer(cx, "spread geometry", &self.gw, n, first);
            dispatches.push(cx.dispatch(
                &kernel,
                &[
                    pos.buffer,
                    vals.buffer,
                    accumulate.grid,
                    &geo,
                    &tiles,
                    count,
                    start,
                    order,
                    local,
                ],
                cx.grid_1d(nt[3] as u64, 1),
            ));
        }
        dispatches.extend(accumulate.finish(cx, out)?);
        Ok(dispatches)
    }
}

fn interpolate_kind() -> NodeKind {
    NodeKind::declare(
        "interpolate",
        "interpolate a periodic grid at particles with a window (the adjoint of spread): u_i = sum_j delta(q_i - r_j) v_j dV_j",
    )
    .input(PortSpec::new(
        "grid",
        PortType::RealGrid,
        "the field, C components",
    ))
    .input(PortSpec::new(
        "positions",
        PortType::Particles(None),
        "positions (N x 2 or N x 3)",
    ))
    .input(
        PortSpec::new(
            "weights",
            PortType::RealGrid,
            "per-cell quadrature weights dV (default: the cell volume)",
        )
        .optional(),
    )
    .output(PortSpec::new(
        "out",
        PortType::Particles(None),
        "values per particle (N x C)",
    ))
    .params(grid_params())
    .build(|p| {
        Ok(Box::new(Interpolate {
            gw: grid_window(p)?,
            variant: Variant::parse(p.text("variant")),
        }))
    })
}

struct Interpolate {
    gw: GridWindow,
    variant: Variant,
}

impl Node for Interpolate {
    fn infer(
        &self,
        inputs: &[Option<ValueType>],
        caps: &DeviceCaps,
    ) -> Result<Signature, PortError> {
        let Some(ValueType::RealGrid { dims, comps }) = inputs[0] else {
            unreachable!("port type checked")
        };
        if self.gw.grid_type(comps) != inputs[0].expect("required") {
            return Err(PortError::new(
                "grid",
                format!("is {dims:?} cells but the params say {:?}", self.gw.cells),
            ));
        }
        if let Some(w) = inputs[2]
            && w != self.gw.grid_type(1)
        {
            return Err(PortError::new(
                "weights",
                format!(
                    "is {w} but must be {} (one weight per cell)",
                    self.gw.grid_type(1)
                ),
            ));
        }
        let n = check_positions(&self.gw, inputs[1])?;
        self.gw.check_resolution("grid")?;
        let plan = strategy::interpolate(&self.gw, self.variant, n, comps, caps);
        Ok(Signature::outputs(vec![ValueType::Particles { n, k: comps }]).with_plan(plan))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn notes(&self, _: &[Option<ValueType>]) -> Vec<String> {
        vec![format!(
            "{} on a {:?} grid",
            self.gw.window.describe(),
            self.gw.cells
        )]
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let grid = inputs[0].as_ref().expect("required");
        let pos = &inputs[1].as_ref().expect("required").data;
        let weights = inputs[2].as_ref().map(|w| &w.data);
        let ValueType::RealGrid { comps, .. } = grid.ty else {
            unreachable!()
        };
        let d = self.gw.dims();
        let cells = self.gw.cell_count();
        let dv = self.gw.cell_volume();
        let k = comps as usize;
        for (i, row) in outputs[0].data.chunks_mut(k).enumerate() {
            row.fill(0.0);
            for (cell, w) in self.gw.support(&pos[i * d..(i + 1) * d]) {
                let q = weights.map(|ws| ws[cell]).unwrap_or(dv);
                for (c, r) in row.iter_mut().enumerate() {
                    *r += w * q * grid.data[c * cells + cell];
                }
            }
        }
    }
}

impl GpuKernels for Interpolate {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let grid = io.inputs[0].expect("required");
        let pos = io.inputs[1].expect("required");
        let weights = io.inputs[2];
        let ValueType::RealGrid { comps, .. } = grid.ty else {
            unreachable!()
        };
        let ValueType::Particles { n, .. } = pos.ty else {
            unreachable!()
        };
        let plan = io.plan::<InterpolatePlan>();
        let ns = self.gw.window.support();
        let window = cx.shader(self.gw.window.shader())?;
        // The workgroup-table kernel's source, where the lane kernel does not serve.
        let (lanes, source) = match plan.strategy {
            InterpolateStrategy::Lanes { seg } => (Some(seg), String::new()),
            InterpolateStrategy::Table { subgroups } => {
                let file = InterpolateStrategy::table_shader(subgroups);
                (None, format!("{window}{}", cx.shader(file)?))
            }
        };
        // Without weights the binding still needs a buffer; the kernel never reads it.
        let quadrature = weights.map(|w| w.buffer).unwrap_or(grid.buffer);
        let mut dispatches = Vec::new();
        let chunks = plan.chunks;
        for first in (0..comps).step_by(CHUNK_COMPS as usize) {
            let chunk = CHUNK_COMPS.min(comps - first);
            let bindings = [
                Binding::StorageRead,
                Binding::StorageRead,
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::Uniform,
            ];
            let (spec, groups) = if let Some(seg) = lanes {
                let generated = interpgen::interpolate_source(
                    ns,
                    self.gw.dims() as u32,
                    chunk,
                    comps,
                    weights.is_some(),
                    seg,
                    self.gw.workgroup,
                );
                let source = composed(&window, &generated)?;
                let spec = KernelSpec::new(
                    format!("interpolate ({}, lanes)", self.gw.window.shader()),
                    source,
                    &bindings,
                )
                .constant("CHUNKS", chunks as f64);
                (spec, slot_groups(cx, n, chunks, seg, self.gw.workgroup))
            } else {
                let spec = KernelSpec::new(
                    format!("interpolate ({})", self.gw.window.shader()),
                    source.clone(),
                    &bindings,
                )
                .constant("NS", ns as f64)
                .constant("DIMS", self.gw.dims() as f64)
                .constant("COMPS", chunk as f64)
                .constant("TOTAL", comps as f64)
                .constant("HAS_WEIGHTS", f64::from(u8::from(weights.is_some())))
                .constant("CHUNKS", chunks as f64)
                .constant("WG", self.gw.workgroup as f64);
                (
                    spec,
                    slot_groups(cx, n, chunks, table_segment(ns), self.gw.workgroup),
                )
            };
            let kernel = cx.kernel(&spec)?;
            let geo = geometry_buffer(cx, "interpolate geometry", &self.gw, n, first);
            dispatches.push(cx.dispatch(
                &kernel,
                &[
                    pos.buffer,
                    grid.buffer,
                    quadrature,
                    io.outputs[0].buffer,
                    &geo,
                ],
                groups,
            ));
        }
        Ok(dispatches)
    }
}

pub fn register(r: &mut Registry) {
    r.add(spread_kind());
    r.add(interpolate_kind());
}
