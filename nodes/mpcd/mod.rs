//! Multi-particle collision dynamics (MPCD): a particle solvent that streams ballistically
//! and exchanges momentum inside the cells of a randomly shifted grid (stochastic rotation
//! dynamics, SRD; or Ihle's biased collisions between cell pairs, MPCD-BC, with `rule`
//! `biased`). One time step of `graphs/mpcd.json` (2D: `graphs/mpcd2d.json`) is
//!
//! `mpcd_stream` (x += v dt under the body force, walls, periodic wrap) ->
//! `mpcd_bin` (cell of each particle in this step's shifted grid; per cell the count,
//! sum v and, for a thermostat, sum |v|^2 as exact 64-bit fixed-point sums by native
//! 64-bit atomics, or pairs of u32 atomics where the adapter lacks them) ->
//! `mpcd_collide` (v <- u_c + S R (v - u_c) per particle, the cell's rotation and thermostat
//! factor recomputed from Philox by every particle of the cell, virtual particles in
//! wall-cut cells) -> `mpcd_measure` (observables accumulated after the warm-up) ->
//! `mpcd_average`; `mpcd_init` draws the initial state. The graph runs the first two as
//! one kernel, `mpcd_stream_bin` (the same arithmetic, without the binning's second read
//! of the particles).
//!
//! A solute (`graphs/mpcd_solute.json`): a second species of mass M streams with its own
//! `mpcd_stream`; `mpcd_bin_solute` adds it to `mpcd_bin`'s cell sums weighted by M / m
//! (and appends the solute count per cell and M / m), so that `mpcd_collide` uses the
//! mass-weighted means u = (m sum v + M sum V) / (m n + M n_s); a second `mpcd_collide`
//! with the same params on the solute's velocities and cells applies the same rotation of
//! each cell (V' = u + S R (V - u)). The cell thermostat S counts the relative energy and
//! degrees of freedom of both species; virtual particles in wall-cut cells add to the
//! cell's mass. With MPCD-BC (`mpcd_bin_solute` given the same `rule`: the grid shift of
//! width 2a) the cells' masses in units of m stand for the counts n1, n2 of the acceptance
//! tanh(A du n1 n2) and the pair mean (Ihle's rule is defined for one species: with M = m,
//! as the solid spheres' virtual particles, it is that rule; other masses generalise it
//! by mass, conserving momentum and energy).
//!
//! Conventions: the box is centred at the origin, particle arrays are (N, d) with d = 2 or 3
//! (the length of `box`), the body force acts along x, and walls (`plates`) are
//! perpendicular to the last axis (z in 3D, y in 2D) at +-L/2. Cells are linear
//! (x fastest); the walled axis has L/a + 1 layers (the grid shift cuts the first and last).
//!
//! Accuracy: cell sums are integers (velocity in units of v_th / 2^24, squared speed in
//! units of v_th^2 / 2^16, v_th = sqrt(kT/m)), so they are exact and independent of the
//! order of the atomics; velocities stay f32, so each collision conserves a cell's momentum
//! and energy up to the f32 rounding of its particles' new velocities (a random walk, no
//! drift: the 3D rotation is two reflections, norm-preserving whatever the f32 axis).
//! Velocities must stay below 128 v_th (the range of the fixed point).

mod collide;
mod init;
mod measure;
mod solute;
mod sphere_coupling;
mod sphere_profile;
mod spheres;
mod stream;
mod stream_bin;
mod virial;

use crate::node::{ParamKind, ParamSpec, Params, PortError, PortSpec, Registry, RowError};
use crate::value::{HostArray, HostData, PortType, ValueType};

pub use collide::srd_rotation;
pub use sphere_coupling::{shell_count, shell_inner};
pub use spheres::{SPHERE_WORDS, impulse_of};

/// Words per cell of the cell sums' first block: the count and sum v as 64-bit (lo, hi)
/// pairs, [0, 1] count (hi zero) and [SUM_V + 2a, SUM_V + 2a + 1] sum v_a (v_z zero in 2D):
/// 32 bytes, so that a cell's sums are one aligned memory sector and one 64-bit atomic each.
pub const CELL_WORDS: u32 = 8;

/// The first word of the pair of sum v_x within a cell's block.
pub const SUM_V: usize = 2;

