//! How `spread` and `interpolate` run: the one place their strategies are chosen.
//!
//! Each node decides once, in `infer`, from its typed params, the particle count and the
//! adapter's capabilities, into a [`SpreadPlan`] or an [`InterpolatePlan`]. The planner
//! keeps the decision with the node's launch, `mesoflow inspect` prints it, the scratch
//! `infer` asks for follows it, and `compile` builds the kernels it names: nothing
//! downstream re-reads a param or re-asks the adapter.

use std::fmt;

use super::{GridWindow, fixed, interpgen, tilegen};
use crate::gpu::{Choice, DeviceCaps};
use crate::nodes::bin_sort::{self, BinSortPlan};
use crate::nodes::scan;

/// The `tiles` param of `spread`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TileMode {
    /// Tile by tile where it pays and the adapter can.
    Auto,
    /// Always (an error where the adapter cannot).
    On,
    Off,
}

impl TileMode {
    pub fn parse(s: &str) -> TileMode {
        match s {
            "on" => TileMode::On,
            "off" => TileMode::Off,
            _ => TileMode::Auto,
        }
    }
}

/// The `variant` param of both nodes: how spreading adds into the grid (float atomics
/// or compare-and-swap), and for interpolation whether subgroup operations may be used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Variant {
    /// Whatever the adapter has.
    Auto,
    /// Float atomics (an error where the adapter lacks them); interpolation: as `Auto`.
    Atomic,
    /// Compare-and-swap adds, no subgroup operations.
    Portable,
}

impl Variant {
    pub fn parse(s: &str) -> Variant {
        match s {
            "atomic" => Variant::Atomic,
            "portable" => Variant::Portable,
            _ => Variant::Auto,
        }
    }
}

/// How a spreading kernel adds a weighted value into a grid cell.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Add {
    /// `atomicAdd` on f32 (SHADER_FLOAT32_ATOMIC).
    FloatAtomic,
    /// A compare-and-swap loop on the f32 bits.
    CompareAndSwap,
    /// Deterministic runs: 64-bit fixed-point integers in a scratch grid (fixed.rs),
    /// scaled by 2^(60 - e - exp) for the largest |value| 2^e and the bound 2^exp on a
    /// cell's total weight, then converted to f32: any order of the adds, the same bits.
    FixedPoint { exp: i32 },
}

impl Add {
    /// The shader file that defines the kernels' `add`.
    pub fn shader(self) -> &'static str {
        match self {
            Add::FloatAtomic => "spread/add_atomic.wgsl",
            Add::CompareAndSwap => "spread/add_cas.wgsl",
            Add::FixedPoint { .. } => "spread/add_fixed.wgsl",
        }
    }
}

/// How the tile kernel runs on an adapter: components per dispatch (as many as workgroup
/// memory holds, up to `CHUNK_COMPS`), lanes per particle, the smallest subgroup it must
/// size its per-subgroup sums for, and how the counting sort by tile runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileLaunch {
    pub per_dispatch: u32,
    pub seg: u32,
    pub min_subgroup: u32,
    pub sort: BinSortPlan,
}

/// The kernel family that spreads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpreadStrategy {
    /// Tile by tile in workgroup memory (tilegen.rs), after a counting sort by tile.
    Tiles(TileLaunch),
    /// Sorted, dense input box by box (boxgen.rs): runs of `run` particles per workgroup.
    Boxes { run: u32 },
    /// A segment of `seg` subgroup lanes per particle (interpgen.rs).
    Lanes { seg: u32 },
    /// The workgroup-table kernel (shaders/spread/spread.wgsl).
    Table,
}

/// What `spread` runs for one particle count on one adapter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SpreadPlan {
    pub strategy: SpreadStrategy,
    pub add: Add,
    /// Interleaved runs the per-particle kernels serve particles in (1: input order).
    pub chunks: u32,
}

/// What `interpolate` runs for one particle count on one adapter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct InterpolatePlan {
    pub strategy: InterpolateStrategy,
    pub chunks: u32,
}

/// The kernel family that interpolates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InterpolateStrategy {
    /// A segment of `seg` subgroup lanes per particle (interpgen.rs).
    Lanes { seg: u32 },
    /// The workgroup-table kernel, reducing with subgroup shuffles where `subgroups`
    /// (shaders/spread/interpolate_subgroup.wgsl) or a workgroup-memory tree
    /// (interpolate.wgsl).
    Table { subgroups: bool },
}

impl InterpolateStrategy {
    pub fn table_shader(subgroups: bool) -> &'static str {
        if subgroups {
            "spread/interpolate_subgroup.wgsl"
        } else {
            "spread/interpolate.wgsl"
        }
    }
}

