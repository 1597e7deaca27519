//! FFT plans as data. A [`Recipe`] says everything a transform does on a device, pass by
//! pass: axis, radix sequence (a mixed-radix Stockham autosort), how lines are read and
//! written, threads per line, lines per workgroup, workgroup memory and twiddle tables
//! (computed here in f64). Recipes are memoised by shape, transform, axes, folding and
//! the device limits that shape them; kernels are generated from them afterwards
//! (`codegen.rs`), so `mesoflow inspect` prints exactly what will run.
//!
//! Design (after VkFFT): each pass reads every line once from global memory and writes it
//! once. A line lives in registers (E values per thread) during a radix stage and goes
//! through workgroup memory between stages. Strided axes (y, z) are done without
//! transposes: a workgroup takes a tile of consecutive lines, which are neighbours in x,
//! so global accesses stay coalesced.

use std::collections::HashMap;
use std::f64::consts::PI;
use std::fmt::Write;
use std::sync::{Arc, Mutex, OnceLock};

use crate::gpu::DeviceCaps;

/// Longest transform length along one axis. A line lives in one workgroup's memory
/// (4096 complex f32 = 32 KiB, what lavapipe offers; NVIDIA offers 48 KiB); longer lines
/// would need a multi-pass (four-step) scheme that is not implemented.
pub const MAX_LENGTH: u32 = 4096;

/// The most cells a host planner may put in one grid (all axes together): 2^30 (1024^3),
/// 8 GiB as a complex f32 grid, more than one buffer of most adapters holds.
pub const MAX_GRID_CELLS: f64 = (1u64 << 30) as f64;

/// A planner's cells per axis, checked before the float is converted: a count outside
/// 1..=[`MAX_LENGTH`] (1e30, infinity or NaN from a huge box or a tiny radius) is an
/// error naming `what` and the limit, never a saturated u32.
pub fn cells_per_axis(what: &str, cells: f64) -> Result<u32, String> {
    if cells.is_finite() && (1.0..=MAX_LENGTH as f64).contains(&cells) {
        Ok(cells as u32)
    } else {
        Err(format!(
            "{what} needs {cells} cells along an axis; an FFT axis takes 1 to {MAX_LENGTH} (MAX_LENGTH)"
        ))
    }
}

/// The cells of a planner's grid, checked against [`MAX_GRID_CELLS`].
pub fn checked_grid(what: &str, cells: Vec<u32>) -> Result<Vec<u32>, String> {
    let total: f64 = cells.iter().map(|&n| n as f64).product();
    if total > MAX_GRID_CELLS {
        return Err(format!(
            "{what} would be a grid of {cells:?} = {total} cells, more than the {MAX_GRID_CELLS} (MAX_GRID_CELLS) a grid may have"
        ));
    }
    Ok(cells)
}

/// Radices the kernels have butterflies for.
pub const RADICES: [u32; 6] = [2, 3, 4, 5, 7, 8];

/// Whether `n`'s prime factors are all in {2, 3, 5, 7} (1 is friendly, 0 is not).
pub fn is_friendly(n: u32) -> bool {
    if n == 0 {
        return false;
    }
    let mut m = n;
    for p in [2, 3, 5, 7] {
        while m.is_multiple_of(p) {
            m /= p;
        }
    }
    m == 1
}

/// The largest friendly u32: 2 * 3^6 * 5^2 * 7^6 = 4 288 306 050.
pub const LARGEST_FRIENDLY: u32 = 4_288_306_050;

/// The smallest size >= `n` whose prime factors are all 2, 3, 5 or 7: the grid size a
/// planner should pick for an FFT axis of at least `n` cells. Panics for `n` above
/// [`LARGEST_FRIENDLY`] (no u32 answers; FFT lines are far shorter anyway).
pub fn next_friendly(n: u32) -> u32 {
    assert!(
        n <= LARGEST_FRIENDLY,
        "no friendly FFT size >= {n} fits in a u32"
    );
    (n.max(1)..=LARGEST_FRIENDLY)
        .find(|&m| is_friendly(m))
        .unwrap_or(LARGEST_FRIENDLY)
}