/// Where things are in the cell sums of `mpcd_bin` (and `mpcd_bin_solute`): `CELL_WORDS`
/// per cell; then, when a thermostat needs them, the pair of sum |v|^2 per cell; then,
/// with a solute, the solute count per cell and the f32 bits of M / m.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SumsLayout {
    pub ncells: u32,
    pub energy: bool,
    pub solute: bool,
}

/// One cell's exact sums as integers: the count, sum v_x, v_y, v_z and sum |v|^2 (zero
/// where the layout has no energy sums), in the fixed-point units of the kernels.
pub type CellSums = [i64; 5];

impl SumsLayout {
    /// The four layouts for `ncells` cells: plain, with energy sums, with a solute, both.
    pub fn all(ncells: u32) -> [SumsLayout; 4] {
        [(false, false), (true, false), (false, true), (true, true)].map(|(energy, solute)| {
            SumsLayout {
                ncells,
                energy,
                solute,
            }
        })
    }

    pub fn words(&self) -> u64 {
        let n = self.ncells as u64;
        n * CELL_WORDS as u64
            + if self.energy { 2 * n } else { 0 }
            + if self.solute { n + 1 } else { 0 }
    }

    /// First word of cell c's block.
    pub fn cell(&self, c: usize) -> usize {
        c * CELL_WORDS as usize
    }

    /// Cell c's block (count and sum v) of cell sums in any layout: the blocks come first.
    pub fn block(sums: &[f64], c: usize) -> &[f64] {
        &sums[c * CELL_WORDS as usize..(c + 1) * CELL_WORDS as usize]
    }

    /// Cell c's sums read from `sums` words (this layout's energy sums where it has them).
    pub fn read(&self, sums: &[f64], c: usize) -> CellSums {
        let b = Self::block(sums, c);
        let mut e = [value_of(b[0], b[1]), 0, 0, 0, 0];
        for j in 0..3 {
            e[1 + j] = value_of(b[SUM_V + 2 * j], b[SUM_V + 1 + 2 * j]);
        }
        if self.energy {
            let k = self.energy_word(c);
            e[4] = value_of(sums[k], sums[k + 1]);
        }
        e
    }

    /// Writes cell c's sums into `out` (the energy sums where this layout has them).
    pub fn write(&self, out: &mut [f64], c: usize, cs: &CellSums) {
        let b = self.cell(c);
        out[b..b + 2].copy_from_slice(&words_of(cs[0]));
        for j in 0..3 {
            out[b + SUM_V + 2 * j..b + SUM_V + 2 + 2 * j].copy_from_slice(&words_of(cs[1 + j]));
        }
        if self.energy {
            let k = self.energy_word(c);
            out[k..k + 2].copy_from_slice(&words_of(cs[4]));
        }
    }

    /// The low word of cell c's sum |v|^2 (with `energy`).
    pub fn energy_word(&self, c: usize) -> usize {
        self.ncells as usize * CELL_WORDS as usize + 2 * c
    }

    /// The solute count of cell c (with `solute`); the M / m word follows the last one.
    pub fn solute_word(&self, c: usize) -> usize {
        self.ncells as usize * (CELL_WORDS as usize + if self.energy { 2 } else { 0 }) + c
    }

    /// The layout a buffer of `words` words has for `ncells` cells, if any.
    pub fn of_words(ncells: u32, words: u64) -> Option<SumsLayout> {
        Self::all(ncells).into_iter().find(|l| l.words() == words)
    }

    /// The layout of the cell sums at port `sums` of `node` for `ncells` cells, or the
    /// error naming the layouts it could have had.
    pub fn of_port(
        ncells: u32,
        sums: Option<ValueType>,
        node: &str,
    ) -> Result<SumsLayout, PortError> {
        let layout = match sums {
            Some(ValueType::Indices { n }) => Self::of_words(ncells, n as u64),
            _ => None,
        };
        layout.ok_or_else(|| {
            PortError::new(
                "sums",
                format!(
                    "expected the cell sums of mpcd_bin for {ncells} cells: {}; got {sums:?}; do mpcd_bin and {node} have the same box, cell and walls?",
                    Self::describe(ncells)
                ),
            )
        })
    }