/// Supports covering a cell, on average (particles per cell x support^3), from which
/// `tiles: auto` spreads tile by tile: the tile kernel's cost per tile (a few rounds of
/// dependent loads, barriers, the flush of the padded tile) pays off where every cell
/// takes many adds. Measured on an H200 (BENCHMARKS.md): 51 (support 8 at 0.1 per cell)
/// 0.85 against 1.35 ns per particle; 17 (PSE's far field, support 6 at 0.08 per cell,
/// 3 components) 0.233 against about 0.2 ms; 3 (FCM at 1e-2) 0.69 against 0.60 ms.
const TILE_MIN_OVERLAP: f64 = 32.0;

/// Particles per cell below which spreading sorted input box by box stops paying (the
/// box of a run then holds few particles: one grid atomic per box cell is no saving; on
/// an H200 at 0.1 per cell the box kernel took 1.75 ns per particle against 1.54 for the
/// per-particle kernel, at 1 per cell 1.0 against 1.8).
const BOX_MIN_DENSITY: f64 = 0.5;

/// Smallest support spread box by box: the box's z sums run over all 16 box cells, so
/// small supports waste most of them (support 4 at 1 per cell: 0.69 ns per particle
/// against 0.32 for the per-particle kernel on an H200).
const BOX_MIN_SUPPORT: u32 = 6;

/// Particles per workgroup of the box kernels (shaders/spread/box.wgsl): about as many
/// as a 4^3 block of cells holds (a Morton order of cells visits such blocks whole), a
/// power of two from 4 to 64, so that a run's box stays within 16 cells per axis: 64 at
/// one particle per cell, 8 at 0.1.
pub fn box_run(count: u32, cells: u64) -> u32 {
    let per_block = (64.0 * count as f64 / cells.max(1) as f64).ceil() as u32;
    per_block.next_power_of_two().clamp(4, 64)
}

/// Lanes per particle of the lane kernels (interpgen.rs) on this adapter, or None.
fn lane_segment(gw: &GridWindow, caps: &DeviceCaps) -> Option<u32> {
    match caps.subgroups {
        Some((min, _)) if gw.lanes => interpgen::segment(gw.window.support(), min),
        _ => None,
    }
}

/// Whether sorted input of `n` particles goes box by box: dense enough, and a support
/// wide enough to pay and narrow enough to fit.
fn uses_boxes(gw: &GridWindow, sorted_input: bool, n: u32) -> bool {
    sorted_input
        && (BOX_MIN_SUPPORT..=super::boxgen::BMAX).contains(&gw.window.support())
        && n as f64 >= BOX_MIN_DENSITY * gw.cell_count() as f64
}

/// Whether spreading `n` particles may go tile by tile, as far as the params and sizes
/// tell; the adapter may still rule it out (`tile_launch`).
fn wants_tiles(gw: &GridWindow, tiles: TileMode, sorted_input: bool, n: u32) -> bool {
    n > 0
        && gw.dims() == 3
        && match tiles {
            TileMode::On => true,
            TileMode::Off => false,
            TileMode::Auto => {
                let overlap =
                    n as f64 * (gw.window.support() as f64).powi(3) / gw.cell_count() as f64;
                overlap >= TILE_MIN_OVERLAP && !uses_boxes(gw, sorted_input, n)
            }
        }
}

/// How the tile kernel runs on this adapter, or why it cannot: no subgroups as wide as
/// the support, or not even one component's padded tile fits in workgroup memory.
fn tile_launch(gw: &GridWindow, caps: &DeviceCaps) -> Result<TileLaunch, String> {
    let ns = gw.window.support();
    let seg = lane_segment(gw, caps).ok_or_else(|| {
        format!(
            "needs subgroups at least as wide as the support ({ns} cells; this adapter's: {})",
            match caps.subgroups {
                Some((min, _)) => format!("{min} lanes"),
                None => "none".into(),
            }
        )
    })?;
    let memory = caps.max_workgroup_storage;
    let min_subgroup = caps.subgroups.map_or(1, |(min, _)| min);
    let bytes = |c| tilegen::workgroup_bytes(ns, c, min_subgroup);
    let per_dispatch = (1..=super::CHUNK_COMPS)
        .take_while(|&c| bytes(c) <= memory)
        .last()
        .ok_or_else(|| {
            format!(
                "needs {} bytes of workgroup memory for support {ns}; this adapter has {memory}",
                bytes(1)
            )
        })?;
    let tiles = tilegen::tiles_per_axis(&gw.cells).iter().product();
    Ok(TileLaunch {
        per_dispatch,
        seg,
        min_subgroup,
        sort: bin_sort::plan(scan::Variant::Auto, tiles, caps)?,
    })
}

