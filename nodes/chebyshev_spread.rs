//! Spreading and interpolation on the grid of the doubly periodic solvers: regular in x
//! and y (periodic, cells centred at -L/2 + (i + 1/2) h as `spread`'s), Chebyshev-Gauss-
//! Lobatto in z (z_j = zmid + (H/2) cos(pi j / (n - 1)), j = 0 the top, H = zmax - zmin;
//! `chebyshev`'s layout). UAMMD thesis section 23.4; digest section 7.6.
//!
//! The window is separable, delta(r) = phi_x(dx) phi_y(dy) phi_z(dz), each factor the
//! window library's phi per unit length (`spread::window`), z's with the x cell size: its
//! support in z is the same length, `support` x h / 2 either side, over however many
//! Chebyshev points fall inside (their spacing shrinks towards the ends). With walls the
//! images are subtracted in the kernel, delta~ = delta(r - q) - delta(r - q_img), the
//! bottom image at 2 zmin - q_z (`walls`: bottom, slit), the top one at 2 zmax - q_z
//! (slit): a particle on a wall spreads nothing, and the spread field vanishes there.
//!
//! - `spread_chebyshev`: grid(x, y, z_j) = sum_i v_i delta~(x - q_i) (a density: no
//!   weights), one workgroup per particle, its threads over the (support + 1)^2 columns,
//!   each over the column's z points; float atomics, or fixed point in deterministic
//!   runs (`spread::fixed`).
//! - `interpolate_chebyshev`: u_i = sum over the grid of u(x, y, z_j) delta~(x - q_i)
//!   h_x h_y (H/2) w_j, w_j the Clenshaw-Curtis weights of the Lobatto points (their sum
//!   is 2): the quadrature of the integral of u delta~, adjoint to spreading in that
//!   inner product; the workgroup's sums added in a fixed order.
//!
//! Two pairs of kernels (`kernel`): `workgroup`, one workgroup of 64 threads per
//! particle as above, its window factors computed into workgroup memory behind a barrier
//! (shaders/chebyshev/spread.wgsl, interpolate.wgsl), and `lanes` (the default where the
//! adapter has subgroups), a segment of up to 32 subgroup lanes per particle, several
//! particles per workgroup (shaders/chebyshev/lanes.wgsl): the support's nonzero (x, y)
//! columns packed over the lanes (25 to 30 of the 49 (support + 1)^2 at a support of 5.1
//! cells, the `support` param 6), each lane evaluating its own column's factors and lane
//! t the z factor of point t, shared by shuffle; interpolation adds the segment by a
//! shuffle butterfly instead of the workgroup tree. Both give the same sums up to f32
//! rounding (the same weights; in deterministic runs the same spread bits).
//!
//! Particles must lie in [zmin, zmax] (the domain holds their support, or a wall bounds
//! it): others are refused with their row.

use std::f64::consts::PI;

use crate::gpu::{Binding, CompileCtx, CompileError, DeviceCaps, Dispatch, KernelSpec, NodeIo};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamKind, ParamSpec, Params, PortError, PortSpec,
    RefCtx, Registry, RowError, Signature,
};
use crate::value::{HostArray, HostData, PortType, RefArray, ValueType};

use super::chebyshev;
use super::spread::fixed;
use super::spread::window::{self, Window};

/// Threads per particle (one workgroup) of the kernels.
const WG: u32 = 64;

/// Components the interpolation kernel sums per particle.
const MAX_COMPS: u32 = 4;

/// Threads per workgroup of the `lanes` kernels: 256 / seg consecutive particles on one
/// multiprocessor, whose supports overlap where the particles are sorted (their grid
/// reads shared in its L1), as FCM's lane kernels.
const LANES_WG: u32 = 256;

/// Most lanes per particle of the `lanes` kernels (a warp on NVIDIA): a support of 5.1
/// cells packs 25 to 30 columns.
const MAX_SEG: u32 = 32;