    /// The word counts of the four layouts, for error messages.
    pub fn describe(ncells: u32) -> String {
        let [plain, energy, solute, both] = Self::all(ncells).map(|l| l.words());
        format!(
            "{plain} words ({ncells} cells x {CELL_WORDS}), {energy} with the energy sums of a thermostat, {solute} / {both} with a solute"
        )
    }
}

/// The parameter block of every MPCD kernel (`struct Mpcd` of shaders/mpcd/common.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct Uniform {
    pub box_len: [f32; 4],
    pub cells: [u32; 4],
    pub n: u32,
    pub ncells: u32,
    pub walls: u32,
    pub wall_slip: u32,
    pub seed_lo: u32,
    pub seed_hi: u32,
    pub stream: u32,
    pub shift: u32,
    pub cell: f32,
    pub dt: f32,
    pub mass: f32,
    pub kt: f32,
    pub cos_a: f32,
    pub sin_a: f32,
    pub density: f32,
    pub thermostat: u32,
    pub accel: f32,
    pub force_shape: u32,
    pub mc_c: f32,
    pub ghosts: u32,
    pub fix_v: f32,
    pub fix_e: f32,
    pub bins: u32,
    pub warmup: u32,
    pub every: u32,
    pub rule: u32,
    pub accept_a: f32,
    pub half_cos: f32,
    pub half_sin: f32,
    /// 1: the cell sums carry a solute (`mpcd_bin_solute`'s layout).
    pub solute: u32,
    /// Solute mass over solvent mass M / m.
    pub ratio: f32,
    /// 1: the cell sums carry sum |v|^2 per cell (a thermostat needs them).
    pub energy: u32,
    /// The stream of mpcd_bin's grid shift (mpcd_collide, MPCD-BC with plates: which
    /// layers the plates cut).
    pub shift_stream: u32,
    pub pad: [u32; 3],
}

/// Box, cells and walls, shared by the MPCD kinds.
#[derive(Clone, Debug)]
pub(crate) struct Geometry {
    pub lengths: Vec<f64>,
    pub cell: f64,
    pub walls: bool,
    /// Cells per axis (the walled axis: L/a + 1 layers, L/a + 2 for MPCD-BC).
    pub cells: Vec<u32>,
    /// MPCD-BC's grid (a kind whose `rule` is biased): the shift spans 2a.
    pub biased: bool,
}

impl Geometry {
    pub fn from_params(p: &Params) -> Result<Self, String> {
        let lengths = p.numbers("box").to_vec();
        let cell = p.number("cell");
        let walls = p.text("walls") == "plates";
        // MPCD-BC's grid shift spans 2a: one layer more on the walled axis (kinds with a
        // `rule`).
        let biased = u32::from(
            matches!(p.get("rule"), Some(crate::expr::ParamValue::Text(t)) if t == "biased"),
        );
        if !(2..=3).contains(&lengths.len()) {
            return Err(format!("`box` needs 2 or 3 lengths, got {}", lengths.len()));
        }
        let mut cells = Vec::new();
        for (a, &l) in lengths.iter().enumerate() {
            let r = l / cell;
            if (r - r.round()).abs() > 1e-9 * r.max(1.0) || r.round() < 1.0 {
                return Err(format!(
                    "box length {l} along axis {a} is not a whole number of cells of size {cell}"
                ));
            }
            if r.round() > MAX_AXIS_CELLS {
                return Err(format!(
                    "box length {l} along axis {a} is {} cells of size {cell}, more than {MAX_AXIS_CELLS}: f32 positions at the box edge would not resolve 1/256 of a cell; use larger cells or a smaller box",
                    r.round()
                ));
            }
            cells
                .push(r.round() as u32 + (1 + biased) * u32::from(walls && a == lengths.len() - 1));
        }
        let total: f64 = cells.iter().map(|&c| c as f64).product();
        if total * (CELL_WORDS as f64 + 3.0) + 1.0 > u32::MAX as f64 {
            return Err(format!(
                "{total} cells are too many (at most about 2^32 / {})",
                CELL_WORDS + 3
            ));
        }
        Ok(Geometry {
            lengths,
            cell,
            walls,
            cells,
            biased: biased == 1,
        })
    }

    pub fn dims(&self) -> usize {
        self.lengths.len()
    }

    pub fn ncells(&self) -> u32 {
        self.cells.iter().product()
    }