/// `spread`'s decision for `n` particles of `comps` components.
pub fn spread(
    gw: &GridWindow,
    tiles: TileMode,
    sorted_input: bool,
    variant: Variant,
    n: u32,
    comps: u32,
    caps: &DeviceCaps,
) -> Choice<SpreadPlan> {
    let add = match variant {
        // Deterministic runs take fixed-point adds whatever the variant asks for: both
        // float paths add in the order the threads run.
        _ if caps.deterministic => match fixed::weight_exponent(gw, n) {
            Ok(exp) => Add::FixedPoint { exp },
            Err(why) => return Choice(Err(why)),
        },
        Variant::Atomic if !caps.f32_atomics => {
            return Choice(Err("variant \"atomic\" needs float atomics (SHADER_FLOAT32_ATOMIC), which this adapter lacks; use \"portable\" or \"auto\"".into()));
        }
        Variant::Portable => Add::CompareAndSwap,
        _ if caps.f32_atomics => Add::FloatAtomic,
        _ => Add::CompareAndSwap,
    };
    let chunks = gw.chunks(n, comps);
    if wants_tiles(gw, tiles, sorted_input, n) {
        match tile_launch(gw, caps) {
            Ok(launch) => {
                return Choice(Ok(SpreadPlan {
                    strategy: SpreadStrategy::Tiles(launch),
                    add,
                    chunks,
                }));
            }
            Err(why) if tiles == TileMode::On => {
                return Choice(Err(format!(
                    "spread: tiles \"on\" {why}; use tiles \"auto\" or \"off\""
                )));
            }
            Err(_) => {}
        }
    }
    let strategy = if uses_boxes(gw, sorted_input, n) {
        SpreadStrategy::Boxes {
            run: box_run(n, gw.cell_count() as u64),
        }
    } else if let Some(seg) = lane_segment(gw, caps) {
        SpreadStrategy::Lanes { seg }
    } else {
        SpreadStrategy::Table
    };
    Choice(Ok(SpreadPlan {
        strategy,
        add,
        chunks,
    }))
}

/// `interpolate`'s decision for `n` particles of `comps` components.
pub fn interpolate(
    gw: &GridWindow,
    variant: Variant,
    n: u32,
    comps: u32,
    caps: &DeviceCaps,
) -> InterpolatePlan {
    // "portable" forces the workgroup-memory tree: no lanes, no shuffles.
    let portable = variant == Variant::Portable;
    let strategy = match lane_segment(gw, caps).filter(|_| !portable) {
        Some(seg) => InterpolateStrategy::Lanes { seg },
        None => InterpolateStrategy::Table {
            subgroups: caps.subgroups.is_some() && !portable,
        },
    };
    InterpolatePlan {
        strategy,
        chunks: gw.chunks(n, comps),
    }
}

fn order(chunks: u32) -> String {
    if chunks == 1 {
        "particles in input order".into()
    } else {
        format!("particles in {chunks} interleaved runs")
    }
}

impl fmt::Display for SpreadPlan {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let p = self;
        let add = match p.add {
            Add::FloatAtomic => "float atomic adds".to_string(),
            Add::CompareAndSwap => "compare-and-swap adds".to_string(),
            Add::FixedPoint { exp } => format!(
                "64-bit fixed-point adds (deterministic; unit 2^(e + {exp} - 60) for the largest |value| 2^e)"
            ),
        };
        match p.strategy {
            SpreadStrategy::Tiles(t) => write!(
                f,
                "strategy: tiles (8^3 cells each, {} component{} a dispatch, {} lanes a particle), {add}",
                t.per_dispatch,
                if t.per_dispatch == 1 { "" } else { "s" },
                t.seg
            ),
            SpreadStrategy::Boxes { run } => write!(
                f,
                "strategy: boxes (sorted input, runs of {run} particles), {add}"
            ),
            SpreadStrategy::Lanes { seg } => write!(
                f,
                "strategy: lanes ({seg} a particle, {}), {add}",
                order(p.chunks)
            ),
            SpreadStrategy::Table => {
                write!(f, "strategy: workgroup table ({}), {add}", order(p.chunks))
            }
        }
    }
}

impl fmt::Display for InterpolatePlan {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.strategy {
            InterpolateStrategy::Lanes { seg } => write!(
                f,
                "strategy: lanes ({seg} a particle, {})",
                order(self.chunks)
            ),
            InterpolateStrategy::Table { subgroups } => write!(
                f,
                "strategy: workgroup table ({}, {})",
                if subgroups {
                    "subgroup reduction"
                } else {
                    "workgroup-memory reduction"
                },
                order(self.chunks)
            ),
        }
    }
}