/// The radix sequence of a friendly length: eights (then a four or two for the rest of
/// the power of two: 2^7 = 8*4*4 rather than 8*8*2, fewer wasted slots), then 7s, 5s, 3s.
pub fn radices(n: u32) -> Vec<u32> {
    debug_assert!(is_friendly(n));
    let mut m = n;
    let mut twos = 0;
    while m.is_multiple_of(2) {
        m /= 2;
        twos += 1;
    }
    let mut out = Vec::new();
    match twos % 3 {
        0 => out.extend(std::iter::repeat_n(8, twos / 3)),
        1 if twos >= 4 => {
            out.extend(std::iter::repeat_n(8, twos / 3 - 1));
            out.extend([4, 4]);
        }
        1 => out.push(2),
        _ => {
            out.extend(std::iter::repeat_n(8, twos / 3));
            out.push(4);
        }
    }
    for p in [7, 5, 3] {
        while m.is_multiple_of(p) {
            m /= p;
            out.push(p);
        }
    }
    out
}

/// The four transforms.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Kind {
    /// complex -> complex, e^{-2 pi i k x / n}, unnormalised.
    Forward,
    /// complex -> complex, e^{+2 pi i k x / n}, times 1/N.
    Inverse,
    /// real -> Hermitian half spectrum, as `Forward`.
    RealForward,
    /// Hermitian half spectrum -> real, as `Inverse`.
    RealInverse,
}

impl Kind {
    pub fn inverse(self) -> bool {
        matches!(self, Kind::Inverse | Kind::RealInverse)
    }

    pub fn name(self) -> &'static str {
        match self {
            Kind::Forward => "fft",
            Kind::Inverse => "ifft",
            Kind::RealForward => "rfft",
            Kind::RealInverse => "irfft",
        }
    }
}

/// Which buffer a pass reads or writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Buf {
    Input,
    Output,
    /// The node's scratch buffer (inverse real transforms over several axes: the input
    /// spectrum must stay intact and the real output is too small to hold a spectrum).
    Scratch,
}

/// How a pass turns its input line into the `n` complex values it transforms.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Load {
    /// Complex values (also a real line of even length read as n = len/2 pairs).
    Complex,
    /// Real values (odd real forward: imaginary parts are zero).
    Real,
    /// The n/2 + 1 values of a half spectrum, extended by Hermitian symmetry (odd real
    /// inverse).
    HalfMirror,
    /// The n + 1 values of a half spectrum of a real line of length 2n, folded into the
    /// n-point spectrum of the packed line x[2m] + i x[2m+1] (even real inverse).
    HalfPacked,
}

/// How a pass writes its transformed line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Store {
    /// Complex values (also a real line of even length written as pairs).
    Complex,
    /// The first n/2 + 1 values (odd real forward).
    Half,
    /// Real parts (odd real inverse).
    Real,
    /// The n + 1 values of the half spectrum of a real line of length 2n, unfolded from
    /// the n-point transform of its packed pairs (even real forward).
    HalfPacked,
}

/// How threads map onto the lines of a workgroup tile.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Layout {
    /// Lines are contiguous in memory (x): consecutive threads walk along a line.
    Contiguous,
    /// Lines are strided (y, z): consecutive threads take neighbouring lines, so each
    /// global access covers a run of consecutive x.
    Strided,
}