    /// The uniform with the geometry and the fixed-point scales of the kind's
    /// `temperature` and `mass` (`thermal_params`) filled in.
    pub(crate) fn thermal_uniform(&self, p: &Params) -> Uniform {
        let mut u = self.uniform();
        (u.fix_v, u.fix_e) = fixed_scales(p.number("temperature"), p.number("mass"));
        u
    }

    /// The uniform with the geometry filled in.
    pub fn uniform(&self) -> Uniform {
        let mut u = Uniform::default();
        for a in 0..self.dims() {
            u.box_len[a] = self.lengths[a] as f32;
            u.cells[a] = self.cells[a];
        }
        for a in self.dims()..4 {
            u.box_len[a] = 1.0;
            u.cells[a] = 1;
        }
        u.ncells = self.ncells();
        u.walls = u32::from(self.walls);
        u.cell = self.cell as f32;
        u.every = 1;
        u
    }

    /// Checks a particle array against the box; returns N.
    pub fn particles(&self, port: &str, t: Option<ValueType>) -> Result<u32, PortError> {
        match t {
            Some(ValueType::Particles { n, k }) if k as usize == self.dims() => Ok(n),
            Some(other) => Err(PortError::new(
                port,
                format!(
                    "is {other} but the box has {} axes (N x {} expected)",
                    self.dims(),
                    self.dims()
                ),
            )),
            None => Err(PortError::new(port, "is required")),
        }
    }

    /// Reference cell of a position for grid shift `s` (f64 twin of `cell_of`).
    pub fn cell_of(&self, x: &[f64], s: &[f64; 3]) -> u32 {
        let d = self.dims();
        let mut c = 0u64;
        for a in (0..d).rev() {
            let nc = self.cells[a] as i64;
            let l = self.lengths[a];
            let i = if self.walls && a == d - 1 {
                (((x[a]
                    + 0.5 * l
                    + s[a]
                    + if self.biased {
                        self.cell
                    } else {
                        0.5 * self.cell
                    })
                    / self.cell)
                    .floor() as i64)
                    .clamp(0, nc - 1)
            } else {
                (((x[a] + 0.5 * l + s[a]) / self.cell).floor() as i64).rem_euclid(nc)
            };
            c = c * nc as u64 + i as u64;
        }
        c as u32
    }

    /// Layer of a cell along the last axis.
    pub fn layer(&self, c: u32) -> u32 {
        let d = self.dims();
        let below: u32 = self.cells[..d - 1].iter().product();
        c / below
    }
}

/// How far from the box a given position on a periodic axis may be, in box lengths: the
/// kernels wrap it in f32, and an image farther out loses more than 2^-13 L of its place
/// to rounding (an f32 carries 24 bits).
pub const FAR_IMAGES: f64 = 1024.0;

/// The largest velocity component the fixed point of the cell sums carries, in units of
/// v_th: round(v 2^24 / v_th) must fit an i32.
pub const MAX_VELOCITY: f64 = 128.0;

/// What a per-particle MPCD port holds, for the host-side check of given data
/// ([`check_rows`]).
#[derive(Clone, Copy, Debug)]
pub(crate) enum Rows {
    /// Positions: finite, inside the plates on the walled axis, within [`FAR_IMAGES`] box
    /// lengths of the box on periodic ones.
    Positions,
    /// Velocities: finite; with `Some(v_th)` (a node that sums them in fixed point) each
    /// component below [`MAX_VELOCITY`] v_th in magnitude.
    Velocities(Option<f64>),
}

/// A number as messages print it: to 7 significant digits (1e-30 read from a file, not
/// 9.999999999999999e-31), plainly from 1e-4 to 1e6, else in exponent form.
pub(crate) fn num(x: f64) -> String {
    let rounded: f64 = format!("{x:.6e}").parse().unwrap_or(x);
    if rounded == 0.0 || (1e-4..1e6).contains(&rounded.abs()) {
        format!("{rounded}")
    } else {
        format!("{rounded:e}")
    }
}

/// The name of axis `a` in messages.
fn axis_name(a: usize) -> &'static str {
    ["x", "y", "z"][a]
}