/// The `kernel` param: which pair of kernels runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KernelChoice {
    /// `lanes` where the adapter has subgroups, else `workgroup`.
    Auto,
    /// One workgroup of 64 threads per particle, the factors in workgroup memory
    /// (shaders/chebyshev/spread.wgsl, interpolate.wgsl).
    Workgroup,
    /// A segment of subgroup lanes per particle (shaders/chebyshev/lanes.wgsl); an error
    /// where the adapter has no subgroups.
    Lanes,
}

impl KernelChoice {
    fn parse(s: &str) -> KernelChoice {
        match s {
            "workgroup" => KernelChoice::Workgroup,
            "lanes" => KernelChoice::Lanes,
            _ => KernelChoice::Auto,
        }
    }
}

/// Image subtraction by the walls bounding z.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Walls {
    None,
    Bottom,
    Slit,
}

impl Walls {
    fn code(self) -> u32 {
        match self {
            Walls::None => 0,
            Walls::Bottom => 1,
            Walls::Slit => 2,
        }
    }
}

/// The grid and window, with the f64 functions the reference and the tables use.
#[derive(Clone, Debug)]
pub struct ChebyshevGrid {
    pub lengths: [f64; 2],
    pub cells: [u32; 2],
    pub zmin: f64,
    pub zmax: f64,
    pub points: u32,
    pub window: Window,
    pub walls: Walls,
    /// Where particles may lie in z: [zmin, zmax], or the narrower range of a padded grid
    /// (`particle_zmin`, `particle_zmax`: the physical domain, its open sides padded so a
    /// particle's support stays inside).
    pub particle_z: [f64; 2],
    /// Which kernels run (`kernel`).
    pub kernel: KernelChoice,
}

impl ChebyshevGrid {
    pub fn h(&self, a: usize) -> f64 {
        self.lengths[a] / self.cells[a] as f64
    }

    /// Where the window ends along x (a = 0) or y (1), in cells.
    fn half_support(&self, a: usize) -> f64 {
        self.window.half_support_cells(self.h(a))
    }

    /// Where the window ends along z, as a length (z is measured in x cells).
    pub fn z_radius(&self) -> f64 {
        self.half_support(0) * self.h(0)
    }

    /// The z of each Chebyshev point, top first.
    pub fn z_points(&self) -> Vec<f64> {
        let (mid, half) = (0.5 * (self.zmin + self.zmax), 0.5 * (self.zmax - self.zmin));
        chebyshev::points(self.points as usize)
            .into_iter()
            .map(|x| mid + half * x)
            .collect()
    }

    /// Quadrature weight of each grid point: h_x h_y (H / 2) w_j.
    pub fn weights(&self) -> Vec<f64> {
        let scale = self.h(0) * self.h(1) * 0.5 * (self.zmax - self.zmin);
        clenshaw_curtis(self.points as usize)
            .into_iter()
            .map(|w| w * scale)
            .collect()
    }

    /// phi per unit length along x or y at `r` cells, zero beyond the support.
    fn phi_xy(&self, r: f64, a: usize) -> f64 {
        if r.abs() > self.half_support(a) {
            0.0
        } else {
            self.window.phi(r, self.h(a)) / self.h(a)
        }
    }

    /// phi per unit length along z at distance `d`, zero beyond the support.
    fn phi_z(&self, d: f64) -> f64 {
        let h = self.h(0);
        if d.abs() > self.z_radius() {
            0.0
        } else {
            self.window.phi(d / h, h) / h
        }
    }

    /// The z factor of the image-subtracted kernel between a grid point at z and a
    /// particle at qz.
    pub fn z_kernel(&self, z: f64, qz: f64) -> f64 {
        let mut w = self.phi_z(z - qz);
        if self.walls != Walls::None {
            w -= self.phi_z(z - (2.0 * self.zmin - qz));
        }
        if self.walls == Walls::Slit {
            w -= self.phi_z(z - (2.0 * self.zmax - qz));
        }
        w
    }