/// One pass over the grid along one axis.
#[derive(Clone, Debug, PartialEq)]
pub struct Pass {
    pub axis: usize,
    /// Transform length (complex points) of each line.
    pub n: u32,
    pub radices: Vec<u32>,
    pub inverse: bool,
    pub load: Load,
    pub store: Store,
    pub src: Buf,
    pub dst: Buf,
    /// Line length in the source (in its own elements: f32 for `Load::Real`, else
    /// complex) and the stride between consecutive points (the distance between
    /// neighbouring lines is 1 when this is > 1, and the line length when it is 1).
    pub in_len: u32,
    pub in_inner: u32,
    pub out_len: u32,
    pub out_inner: u32,
    /// Lines the tiles enumerate: every line of every component, or with a folded
    /// spectral node the lines of one component (a tile then handles all components, at
    /// once or in turn).
    pub lines: u32,
    /// Components per tile at once: 1, or all of them with a folded spectral node on a
    /// pass along x (its results are unfolded through workgroup memory).
    pub tile_comps: u32,
    /// Components a tile transforms one after another, keeping each one's results in
    /// registers: all of them with a folded spectral node on a pass along y or z (a
    /// thread then holds every component of its points), else 1. One component's lines
    /// in workgroup memory at a time, so the tile keeps 16 neighbouring lines.
    pub seq_comps: u32,
    /// Lines (per component) per workgroup.
    pub tile_lines: u32,
    pub threads_per_line: u32,
    /// Complex values per thread (registers) in the largest stage.
    pub registers: u32,
    pub layout: Layout,
    /// Workgroup memory in complex values (0: the pass needs none).
    pub shared: u32,
    /// Pad the contiguous layout (one slot per 16) against bank conflicts.
    pub padded: bool,
    /// Factor on the results (1/N in the last pass of an inverse transform).
    pub scale: f64,
    /// Workgroups in all.
    pub groups: u32,
    /// A spectral node's function is applied to the results (the forward transform's
    /// last pass).
    pub spectral: bool,
    /// After the spectral node, the lines are transformed back (the first pass of the
    /// inverse transform that reads the spectral node's output, run here instead).
    pub inverse_after: bool,
}

impl Pass {
    pub fn threads(&self) -> u32 {
        self.tile_comps * self.tile_lines * self.threads_per_line
    }

    /// Values a workgroup line keeps in workgroup memory.
    pub fn shared_line(&self) -> u32 {
        if self.load == Load::HalfPacked {
            self.n + 1
        } else {
            self.n
        }
    }

    /// Whether the results go through workgroup memory before the global write (to
    /// combine values of other threads or components).
    pub fn store_via_shared(&self) -> bool {
        self.store == Store::HalfPacked || self.spectral && !self.spectral_in_registers()
    }

    /// The folded spectral node is applied where the last butterflies leave the results,
    /// in registers (complex lines along y or z, components in turn), rather than after
    /// gathering them in workgroup memory (along x, where real spectra are unfolded).
    pub fn spectral_in_registers(&self) -> bool {
        self.spectral && in_registers(self.layout, self.store)
    }

    /// Components of the grid the pass transforms per line position.
    pub fn comps_per_line(&self) -> u32 {
        self.tile_comps * self.seq_comps
    }

    /// Output values per line.
    pub fn out_count(&self) -> u32 {
        match self.store {
            Store::HalfPacked => self.n + 1,
            Store::Half => self.n / 2 + 1,
            Store::Complex | Store::Real => self.n,
        }
    }

    /// (radix, points before this stage `Ns`) per stage.
    pub fn stages(&self) -> Vec<(u32, u32)> {
        let mut ns = 1;
        self.radices
            .iter()
            .map(|&r| {
                let s = (r, ns);
                ns *= r;
                s
            })
            .collect()
    }

    /// Offsets of each stage's twiddles in the table (stage 0 needs none), and of the
    /// real-transform table after them.
    pub fn twiddle_offsets(&self) -> (Vec<u32>, u32) {
        let mut off = 0;
        let mut offs = Vec::new();
        for (r, ns) in self.stages() {
            offs.push(off);
            if ns > 1 {
                off += ns * (r - 1);
            }
        }
        (offs, off)
    }

    /// The twiddle table, computed in f64 and rounded once: per stage (radix R after Ns
    /// points) w^(k r) for k < Ns, 1 <= r < R, w = e^(-+2 pi i / (Ns R)); then for
    /// the packed real transforms e^(-+2 pi i q / 2n) for q <= n.
    pub fn twiddles(&self) -> Vec<[f32; 2]> {
        let sign = if self.inverse { 1.0 } else { -1.0 };
        let root = |num: u64, den: u64| {
            let a = sign * 2.0 * PI * num as f64 / den as f64;
            [a.cos() as f32, a.sin() as f32]
        };
        let mut t = Vec::new();
        for (r, ns) in self.stages() {
            if ns > 1 {
                for k in 0..ns {
                    for j in 1..r {
                        t.push(root((k * j) as u64, (ns * r) as u64));
                    }
                }
            }
        }
        if self.load == Load::HalfPacked || self.store == Store::HalfPacked {
            for q in 0..=self.n {
                t.push(root(q as u64, 2 * self.n as u64));
            }
        }
        t
    }
}