/// Checks the rows of given per-particle data (N x d f32, as uploaded) against the
/// geometry: the first row refused, with the coordinate, its value and the bound. Data of
/// another type is left to planning, which refuses it.
pub(crate) fn check_rows(geo: &Geometry, rows: Rows, data: &HostArray) -> Result<(), RowError> {
    let d = geo.dims();
    let (ValueType::Particles { k, .. }, HostData::F32(values)) = (data.ty, &data.data) else {
        return Ok(());
    };
    if k as usize != d {
        return Ok(());
    }
    let walled = geo.walls.then_some(d - 1);
    for (row, r) in values.chunks_exact(d).enumerate() {
        for (a, &x) in r.iter().enumerate() {
            let name = match rows {
                Rows::Positions => axis_name(a).to_string(),
                Rows::Velocities(_) => format!("v_{}", axis_name(a)),
            };
            if !x.is_finite() {
                return Err(RowError::new(row, format!("{name} = {x} is not finite")));
            }
            let l = geo.lengths[a];
            let h = 0.5 * l;
            let x64 = x as f64;
            match rows {
                // As the kernels compare: with the f32 half length.
                Rows::Positions if walled == Some(a) => {
                    if x.abs() > 0.5 * l as f32 {
                        return Err(RowError::new(
                            row,
                            format!(
                                "{name} = {x} is outside the plates [{}, {}] (walls = plates: at {name} = +-L/2, L = {})",
                                num(-h),
                                num(h),
                                num(l)
                            ),
                        ));
                    }
                }
                Rows::Positions => {
                    if x64.abs() > h + FAR_IMAGES * l {
                        return Err(RowError::new(
                            row,
                            format!(
                                "{name} = {x} is more than {FAR_IMAGES} box lengths (L = {}) outside the periodic box [{}, {}): so far out an image loses its place to f32 rounding; give positions inside the box",
                                num(l),
                                num(-h),
                                num(h)
                            ),
                        ));
                    }
                }
                Rows::Velocities(Some(vth)) => {
                    let max = MAX_VELOCITY * vth;
                    if x64.abs() >= max {
                        return Err(RowError::new(
                            row,
                            format!(
                                "|{name}| = {} is not below {MAX_VELOCITY} v_th = {}, the range of the cell sums' fixed point (v_th = sqrt(temperature / mass) = {}; 1 at temperature 0)",
                                x.abs(),
                                num(max),
                                num(vth)
                            ),
                        ));
                    }
                }
                Rows::Velocities(None) => {}
            }
        }
    }
    Ok(())
}

/// The velocity unit of the cell sums' fixed point, v_th = sqrt(kT / m) (1 at kT = 0).
pub(crate) fn velocity_unit(kt: f64, mass: f64) -> f64 {
    if kt > 0.0 { (kt / mass).sqrt() } else { 1.0 }
}

/// The magnitude bound of MPCD's dimensional params (lengths, kT, masses, dt, forces):
/// from 1e-30 to 1e30 an f32 (normal from 1.2e-38 to 3.4e38) carries each of them, and
/// their products with the counts and ratios the kernels form, with 8 decades to spare.
pub const F32_SCALE: f64 = 1e30;

/// The range of v_th^2 = kT / m: the cell sums' units 2^24 / v_th and 2^16 / v_th^2, and
/// sums of |v|^2 over 10^12 particle-samples (up to 3 10^12 v_th^2), stay finite in f32.
pub const VTH2_RANGE: (f64, f64) = (1e-20, 1e20);

/// The most cells along one axis: positions at the box edge, +-2^15 cells from the
/// centre, still resolve 1/256 of a cell in f32.
pub const MAX_AXIS_CELLS: f64 = 65_536.0;

/// The passes of the streaming kernel's wall loop: each ends at a plate or the end of the
/// step, so a particle may cross the gap at most PASSES - 2 times in one step.
pub const WALL_PASSES: f64 = 16.0;

/// The smallest mean free path dt v_th, relative to the largest box length, that the f32
/// positions resolve: the step moves a particle by at least 2^4 ulps at the box edge
/// (2^-20 L; an f32 carries 24 bits), so rounding takes at most 1/16 of it.
pub const MIN_FREE_PATH: f64 = 1.0 / 1_048_576.0;