    /// Every grid word (x + nx (y + ny j)) a particle at q touches, with its kernel value.
    pub fn support(&self, q: &[f64]) -> Vec<(usize, f64)> {
        let [nx, ny] = self.cells;
        let s = self.window.support() as i64;
        let mut cols = Vec::new();
        let mut first = [0i64; 2];
        let mut u = [0.0; 2];
        for a in 0..2 {
            let l = self.lengths[a];
            let folded = q[a] - l * (q[a] / l + 0.5).floor();
            u[a] = (folded + 0.5 * l) / self.h(a) - 0.5;
            first[a] = (u[a] - self.half_support(a)).ceil() as i64;
        }
        for dy in 0..=s {
            for dx in 0..=s {
                let (ix, iy) = (first[0] + dx, first[1] + dy);
                let w = self.phi_xy(ix as f64 - u[0], 0) * self.phi_xy(iy as f64 - u[1], 1);
                if w != 0.0 {
                    let cell = ix.rem_euclid(nx as i64) as usize
                        + nx as usize * iy.rem_euclid(ny as i64) as usize;
                    cols.push((cell, w));
                }
            }
        }
        let plane = nx as usize * ny as usize;
        let mut out = Vec::new();
        for (j, z) in self.z_points().into_iter().enumerate() {
            let wz = self.z_kernel(z, q[2]);
            if wz == 0.0 {
                continue;
            }
            for &(cell, w) in &cols {
                out.push((j * plane + cell, w * wz));
            }
        }
        out
    }

    fn grid_type(&self, comps: u32) -> ValueType {
        ValueType::RealGrid {
            dims: [self.cells[0], self.cells[1], self.points],
            comps,
        }
    }