/// A whole transform.
#[derive(Clone, Debug, PartialEq)]
pub struct Recipe {
    pub kind: Kind,
    /// Real-space dims (nx, ny, nz).
    pub dims: [u32; 3],
    pub comps: u32,
    pub axes: [bool; 3],
    pub passes: Vec<Pass>,
    /// Bytes of scratch the node asks the planner for.
    pub scratch: u64,
}

impl Recipe {
    /// Dims of the spectrum as stored: the half spectrum for real transforms.
    pub fn spectrum_dims(&self) -> [u32; 3] {
        match self.kind {
            Kind::RealForward | Kind::RealInverse => crate::value::half_dims(self.dims),
            _ => self.dims,
        }
    }

    /// One line per decision, for `mesoflow inspect`.
    pub fn describe(&self) -> Vec<String> {
        let axis = ["x", "y", "z"];
        let mut out = Vec::new();
        for (i, p) in self.passes.iter().enumerate() {
            let rad: Vec<String> = p.radices.iter().map(|r| r.to_string()).collect();
            let what = match (p.load, p.store) {
                (Load::Real, _) => format!("real -> half spectrum, {}-point", p.n),
                (_, Store::HalfPacked) => format!(
                    "real -> half spectrum, {}-point on packed pairs + unfold",
                    p.n
                ),
                (Load::HalfMirror, _) => format!("half spectrum -> real, {}-point", p.n),
                (Load::HalfPacked, _) => format!(
                    "half spectrum -> real, fold + {}-point on packed pairs",
                    p.n
                ),
                _ => format!("{}-point", p.n),
            };
            let mut line = format!(
                "pass {}: {} {} {}, radices {}, {} thread{}/line x {} line{}{} = {} threads, {} registers, {} layout",
                i + 1,
                axis[p.axis],
                if p.inverse { "inverse" } else { "forward" },
                what,
                if rad.is_empty() {
                    "none".into()
                } else {
                    rad.join("x")
                },
                p.threads_per_line,
                if p.threads_per_line == 1 { "" } else { "s" },
                p.tile_lines,
                if p.tile_lines == 1 { "" } else { "s" },
                if p.tile_comps > 1 {
                    format!(" x {} comps", p.tile_comps)
                } else if p.seq_comps > 1 {
                    format!(" x {} comps in turn", p.seq_comps)
                } else {
                    String::new()
                },
                p.threads(),
                p.registers,
                match p.layout {
                    Layout::Contiguous => "contiguous",
                    Layout::Strided => "strided",
                },
            );
            write!(
                line,
                ", {} B workgroup memory{}, {} twiddles (f64 -> f32), {} workgroups, {:?} -> {:?}",
                8 * p.shared,
                if p.padded { " (padded)" } else { "" },
                p.twiddles().len(),
                p.groups,
                p.src,
                p.dst
            )
            .expect("writing to a String");
            if p.scale != 1.0 {
                write!(line, ", scale 1/{}", (1.0 / p.scale).round()).expect("String");
            }
            if p.spectral {
                line.push_str(", applies the folded spectral node");
            }
            if p.inverse_after {
                line.push_str(
                    ", then transforms the lines back (the inverse transform's first pass)",
                );
            }
            out.push(line);
        }
        if self.scratch > 0 {
            out.push(format!("scratch {} bytes", self.scratch));
        }
        out
    }
}

/// The device limits a recipe depends on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Limits {
    pub shared_bytes: u32,
    pub threads: u32,
    pub groups_per_dim: u32,
}

impl Limits {
    pub fn of(caps: &DeviceCaps) -> Self {
        Limits {
            shared_bytes: caps.max_workgroup_storage,
            // Beyond 1024 the workgroup's x size could exceed the device's cap.
            threads: caps.max_invocations.min(1024),
            groups_per_dim: caps.max_workgroups_per_dim,
        }
    }
}

/// What identifies a recipe.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Key {
    pub kind: Kind,
    pub dims: [u32; 3],
    pub comps: u32,
    pub axes: [bool; 3],
    /// A spectral node is folded into the forward transform's last pass.
    pub spectral: bool,
    /// ... and that pass also runs the first pass of the inverse transform after it.
    pub inverse_after: bool,
    pub limits: Limits,
}