pub(crate) fn geometry_params() -> Vec<ParamSpec> {
    vec![
        ParamSpec {
            name: "box",
            kind: ParamKind::Numbers {
                len: None,
                min: 1.0 / F32_SCALE,
                max: F32_SCALE,
            },
            default: None,
            doc: "box lengths per axis (2 or 3 values), centred at the origin; from 1e-30 to 1e30 (f32 carries them and their sums with the grid shift), at most 65536 cells along an axis (positions at the box edge then resolve 1/256 of a cell in f32)",
        },
        ParamSpec::number(
            "cell",
            Some(1.0),
            1.0 / F32_SCALE,
            F32_SCALE,
            "collision cell size a (box lengths are whole numbers of cells); from 1e-30 to 1e30 (f32)",
        ),
        ParamSpec::choice(
            "walls",
            "none",
            &["none", "plates"],
            "none: periodic; plates: walls perpendicular to the last axis at +-L/2",
        ),
    ]
}

/// `temperature` of the kinds that take a thermal scale.
pub(crate) fn temperature_param() -> ParamSpec {
    ParamSpec::number(
        "temperature",
        Some(1.0),
        0.0,
        F32_SCALE,
        "kT (sets the fixed-point unit v_th = sqrt(kT/m) of the cell sums; 1 at kT = 0): 0 or from 1e-30 to 1e30, with kT/m from 1e-20 to 1e20 (the f32 kernels form kT/m, m/kT, 2^24/v_th, 2^16/v_th^2 and sums of |v|^2 over 10^12 particle-samples)",
    )
}

/// `mass` of the MPCD kinds.
pub(crate) fn mass_param() -> ParamSpec {
    ParamSpec::number(
        "mass",
        Some(1.0),
        1.0 / F32_SCALE,
        F32_SCALE,
        "particle mass m: from 1e-30 to 1e30 (f32; see temperature for kT/m)",
    )
}

pub(crate) fn thermal_params() -> Vec<ParamSpec> {
    vec![temperature_param(), mass_param()]
}

/// The fixed-point unit v_th of checked `temperature` and `mass` params, or why the f32
/// kernels cannot carry them (`temperature_param`'s range).
pub(crate) fn thermal_unit(p: &Params) -> Result<f64, String> {
    let (kt, mass) = (p.number("temperature"), p.number("mass"));
    if kt == 0.0 {
        return Ok(1.0);
    }
    if kt < 1.0 / F32_SCALE {
        return Err(format!(
            "temperature {} is below 1e-30 (give 0 or from 1e-30 to 1e30: the f32 kernels carry kT)",
            num(kt)
        ));
    }
    let vth2 = kt / mass;
    if !(VTH2_RANGE.0..=VTH2_RANGE.1).contains(&vth2) {
        return Err(format!(
            "temperature / mass = {} / {} = {} is outside [1e-20, 1e20]: v_th^2 = kT/m must be there for the f32 kernels (the cell sums' units 2^24/v_th and 2^16/v_th^2, sums of |v|^2); change temperature or mass",
            num(kt),
            num(mass),
            num(vth2)
        ));
    }
    Ok(vth2.sqrt())
}

/// The fixed-point scales (fix_v, fix_e) for (kT, m), as f32 (the GPU's values).
pub(crate) fn fixed_scales(kt: f64, mass: f64) -> (f32, f32) {
    let vth = velocity_unit(kt, mass);
    ((16_777_216.0 / vth) as f32, (65_536.0 / (vth * vth)) as f32)
}

/// `warmup` and `every`: the steps an accumulating node samples (from step `warmup` on,
/// every `every`-th), for `Uniform::set_sampling`.
pub(crate) fn sampling_params() -> Vec<ParamSpec> {
    vec![
        ParamSpec::integer(
            "warmup",
            Some(0.0),
            0.0,
            u32::MAX as f64,
            "steps before the first sample",
        ),
        ParamSpec::integer(
            "every",
            Some(1.0),
            1.0,
            u32::MAX as f64,
            "steps between samples",
        ),
    ]
}

impl Uniform {
    /// `sampling_params` into the uniform.
    pub(crate) fn set_sampling(&mut self, p: &Params) {
        self.warmup = p.number("warmup") as u32;
        self.every = p.number("every") as u32;
    }