    /// Refuses a position outside [zmin, zmax] or not finite, by row.
    fn check_positions(&self, data: &HostArray) -> Result<(), RowError> {
        let (ValueType::Particles { k: 3, .. }, HostData::F32(values)) = (data.ty, &data.data)
        else {
            return Ok(());
        };
        for (row, x) in values.chunks_exact(3).enumerate() {
            if x.iter().any(|c| !c.is_finite()) {
                return Err(RowError::new(row, format!("position {x:?} is not finite")));
            }
            let z = x[2] as f64;
            let [lo, hi] = self.particle_z;
            if z < lo || z > hi {
                let what = if (lo, hi) == (self.zmin, self.zmax) {
                    "the grid's [zmin, zmax]"
                } else {
                    "the particles' [particle_zmin, particle_zmax]"
                };
                return Err(RowError::new(
                    row,
                    format!(
                        "z = {} is outside {what} = [{lo}, {hi}]{}",
                        x[2],
                        match self.walls {
                            Walls::None => "",
                            Walls::Bottom => " (below the bottom wall, or above the domain)",
                            Walls::Slit => " (through a wall of the slit)",
                        }
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The kernels' uniform.
    fn uniform(&self, n: u32, comps: u32) -> Geometry {
        let (h0, h1) = (self.h(0), self.h(1));
        Geometry {
            n: [self.cells[0], self.cells[1], self.points, n],
            shape: [self.window.support(), comps, self.walls.code(), 0],
            h: [h0 as f32, h1 as f32, (1.0 / h0) as f32, (1.0 / h1) as f32],
            box_len: [
                self.lengths[0] as f32,
                self.lengths[1] as f32,
                (1.0 / self.lengths[0]) as f32,
                (1.0 / self.lengths[1]) as f32,
            ],
            z: [
                self.zmin as f32,
                self.zmax as f32,
                (0.5 * (self.zmin + self.zmax)) as f32,
                (0.5 * (self.zmax - self.zmin)) as f32,
            ],
            win_x: self.window.gpu_params(h0),
            win_y: self.window.gpu_params(h1),
            radius: [
                self.half_support(0) as f32,
                self.z_radius() as f32,
                self.half_support(1) as f32,
                0.0,
            ],
        }
    }

    /// Lanes per particle of the `lanes` kernels on this adapter (the smallest subgroup,
    /// at most MAX_SEG), or None for the workgroup kernels; an error where `lanes` was
    /// asked for and the adapter has no subgroups (raised when the kernels are built, so
    /// that planning without a device takes any choice).
    fn segment(&self, caps: &DeviceCaps) -> Result<Option<u32>, String> {
        let seg = match caps.subgroups {
            Some((min, _)) if min.is_power_of_two() => Some(min.min(MAX_SEG)),
            _ => None,
        };
        match self.kernel {
            KernelChoice::Workgroup => Ok(None),
            KernelChoice::Auto => Ok(seg),
            KernelChoice::Lanes => seg.map(Some).ok_or_else(|| {
                "kernel `lanes` needs subgroups (a power of two wide); this adapter has none"
                    .to_string()
            }),
        }
    }

    /// The z points then the quadrature weights, f32, for the kernels.
    fn table(&self) -> Vec<f32> {
        self.z_points()
            .into_iter()
            .chain(self.weights())
            .map(|v| v as f32)
            .collect()
    }
}

/// Layout of `Geometry` in shaders/chebyshev/grid.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Geometry {
    n: [u32; 4],
    shape: [u32; 4],
    h: [f32; 4],
    box_len: [f32; 4],
    z: [f32; 4],
    win_x: [f32; 4],
    win_y: [f32; 4],
    radius: [f32; 4],
}

/// Clenshaw-Curtis weights of the n Chebyshev-Gauss-Lobatto points on [-1, 1]
/// (Trefethen, Spectral Methods in MATLAB, `clencurt`); they sum to 2.
pub fn clenshaw_curtis(points: usize) -> Vec<f64> {
    let n = points - 1;
    let mut w = vec![0.0; points];
    if n == 0 {
        return vec![2.0];
    }
    let nf = n as f64;
    let ends = if n.is_multiple_of(2) {
        1.0 / (nf * nf - 1.0)
    } else {
        1.0 / (nf * nf)
    };
    w[0] = ends;
    w[n] = ends;
    for (i, wi) in w.iter_mut().enumerate().take(n).skip(1) {
        let theta = PI * i as f64 / nf;
        let mut v = 1.0;
        if n.is_multiple_of(2) {
            for k in 1..n / 2 {
                v -= 2.0 * (2.0 * k as f64 * theta).cos() / (4.0 * (k * k) as f64 - 1.0);
            }
            v -= (nf * theta).cos() / (nf * nf - 1.0);
        } else {
            for k in 1..=(n - 1) / 2 {
                v -= 2.0 * (2.0 * k as f64 * theta).cos() / (4.0 * (k * k) as f64 - 1.0);
            }
        }
        *wi = 2.0 * v / nf;
    }
    w
}

fn grid_params() -> Vec<ParamSpec> {
    vec![
        ParamSpec {
            name: "box",
            kind: ParamKind::Numbers {
                len: Some(2),
                min: f64::MIN_POSITIVE,
                max: f64::MAX,
            },
            default: None,
            doc: "periodic lengths [Lx, Ly], centred at the origin",
        },
        ParamSpec {
            name: "grid",
            kind: ParamKind::Numbers {
                len: Some(2),
                min: 1.0,
                max: 65536.0,
            },
            default: None,
            doc: "cells along x and y",
        },
        ParamSpec::number(
            "zmin",
            None,
            -f64::MAX,
            f64::MAX,
            "the bottom of the z domain",
        ),
        ParamSpec::number(
            "zmax",
            None,
            -f64::MAX,
            f64::MAX,
            "the top of the z domain (above zmin)",
        ),
        ParamSpec::integer(
            "points",
            None,
            2.0,
            chebyshev::MAX_POINTS as f64,
            "Chebyshev-Gauss-Lobatto points along z",
        ),
        ParamSpec::choice(
            "window",
            "gaussian",
            &["gaussian", "es"],
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
            "cells per axis in x and y (0: from the tolerance); in z the same length, support h_x / 2 either side",
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
            "walls",
            "none",
            &["none", "bottom", "slit"],
            "walls whose images are subtracted in the kernel: none, bottom (at zmin), slit (zmin and zmax)",
        ),
        ParamSpec::number(
            "particle_zmin",
            Some(-f64::MAX),
            -f64::MAX,
            f64::MAX,
            "particles below this are refused by row (the physical domain's bottom inside a padded grid; never below zmin)",
        ),
        ParamSpec::number(
            "particle_zmax",
            Some(f64::MAX),
            -f64::MAX,
            f64::MAX,
            "particles above this are refused by row (the physical domain's top inside a padded grid; never above zmax)",
        ),
        ParamSpec::choice(
            "kernel",
            "auto",
            &["auto", "workgroup", "lanes"],
            "workgroup: one workgroup of 64 threads per particle, the window's factors in workgroup memory; lanes: a segment of subgroup lanes per particle (up to 32), its support's columns packed over the lanes, no workgroup memory or barrier (needs subgroups); auto: lanes where the adapter has subgroups",
        ),
    ]
}

fn grid_of(p: &Params) -> Result<ChebyshevGrid, String> {
    let lengths = p.numbers("box");
    let grid = p.numbers("grid");
    if grid.iter().any(|g| g.fract() != 0.0) {
        return Err(format!(
            "`grid` must be whole numbers of cells, got {grid:?}"
        ));
    }
    let (zmin, zmax) = (p.number("zmin"), p.number("zmax"));
    if zmax.partial_cmp(&zmin) != Some(std::cmp::Ordering::Greater) || !(zmax - zmin).is_finite() {
        return Err(format!("`zmax` ({zmax}) must lie above `zmin` ({zmin})"));
    }
    let cells = [grid[0] as u32, grid[1] as u32];
    let h_min = (lengths[0] / grid[0]).min(lengths[1] / grid[1]);
    let window = Window::from_params(
        p.text("window"),
        p.number("width"),
        p.number("support") as u32,
        p.number("beta"),
        p.number("tolerance"),
        h_min,
    )?;
    if window.support() + 1 > cells[0].min(cells[1]) {
        return Err(format!(
            "the window's support ({} cells) must be smaller than the grid ({}x{} cells)",
            window.support(),
            cells[0],
            cells[1]
        ));
    }
    let walls = match p.text("walls") {
        "bottom" => Walls::Bottom,
        "slit" => Walls::Slit,
        _ => Walls::None,
    };
    Ok(ChebyshevGrid {
        lengths: [lengths[0], lengths[1]],
        cells,
        zmin,
        zmax,
        points: p.number("points") as u32,
        window,
        walls,
        particle_z: [
            p.number("particle_zmin").max(zmin),
            p.number("particle_zmax").min(zmax),
        ],
        kernel: KernelChoice::parse(p.text("kernel")),
    })
}

fn spread_kind() -> NodeKind {
    NodeKind::declare(
        "spread_chebyshev",
        "spreads particle values onto a grid regular in x, y (periodic) and Chebyshev-Gauss-Lobatto in z: grid = sum_i v_i delta~(r - q_i), the window with the walls' images subtracted (the doubly periodic solvers)",
    )
    .input(PortSpec::new("positions", PortType::Particles(Some(3)), "particle positions (N x 3), z within [zmin, zmax]"))
    .input(PortSpec::new("values", PortType::Particles(None), "values to spread (N x k)"))
    .output(PortSpec::new("out", PortType::RealGrid, "the grid: nx x ny x points, k components (z index 0 at zmax)"))
    .params(grid_params())
    .build(|p| Ok(Box::new(SpreadChebyshev { g: grid_of(p)? })))
}

fn interpolate_kind() -> NodeKind {
    NodeKind::declare(
        "interpolate_chebyshev",
        "interpolates a grid regular in x, y and Chebyshev-Gauss-Lobatto in z at particles: u_i = sum over the grid of u delta~(r - q_i) h_x h_y (H/2) w_j (Clenshaw-Curtis weights), the adjoint of spread_chebyshev",
    )
    .input(PortSpec::new("grid", PortType::RealGrid, "the field (nx x ny x points, up to 4 components)"))
    .input(PortSpec::new("positions", PortType::Particles(Some(3)), "particle positions (N x 3), z within [zmin, zmax]"))
    .output(PortSpec::new("out", PortType::Particles(None), "the interpolated values (N x components)"))
    .params(grid_params())
    .build(|p| Ok(Box::new(InterpolateChebyshev { g: grid_of(p)? })))
}

struct SpreadChebyshev {
    g: ChebyshevGrid,
}

struct InterpolateChebyshev {
    g: ChebyshevGrid,
}

fn check_positions_type(t: Option<ValueType>, port: &str) -> Result<u32, PortError> {
    match t {
        Some(ValueType::Particles { n, k: 3 }) => Ok(n),
        Some(t) => Err(PortError::new(
            port,
            format!("must be N x 3 positions, got {t}"),
        )),
        None => unreachable!("required"),
    }
}

/// The fixed-point exponent of deterministic spreading: the kernel's peak weight per grid
/// word (at the particle's centre, before image subtraction) times N times the times a
/// support wraps the periodic axes.
fn fixed_exponent(g: &ChebyshevGrid, n: u32) -> Result<i32, String> {
    let peak = g.phi_xy(0.0, 0) * g.phi_xy(0.0, 1) * g.phi_z(0.0);
    let s = g.window.support() + 1;
    let wraps = (s.div_ceil(g.cells[0]) * s.div_ceil(g.cells[1])) as f64;
    fixed::bound_exponent(peak, n, wraps)
}

impl Node for SpreadChebyshev {
    fn check_input(&self, port: usize, data: &HostArray) -> Result<(), RowError> {
        if port == 0 {
            self.g.check_positions(data)
        } else {
            Ok(())
        }
    }

    fn checks_input(&self) -> bool {
        true
    }

    fn infer(
        &self,
        inputs: &[Option<ValueType>],
        caps: &DeviceCaps,
    ) -> Result<Signature, PortError> {
        let n = check_positions_type(inputs[0], "positions")?;
        let Some(ValueType::Particles { n: m, k }) = inputs[1] else {
            unreachable!("port type checked")
        };
        if m != n {
            return Err(PortError::new(
                "values",
                format!("has {m} rows for {n} positions"),
            ));
        }
        let out = self.g.grid_type(k);
        let signature = Signature::outputs(vec![out]);
        if caps.deterministic {
            fixed_exponent(&self.g, n).map_err(|e| PortError::new("values", e))?;
            return Ok(signature.with_scratch(vec![4 * fixed::fixed_words(out.words())]));
        }
        Ok(signature)
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn notes(&self, _: &[Option<ValueType>]) -> Vec<String> {
        vec![describe(&self.g)]
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let pos = &inputs[0].as_ref().expect("required").data;
        let vals = inputs[1].as_ref().expect("required");
        let ValueType::Particles { n, k } = vals.ty else {
            unreachable!()
        };
        let words = self.g.cells[0] as usize * self.g.cells[1] as usize * self.g.points as usize;
        outputs[0].data.fill(0.0);
        for i in 0..n as usize {
            for (cell, w) in self.g.support(&pos[3 * i..3 * i + 3]) {
                for c in 0..k as usize {
                    outputs[0].data[c * words + cell] += w * vals.data[i * k as usize + c];
                }
            }
        }
    }
}

/// A kernel's label, shader file, threads for `n` particles and workgroup size: one
/// workgroup of WG threads per particle, or (`seg` lanes per particle) LANES_WG / seg
/// particles per workgroup of LANES_WG.
fn launch(seg: Option<u32>, node: &str, op: &str, n: u32) -> (String, String, u64, u32) {
    match seg {
        Some(s) => (
            format!("{node} (lanes)"),
            format!("chebyshev/{op}_lanes.wgsl"),
            (n as u64).div_ceil((LANES_WG / s) as u64) * LANES_WG as u64,
            LANES_WG,
        ),
        None => (
            node.to_string(),
            format!("chebyshev/{op}.wgsl"),
            n as u64 * WG as u64,
            WG,
        ),
    }
}

/// The `lanes` kernels' lanes per particle and workgroup size, as WGSL put before their
/// source.
fn seg_constant(seg: Option<u32>) -> String {
    seg.map_or(String::new(), |s| {
        format!("const SEG: u32 = {s}u;\nconst LANES_WG: u32 = {LANES_WG}u;\n")
    })
}

fn describe(g: &ChebyshevGrid) -> String {
    format!(
        "{}x{}x{} grid (Chebyshev in z over [{}, {}]), {}, z support +-{:.4}, walls {:?}, kernel {:?}",
        g.cells[0],
        g.cells[1],
        g.points,
        g.zmin,
        g.zmax,
        g.window.describe(),
        g.z_radius(),
        g.walls,
        g.kernel
    )
}

impl GpuKernels for SpreadChebyshev {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let pos = io.inputs[0].expect("required");
        let vals = io.inputs[1].expect("required");
        let out = io.outputs[0];
        let ValueType::Particles { n, k } = vals.ty else {
            unreachable!()
        };
        let caps = cx.caps();
        let exp = if caps.deterministic {
            Some(fixed_exponent(&self.g, n).map_err(CompileError::Unsupported)?)
        } else {
            None
        };
        let add = match exp {
            Some(_) => "spread/add_fixed.wgsl",
            None if caps.f32_atomics => "spread/add_atomic.wgsl",
            None => "spread/add_cas.wgsl",
        };
        let seg = self.g.segment(caps).map_err(CompileError::Unsupported)?;
        let (label, file, threads, wg) = launch(seg, "spread_chebyshev", "spread", n);
        let source = format!(
            "{}{}{}{}",
            seg_constant(seg),
            cx.shader(self.g.window.shader())?,
            cx.shader(add)?,
            cx.shader(&file)?
        );
        let mut spec = KernelSpec::new(
            label,
            source,
            &[
                Binding::StorageRead,
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::Uniform,
                Binding::StorageRead,
            ],
        );
        let grid = match exp {
            Some(e) => {
                spec = fixed::with_constants(spec, out.ty.words(), e);
                io.scratch[0]
            }
            None => out.buffer,
        };
        let kernel = cx.kernel(&spec)?;
        let geo = cx.uniform(
            "spread_chebyshev geometry",
            bytemuck::bytes_of(&self.g.uniform(n, k)),
        );
        let table = cx.table(
            "spread_chebyshev z points and weights",
            bytemuck::cast_slice(&self.g.table()),
        );
        let mut dispatches = match exp {
            Some(_) => fixed::begin(cx, grid, vals.buffer, vals.ty.words(), out.ty.words())?,
            None => vec![cx.fill(out.buffer, out.ty.words(), 0)?],
        };
        dispatches.push(cx.dispatch(
            &kernel,
            &[pos.buffer, vals.buffer, grid, &geo, &table],
            cx.grid_1d(threads, wg),
        ));
        if let Some(e) = exp {
            dispatches.push(fixed::finish(cx, grid, out.buffer, out.ty.words(), e)?);
        }
        Ok(dispatches)
    }
}

impl Node for InterpolateChebyshev {
    fn check_input(&self, port: usize, data: &HostArray) -> Result<(), RowError> {
        if port == 1 {
            self.g.check_positions(data)
        } else {
            Ok(())
        }
    }

    fn checks_input(&self) -> bool {
        true
    }

    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let n = check_positions_type(inputs[1], "positions")?;
        let Some(ValueType::RealGrid { comps, .. }) = inputs[0] else {
            unreachable!("port type checked")
        };
        if inputs[0] != Some(self.g.grid_type(comps)) {
            return Err(PortError::new(
                "grid",
                format!(
                    "is {} but the params say {}",
                    inputs[0].expect("matched"),
                    self.g.grid_type(comps)
                ),
            ));
        }
        if comps > MAX_COMPS {
            return Err(PortError::new(
                "grid",
                format!("has {comps} components: interpolate_chebyshev takes at most {MAX_COMPS}"),
            ));
        }
        Ok(Signature::outputs(vec![ValueType::Particles {
            n,
            k: comps,
        }]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn notes(&self, _: &[Option<ValueType>]) -> Vec<String> {
        vec![describe(&self.g)]
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let grid = inputs[0].as_ref().expect("required");
        let pos = &inputs[1].as_ref().expect("required").data;
        let ValueType::RealGrid { comps, .. } = grid.ty else {
            unreachable!()
        };
        let k = comps as usize;
        let plane = self.g.cells[0] as usize * self.g.cells[1] as usize;
        let words = plane * self.g.points as usize;
        let weights = self.g.weights();
        for (i, row) in outputs[0].data.chunks_mut(k).enumerate() {
            row.fill(0.0);
            for (cell, w) in self.g.support(&pos[3 * i..3 * i + 3]) {
                let q = weights[cell / plane];
                for (c, r) in row.iter_mut().enumerate() {
                    *r += w * q * grid.data[c * words + cell];
                }
            }
        }
    }
}

impl GpuKernels for InterpolateChebyshev {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let grid = io.inputs[0].expect("required");
        let pos = io.inputs[1].expect("required");
        let ValueType::Particles { n, k } = io.outputs[0].ty else {
            unreachable!()
        };
        let seg = self
            .g
            .segment(cx.caps())
            .map_err(CompileError::Unsupported)?;
        let (label, file, threads, wg) = launch(seg, "interpolate_chebyshev", "interpolate", n);
        let source = format!(
            "{}{}{}",
            seg_constant(seg),
            cx.shader(self.g.window.shader())?,
            cx.shader(&file)?
        );
        let kernel = cx.kernel(&KernelSpec::new(
            label,
            source,
            &[
                Binding::StorageRead,
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::Uniform,
                Binding::StorageRead,
            ],
        ))?;
        let geo = cx.uniform(
            "interpolate_chebyshev geometry",
            bytemuck::bytes_of(&self.g.uniform(n, k)),
        );
        let table = cx.table(
            "interpolate_chebyshev z points and weights",
            bytemuck::cast_slice(&self.g.table()),
        );
        Ok(vec![cx.dispatch(
            &kernel,
            &[pos.buffer, grid.buffer, io.outputs[0].buffer, &geo, &table],
            cx.grid_1d(threads, wg),
        )])
    }
}

pub fn register(r: &mut Registry) {
    r.add(spread_kind());
    r.add(interpolate_kind());
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Clenshaw-Curtis integrates polynomials up to degree n - 1 exactly on [-1, 1].
    #[test]
    fn clenshaw_curtis_integrates_polynomials() {
        for n in [2usize, 3, 4, 9, 16, 33] {
            let w = clenshaw_curtis(n);
            let x = chebyshev::points(n);
            for degree in 0..n {
                let got: f64 = w
                    .iter()
                    .zip(&x)
                    .map(|(w, x)| w * x.powi(degree as i32))
                    .sum();
                let want = if degree % 2 == 1 {
                    0.0
                } else {
                    2.0 / (degree as f64 + 1.0)
                };
                assert!(
                    (got - want).abs() < 1e-12,
                    "n {n} degree {degree}: {got} vs {want}"
                );
            }
        }
    }
}