/// The recipe for `key`, built once per process.
pub fn recipe(key: &Key) -> Result<Arc<Recipe>, String> {
    type Memo = Mutex<HashMap<Key, Result<Arc<Recipe>, String>>>;
    static MEMO: OnceLock<Memo> = OnceLock::new();
    let memo = MEMO.get_or_init(Default::default);
    if let Some(r) = memo.lock().map_err(|_| "FFT plan cache poisoned")?.get(key) {
        return r.clone();
    }
    let r = build(key).map(Arc::new);
    memo.lock()
        .map_err(|_| "FFT plan cache poisoned")?
        .insert(*key, r.clone());
    r
}

/// Axes that get a pass, in order.
fn active_axes(key: &Key) -> Vec<usize> {
    (0..3).filter(|&a| key.axes[a] && key.dims[a] > 1).collect()
}

fn build(key: &Key) -> Result<Recipe, String> {
    let d = key.dims;
    let comps = key.comps;
    let inverse = key.kind.inverse();
    let real = matches!(key.kind, Kind::RealForward | Kind::RealInverse);
    let stored = if real { crate::value::half_dims(d) } else { d };
    let cells = |dims: [u32; 3]| dims[0] as u64 * dims[1] as u64 * dims[2] as u64;
    // Complex transforms along y and z, over the stored spectrum.
    let c2c = |axis: usize| -> PassShape {
        let inner = stored[..axis].iter().product::<u32>();
        PassShape {
            axis,
            n: d[axis],
            load: Load::Complex,
            store: Store::Complex,
            in_len: d[axis],
            in_inner: inner,
            out_len: d[axis],
            out_inner: inner,
            lines_per_comp: (cells(stored) / d[axis] as u64) as u32,
        }
    };
    let mut shapes: Vec<(PassShape, Buf, Buf)> = Vec::new();
    let mut scratch = 0;
    let axes = active_axes(key);
    let n_total: u64 = axes.iter().map(|&a| d[a] as u64).product();
    match key.kind {
        Kind::Forward | Kind::Inverse => {
            // All-trivial axes still need one pass to copy input to output.
            let list = if axes.is_empty() { vec![0] } else { axes };
            for (i, &a) in list.iter().enumerate() {
                let src = if i == 0 { Buf::Input } else { Buf::Output };
                shapes.push((c2c(a), src, Buf::Output));
            }
        }
        Kind::RealForward => {
            shapes.push((real_x(d, false), Buf::Input, Buf::Output));
            for &a in axes.iter().filter(|&&a| a > 0) {
                shapes.push((c2c(a), Buf::Output, Buf::Output));
            }
        }
        Kind::RealInverse => {
            let others: Vec<usize> = axes.iter().copied().filter(|&a| a > 0).rev().collect();
            for (i, &a) in others.iter().enumerate() {
                let src = if i == 0 { Buf::Input } else { Buf::Scratch };
                shapes.push((c2c(a), src, Buf::Scratch));
            }
            let src = if others.is_empty() {
                Buf::Input
            } else {
                scratch = 8 * cells(stored) * comps as u64;
                Buf::Scratch
            };
            shapes.push((real_x(d, true), src, Buf::Output));
        }
    }
    let last = shapes.len() - 1;
    let mut passes = Vec::new();
    for (i, (shape, src, dst)) in shapes.into_iter().enumerate() {
        let scale = if inverse && i == last {
            1.0 / n_total as f64
        } else {
            1.0
        };
        let spectral = key.spectral && i == last && !inverse;
        let pass = tile(key, shape, src, dst, inverse, scale, spectral)?;
        if spectral && key.inverse_after && !pass.inverse_after {
            return Err(
                "the inverse transform's first pass folds only into a last pass along y or z"
                    .into(),
            );
        }
        passes.push(pass);
    }
    Ok(Recipe {
        kind: key.kind,
        dims: d,
        comps,
        axes: key.axes,
        passes,
        scratch,
    })
}