    /// Whether `step` is sampled: the host's twin of `sampled` in shaders/mpcd/common.wgsl.
    pub(crate) fn sampled(&self, step: u32) -> bool {
        step >= self.warmup && (step - self.warmup).is_multiple_of(self.every)
    }
}

/// Seed and stream of a kind's params into the uniform.
pub(crate) fn key_into(u: &mut Uniform, p: &Params) {
    let seed = p.number("seed") as u64;
    u.seed_lo = seed as u32;
    u.seed_hi = (seed >> 32) as u32;
    u.stream = p.number("stream") as u32;
}

/// The key (seed, stream) of a kind's params.
pub(crate) fn key_of(p: &Params) -> (u64, u32) {
    (p.number("seed") as u64, p.number("stream") as u32)
}

/// This step's grid shift (f64 twin of `grid_shift`): uniform in [-w/2, w/2) per axis for
/// a width w = a (SRD) or 2a (MPCD-BC).
pub fn grid_shift(width: f64, step: u64, seed: u64, stream: u32) -> [f64; 3] {
    let w = super::random::block(0, step, seed, stream);
    let mut s = [0.0; 3];
    for a in 0..3 {
        s[a] = ((w[a] >> 8) as f64 / 16_777_216.0 - 0.5) * width;
    }
    s
}

/// MPCD-BC needs supercells that tile a periodic box.
pub(crate) fn check_rule(geo: &Geometry, biased: bool) -> Result<(), String> {
    if !biased {
        return Ok(());
    }
    // With plates the walled axis has L/a + 2 layers: even with L/a.
    if geo.cells.iter().any(|c| c % 2 != 0) {
        let cells: Vec<f64> = geo.lengths.iter().map(|l| (l / geo.cell).round()).collect();
        return Err(format!(
            "rule `biased` needs an even number of cells per axis (supercells of 2), got {cells:?}"
        ));
    }
    Ok(())
}

pub(crate) fn rule_param() -> ParamSpec {
    ParamSpec::choice(
        "rule",
        "srd",
        &["srd", "biased"],
        "srd: rotations within cells; biased: Ihle's biased collisions between cell pairs of 2 x 2 (x 2) supercells (MPCD-BC; grid shift in [-a, a); even cell counts per axis; with plates one more layer of cells on the walled axis, the layers the plates cut filled up to `density` with virtual particles (mpcd_collide's `ghosts`) for the pairs' means and acceptance)",
    )
}

/// The (positions, velocities) pair of a per-particle MPCD node, N x d each.
pub(crate) fn particle_ports() -> Vec<PortSpec> {
    vec![
        PortSpec::new("positions", PortType::Particles(None), "positions (N x d)"),
        PortSpec::new(
            "velocities",
            PortType::Particles(None),
            "velocities (N x d)",
        ),
    ]
}

/// The fixed-point integer of x (clamped to the i32 range, as the GPU does).
pub(crate) fn fx_round(x: f64) -> i64 {
    x.clamp(-2_147_483_520.0, 2_147_483_520.0).round() as i64
}

/// A 64-bit sum as its (lo, hi) words.
pub(crate) fn words_of(v: i64) -> [f64; 2] {
    let u = v as u64;
    [(u & 0xffff_ffff) as f64, (u >> 32) as f64]
}

/// The 64-bit sum held by (lo, hi) words.
pub fn value_of(lo: f64, hi: f64) -> i64 {
    ((hi as u64) << 32 | lo as u64) as i64
}

pub fn register(r: &mut Registry) {
    r.add(init::mpcd_init_kind());
    r.add(stream::mpcd_stream_kind());
    r.add(stream_bin::mpcd_stream_bin_kind());
    r.add(spheres::mpcd_stream_spheres_kind());
    r.add(spheres::mpcd_sphere_exclude_kind());
    r.add(sphere_coupling::mpcd_sphere_fill_kind());
    r.add(sphere_coupling::mpcd_sphere_force_kind());
    r.add(sphere_coupling::mpcd_sphere_move_kind());
    r.add(sphere_profile::mpcd_sphere_profile_kind());
    r.add(virial::mpcd_virial_kind());
    r.add(collide::mpcd_bin_kind());
    r.add(collide::mpcd_collide_kind());
    r.add(solute::mpcd_bin_solute_kind());
    r.add(measure::mpcd_measure_kind());
    r.add(measure::mpcd_average_kind());
}