/// A pass before tiling.
struct PassShape {
    axis: usize,
    n: u32,
    load: Load,
    store: Store,
    in_len: u32,
    in_inner: u32,
    out_len: u32,
    out_inner: u32,
    lines_per_comp: u32,
}

/// The x pass of a real transform: even lengths transform n/2 packed pairs.
fn real_x(d: [u32; 3], inverse: bool) -> PassShape {
    let nx = d[0];
    let half = nx / 2 + 1;
    let even = nx.is_multiple_of(2);
    let n = if even { nx / 2 } else { nx };
    let (load, store, in_len, out_len) = match (inverse, even) {
        (false, true) => (Load::Complex, Store::HalfPacked, n, half),
        (false, false) => (Load::Real, Store::Half, nx, half),
        (true, true) => (Load::HalfPacked, Store::Complex, half, n),
        (true, false) => (Load::HalfMirror, Store::Real, half, nx),
    };
    PassShape {
        axis: 0,
        n,
        load,
        store,
        in_len,
        in_inner: 1,
        out_len,
        out_inner: 1,
        lines_per_comp: d[1] * d[2],
    }
}

/// Whether a spectral node folded into a pass of this shape is applied in registers
/// (see [`Pass::spectral_in_registers`]).
fn in_registers(layout: Layout, store: Store) -> bool {
    layout == Layout::Strided && store == Store::Complex
}

/// Largest power of two <= x (x >= 1).
fn floor_pow2(x: u32) -> u32 {
    1 << (31 - x.max(1).leading_zeros())
}

/// Workgroup memory in complex values for `lines` lines of `len` values.
fn shared_len(lines: u32, len: u32, layout: Layout, padded: bool) -> u32 {
    let f = lines * len;
    match (layout, padded) {
        (Layout::Contiguous, true) => f + (f >> 4) + 1,
        _ => f,
    }
}

/// Threads per line: the count that wastes fewest butterfly slots over the stages, with a
/// mild preference for 8 to 16 registers per thread (enough independent loads in flight,
/// few enough registers for several workgroups per multiprocessor), and at most
/// `max_regs` where that is possible (a pass holding every component's results).
fn threads_per_line(n: u32, radices: &[u32], max_threads: u32, max_regs: u32) -> (u32, u32) {
    if radices.is_empty() {
        return (1, 1);
    }
    let mut best = (f64::INFINITY, 1, 1);
    for t in 1..=n.min(max_threads) {
        let mut slots = 0u64;
        let mut regs = 0;
        for &r in radices {
            let per = (n / r).div_ceil(t);
            slots += (per * r * t) as u64;
            regs = regs.max(per * r);
        }
        let waste = slots as f64 / (radices.len() as u64 * n as u64) as f64;
        let cost = waste
            + 0.01 * regs.saturating_sub(16) as f64
            + 0.02 * 8u32.saturating_sub(regs).min(n.saturating_sub(regs)) as f64
            + if regs > 32 { 1.0 } else { 0.0 }
            + if regs > max_regs { 0.5 } else { 0.0 };
        if cost <= best.0 {
            best = (cost, t, regs);
        }
    }
    (best.1, best.2)
}

fn tile(
    key: &Key,
    s: PassShape,
    src: Buf,
    dst: Buf,
    inverse: bool,
    scale: f64,
    spectral: bool,
) -> Result<Pass, String> {
    let lim = key.limits;
    let radices = radices(s.n);
    let layout = if s.in_inner == 1 && s.out_inner == 1 {
        Layout::Contiguous
    } else {
        Layout::Strided
    };
    // Components in turn where results stay where the butterflies leave them (complex
    // lines along y, z); all at once where they are unfolded in workgroup memory.
    let in_turn = spectral && in_registers(layout, s.store);
    let (tile_comps, seq_comps) = match (spectral, in_turn) {
        (true, true) => (1, key.comps.max(1)),
        (true, false) => (key.comps.max(1), 1),
        _ => (1, 1),
    };
    // Components in turn keep every component's results in registers: fewer per thread.
    let max_regs = if in_turn {
        (24 / key.comps.max(1)).max(4)
    } else {
        32
    };
    let (threads, registers) =
        threads_per_line(s.n, &radices, (lim.threads / tile_comps).max(1), max_regs);
    let lines = if spectral {
        s.lines_per_comp
    } else {
        s.lines_per_comp * key.comps
    };
    let mut pass = Pass {
        axis: s.axis,
        n: s.n,
        radices,
        inverse,
        load: s.load,
        store: s.store,
        src,
        dst,
        in_len: s.in_len,
        in_inner: s.in_inner,
        out_len: s.out_len,
        out_inner: s.out_inner,
        lines,
        tile_comps,
        seq_comps,
        tile_lines: 1,
        threads_per_line: threads,
        registers,
        layout,
        shared: 0,
        padded: false,
        scale,
        groups: 0,
        spectral,
        inverse_after: in_turn && key.inverse_after,
    };
    // A pass that transforms its lines back needs workgroup memory even for one stage.
    let needs_shared = pass.radices.len() > 1
        || pass.store_via_shared()
        || pass.load == Load::HalfPacked
        || pass.inverse_after;
    // Strided tiles want 16+ neighbouring lines (128-byte rows); contiguous ones about
    // 256 threads.
    let per_line = tile_comps * threads;
    let cap = match layout {
        Layout::Contiguous => floor_pow2((256 / per_line).max(1)),
        Layout::Strided => floor_pow2((256 / per_line).max(16)).min(64),
    }
    .min(floor_pow2(lines.max(1)).saturating_mul(2))
    .max(1);
    let mut bs = cap;
    let chosen = loop {
        if tile_comps * bs * threads <= lim.threads {
            let lines_in_tile = tile_comps * bs;
            if !needs_shared {
                break Some((bs, false, 0));
            }
            let fit = [layout == Layout::Contiguous, false]
                .into_iter()
                .find_map(|padded| {
                    let len = shared_len(lines_in_tile, pass.shared_line(), layout, padded);
                    (8 * len <= lim.shared_bytes).then_some((bs, padded, len))
                });
            if fit.is_some() {
                break fit;
            }
        }
        if bs == 1 {
            break None;
        }
        bs /= 2;
    };
    let Some((bs, padded, shared)) = chosen else {
        return Err(format!(
            "{} {}-point line{} along {} need{} {} bytes of workgroup memory and {} threads; this device has {} bytes and {} threads per workgroup",
            tile_comps,
            s.n,
            if tile_comps > 1 {
                "s (one per component)"
            } else {
                ""
            },
            ["x", "y", "z"][s.axis],
            if tile_comps > 1 { "" } else { "s" },
            8 * tile_comps * pass.shared_line(),
            tile_comps * threads,
            lim.shared_bytes,
            lim.threads
        ));
    };
    pass.tile_lines = bs;
    pass.padded = padded;
    pass.shared = shared;
    let groups = lines.div_ceil(bs);
    if groups as u64 > lim.groups_per_dim as u64 * lim.groups_per_dim as u64 {
        return Err(format!(
            "{groups} workgroups exceed what one dispatch can hold on this device"
        ));
    }
    pass.groups = groups;
    Ok(pass)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn friendly_sizes() {
        assert!(is_friendly(1) && is_friendly(375) && is_friendly(189) && is_friendly(432));
        assert!(!is_friendly(0) && !is_friendly(11) && !is_friendly(97));
        assert_eq!(next_friendly(97), 98);
        assert_eq!(next_friendly(0), 1);
        assert_eq!(next_friendly(121), 125);
        assert_eq!(next_friendly(256), 256);
        assert!(is_friendly(LARGEST_FRIENDLY));
        assert_eq!(next_friendly(LARGEST_FRIENDLY - 1), LARGEST_FRIENDLY);
    }

    #[test]
    fn radix_sequences_multiply_back() {
        for n in 1..=4096 {
            if is_friendly(n) {
                let r = radices(n);
                assert_eq!(r.iter().product::<u32>(), n, "{n}: {r:?}");
                assert!(r.iter().all(|x| RADICES.contains(x)), "{n}: {r:?}");
            }
        }
        assert_eq!(radices(128), vec![8, 4, 4]);
        assert_eq!(radices(256), vec![8, 8, 4]);
        assert_eq!(radices(2), vec![2]);
        assert_eq!(radices(16), vec![4, 4]);
    }
}
