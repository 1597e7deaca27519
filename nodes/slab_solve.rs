//! `slab_solve`: the doubly periodic Stokes solve between the Chebyshev transforms in one
//! kernel (shaders/chebyshev/slab_solve.wgsl): from the forcing's Chebyshev coefficients
//! along z (a half spectrum in x, y) to the velocity's values at the Chebyshev points with
//! the walls, which the chain `chebyshev_derivative` (f_z), `slab_pressure_source`,
//! `chebyshev_bvp` (pressure), `chebyshev_derivative` (pressure), `slab_velocity_source`,
//! `chebyshev_bvp` (3 velocity components), `chebyshev` (inverse), `slab_walls` computes
//! with eight dispatches and a global-memory round trip of every intermediate
//! (nodes/stokes_slab.rs has the maths; the chain stays, as the reference and for the
//! other ports graphs need). Same conventions: wave numbers paired (i k zero on an
//! unpaired Nyquist index) in the sources, |k| unpaired; the k = 0 rules of each wall mode.
//!
//! Up to `THREE_LINES_UP_TO` points (shaders/chebyshev/slab_solve.wgsl): per k, 2 threads,
//! one per part (real or imaginary), 32 wave numbers a workgroup. Each thread holds its
//! part's x, y and z velocity lines side by side as the lanes of a vec3 line in registers,
//! so every step runs three independent chains and reads each per-k table entry once for
//! three lines; the pressure, which couples the parts, both threads solve whole (its real
//! and imaginary parts in two lanes), so no pressure crosses between threads. Each thread
//! then forms its three velocity sources and boundary values, solves, sums its
//! coefficients into its end values (workgroup memory), and after the one barrier takes
//! the walls' flow from both parts' end values and writes each value along z, with that
//! flow, as the dense inverse transform makes it (by parity: the even and odd terms' sums
//! at the upper half's points give both halves). On an H100 (2026-12-07 08:40Z, 10^6
//! spheres, 31 points) 0.231 ms, where the thread-per-line kernel below took 0.330.
//!
//! Past 32 points, where three lines no longer fit in registers (35 points: 0.42 ms against
//! 0.27 for a thread per line), shaders/chebyshev/slab_solve_line.wgsl: per k, 6 threads
//! (component, part), KS wave numbers a workgroup; each thread keeps its z line in
//! registers. The pressure is solved by component 0's two threads and handed to the others
//! through workgroup memory with its end values; the rest as above. No line of values is
//! held across a barrier: on an H100 (2026-12-07 02:36Z) that took this kernel from 0.531
//! to 0.330 ms at 10^6 spheres and 0.0635 to 0.0559 ms at 10^5, where the values' line
//! kept for the walls after the barrier had cost registers and so resident threads (with
//! the line loops bounded by the constant POINTS: slab_lines.wgsl says why).
//!
//! Both take the walls' constants and factors from stokes_slab/wall_flow.wgsl, whose
//! values are matrices of complex columns indexed by constants: through its earlier
//! helpers (arrays as arguments and results, indexed in loops) the thread-per-line kernel
//! took 0.63 ms at 10^6 instead of 0.33 and the three-lines kernel 1.02 instead of 0.25;
//! through these, 0.2301 ms against 0.2311 written out (H100, 2026-12-07 11:28Z). The per-k
//! tables (chebyshev_bvp's, the slit's 6 x 6 inverse) are built in f64 on the host, as
//! the chain's nodes build them; the pressure and velocity solves share one table (the
//! same k and domain). The point tables (zeta_j and the weights of dv/dz at the top from
//! the values) are shared with the staged kernel; these take the slope from the
//! coefficients and leave those n weights unread.
//!
//! What it reads and writes per k: 6 n words of f (plus re-reads from cache: both threads
//! of a k read all six lines for the pressure, then their own three), 6 n words out,
//! 5 n + 6 table words (72 more for the slit): 17 n + 6; the chain moves about 82 n + 36
//! words per k through memory (every intermediate written and read back, the tables read by
//! both solves).
//!
//! `staged` (shaders/chebyshev/slab_staged.wgsl), for grids with few wave numbers (the
//! bottom wall's 10^4 spheres: 1624, 102 workgroups of the kernel above on an H100's 132
//! multiprocessors, each thread one serial chain of its line's loads, two solves and a
//! 31 x 31 transform): 8 wave numbers a workgroup of 192 threads, their 48 lines and
//! per-k tables read into workgroup memory once in coalesced runs, the dense transforms
//! spread over 4 threads a line, the banded solves a thread per line from workgroup
//! memory, the walls' constants once per (k, component), the output written in the order
//! of its words. With `values` the input is the forcing's values along z (rfft's output)
//! and the forward transform runs inside, so the product needs no `chebyshev` dispatch
//! before it. The kernels share the line steps (shaders/chebyshev/slab_lines.wgsl).
//!
//! `lanes` (shaders/chebyshev/slab_lanes.wgsl, where the adapter has subgroups): a wave
//! number's z line over a segment of up to 8 subgroup lanes, an even number of consecutive
//! points a lane, the real and imaginary parts of the three velocity components (and the
//! pressure) as two vec3 lines in each lane's registers. The steps that are serial along z
//! in the kernels above are first-order recurrences within a parity (the banded
//! elimination, its back substitution, the Chebyshev derivative): each runs as a scan of
//! affine maps, a lane's own elements composed, then the segment's lanes by shuffles in
//! log2 of its width, then applied; the boundary rows and end values are shuffle sums,
//! and the inverse transform (by parity) reads the other lanes' coefficients by shuffle.
//! No workgroup memory and no barrier. A wave number's serial chain is then a few points
//! and a few shuffles long, and a grid has 8 times the threads of the kernels of whole
//! lines, for grids whose few wave numbers leave those kernels' chains unhidden. On an
//! H100 (2026-12-08 00:32Z) 0.043 ms at 10^5 spheres (bottom wall, 30 points) against the
//! three-lines kernel's 0.053, but 0.25 against 0.23 at 10^6 and slower past 32 points,
//! so it is opt-in (`slab` `lanes`): `auto` is planned without the device its subgroups
//! need, for about 2 % of the product.

use crate::gpu::{Binding, CompileCtx, CompileError, DeviceCaps, Dispatch, KernelSpec, NodeIo};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamSpec, Params, PortError, PortSpec, RefCtx, Registry,
    Signature,
};
use crate::value::{PortType, RefArray, ValueType, half_dims};

use super::{chebyshev, chebyshev_bvp, stokes_slab};

/// Chebyshev points the fused solve takes: its threads run a dense n x n inverse
/// transform each, and lavapipe stops a thread past 65535 loop iterations (n^2 + about
/// 15 n of them); longer lines go through the chain (graphs/lib/dpstokes_mobility.json's
/// `slab`, `dpstokes_slab`).
pub const MAX_POINTS: u32 = 160;

/// Chebyshev points up to which the fused kernel's inverse transform is written out with
/// the matrix's entries as literals (`written_out_transform`): no matrix loads, constant
/// indices. On an H100 (2026-12-06 23:38Z, against the loop in the same call): 0.0722 ->
/// 0.0640 ms at 10^5 spheres (30 points), 0.558 -> 0.529 ms at 10^6 (31). Its text grows
/// as n^2 / 2 products.
pub const WRITTEN_OUT_UP_TO: usize = 64;

/// What slab_solve.wgsl expects before it for n points: `const WRITTEN_OUT` and `fn
/// values_written_out()`, the inverse transform by parity handing each value to the
/// template's `put` (as its loop over `points` does, in the same order) with the entries of
/// `chebyshev::matrix(n, false)` as f32 literals and every index a constant, up to
/// `WRITTEN_OUT_UP_TO` points; past it WRITTEN_OUT is false and the function empty.
fn written_out_transform(n: usize) -> String {
    let written_out = n <= WRITTEN_OUT_UP_TO;
    let mut s = format!("const WRITTEN_OUT: bool = {written_out};\nfn values_written_out() {{\n");
    if written_out {
        let t = chebyshev::matrix(n, false);
        let sum = |j: usize, first: usize| -> String {
            let terms: Vec<String> = (first..n)
                .step_by(2)
                .map(|m| format!("{:?} * coef[{m}u]", t[j * n + m] as f32))
                .collect();
            if terms.is_empty() {
                "0.0".into()
            } else {
                terms.join(" + ")
            }
        };
        for j in 0..n.div_ceil(2) {
            s += &format!("    let even{j} = {};\n", sum(j, 0));
            s += &format!("    let odd{j} = {};\n", sum(j, 1));
            s += &format!("    put({j}u, even{j} + odd{j});\n");
            if n - 1 - j != j {
                s += &format!("    put({}u, even{j} - odd{j});\n", n - 1 - j);
            }
        }
    }
    s + "}\n"
}

/// Wave numbers (half-spectrum columns) up to which lib/dpstokes_mobility.json's `slab`
/// `auto` takes the staged kernel with the forward transform inside (`dpstokes_slab`):
/// where the fused kernel's workgroups (16 wave numbers each) do not fill a large GPU's
/// multiprocessors twice and each thread's serial chain sets its time (the bottom wall's
/// 10^4 spheres: 56 x 56 cells, 1624 wave numbers; 10^5: 15400, left to `fused`).
pub const STAGED_UP_TO: u64 = 4096;

/// Chebyshev points up to which the fused solve runs three lines a thread
/// (shaders/chebyshev/slab_solve.wgsl: a thread per (k, part), its x, y, z velocity lines
/// side by side); past them a thread per line (slab_solve_line.wgsl). On an H100
/// (2026-12-07): 0.231 ms against 0.330 at 31 points (10^6 spheres, bottom wall), 0.42
/// against 0.27 ms at 35 (no walls), where the three lines no longer fit in registers.
pub const THREE_LINES_UP_TO: u32 = 32;

/// Wave numbers per workgroup of the three-lines kernel (64 threads; 16, 64 and 128 timed
/// the same on an H100).
const THREE_LINES_KS: u32 = 32;

/// Workgroup words the thread-per-line kernel's shared lines may take (of the 16 KiB every
/// adapter has).
const SHARED_WORDS: u32 = 3400;

/// Wave numbers per workgroup of the thread-per-line kernel: 16 (96 threads) where their
/// pressure lines fit, fewer for long lines.
fn wave_numbers_per_group(n: u32) -> u32 {
    (SHARED_WORDS / (2 * n + 16)).clamp(1, 16)
}

/// Workgroup words the staged kernel's lines, tables and constants may take (of the 16 KiB
/// every adapter has).
const STAGED_WORDS: u32 = 4000;

/// Wave numbers a staged workgroup takes at most: 8 (48 lines, 203 workgroups at 10^4
/// spheres' 1624 wave numbers, more than an H100's 132 multiprocessors).
const STAGED_KS: u32 = 8;

/// Threads a staged workgroup has about (4 per line at 8 wave numbers).
const STAGED_THREADS: u32 = 192;

/// The staged kernel's shape for n points (shaders/chebyshev/slab_staged.wgsl's
/// constants).
#[derive(Clone, Copy, Debug, PartialEq)]
struct StagedShape {
    /// Wave numbers a workgroup.
    ks: u32,
    /// Threads a workgroup: a multiple of its 6 ks lines.
    wg: u32,
    /// Words between lines in workgroup memory: n rounded up to odd.
    stride: u32,
    /// Rows of chebyshev_bvp's tables read (all but the last, whether k is 0).
    rows: u32,
    /// Outputs of a dense transform per thread.
    outs: u32,
}

#[cfg(test)]
impl StagedShape {
    /// Workgroup words the kernel declares.
    fn words(&self) -> u32 {
        // lines, tables, pressure, pressure ends, the walls' constants (vec4), slopes.
        6 * self.ks * self.stride
            + self.rows * self.ks
            + 2 * self.ks * self.stride
            + 4 * self.ks
            + 12 * self.ks
            + 6 * self.ks
    }
}

fn staged_shape(n: u32) -> StagedShape {
    let stride = n | 1;
    let rows = chebyshev_bvp::table_rows(n as usize) as u32 - 1;
    let per_k = 8 * stride + rows + 22;
    let ks = (STAGED_WORDS / per_k).clamp(1, STAGED_KS);
    let lines = 6 * ks;
    let wg = lines * STAGED_THREADS.div_ceil(lines);
    StagedShape {
        ks,
        wg,
        stride,
        rows,
        outs: (lines * n).div_ceil(wg),
    }
}

/// Lanes a wave number of the `lanes` kernel takes at most (of the adapter's smallest
/// subgroup).
const LANES_SEG: u32 = 8;

/// Threads a workgroup of the `lanes` kernel.
const LANES_WG: u32 = 128;

/// The `lanes` kernel's shape for n points (shaders/chebyshev/slab_lanes.wgsl's constants).
#[derive(Clone, Copy, Debug, PartialEq)]
struct LanesShape {
    /// Lanes a wave number (a power of two, at most the smallest subgroup).
    seg: u32,
    /// Points a lane: even, seg per >= n.
    per: u32,
    /// Upper-half points a lane in the inverse transform: seg half >= (n + 1) / 2.
    half: u32,
    /// Threads a workgroup.
    wg: u32,
}

fn lanes_shape(n: u32, caps: &DeviceCaps) -> Result<LanesShape, String> {
    let seg = match caps.subgroups {
        Some((min, _)) if min.is_power_of_two() && min >= 2 => min.min(LANES_SEG),
        _ => {
            return Err(
                "slab_solve `lanes` needs subgroups (a power of two wide); this adapter has none"
                    .into(),
            );
        }
    };
    Ok(LanesShape {
        seg,
        per: 2 * n.div_ceil(2 * seg),
        half: n.div_ceil(2).div_ceil(seg),
        wg: LANES_WG,
    })
}

struct SlabSolve {
    lengths: [f64; 2],
    viscosity: f64,
    zmin: f64,
    zmax: f64,
    walls: u32,
    /// The `staged` kernel (slab_staged.wgsl) in place of the one of a thread per line.
    staged: bool,
    /// The input holds the forcing's values along z (staged only): the forward transform
    /// runs inside.
    values: bool,
    /// The `lanes` kernel (slab_lanes.wgsl): a wave number's line over a segment of
    /// subgroup lanes.
    lanes: bool,
}

impl SlabSolve {
    fn from_params(p: &Params) -> Result<Self, String> {
        let b = p.numbers("box");
        let (zmin, zmax) = (p.number("zmin"), p.number("zmax"));
        if zmax.partial_cmp(&zmin) != Some(std::cmp::Ordering::Greater) {
            return Err(format!("`zmax` {zmax} must be above `zmin` {zmin}"));
        }
        Ok(SlabSolve {
            lengths: [b[0], b[1]],
            viscosity: p.number("viscosity"),
            zmin,
            zmax,
            walls: stokes_slab::walls_code(p),
            staged: p.flag("staged"),
            values: p.flag("values"),
            lanes: p.flag("lanes"),
        })
        .and_then(|s| {
            if s.values && !s.staged {
                Err("`values` (the forcing's values along z) needs `staged`".into())
            } else if s.lanes && s.staged {
                Err("`lanes` and `staged` are two kernels: set one".into())
            } else {
                Ok(s)
            }
        })
    }
}

impl Node for SlabSolve {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let Some(ValueType::HalfComplexGrid { dims, comps }) = inputs[0] else {
            unreachable!("port type checked")
        };
        if comps != 3 {
            return Err(PortError::new(
                "f",
                format!("must have 3 components (the forcing), got {comps}"),
            ));
        }
        if dims[2] < 2 || dims[2] > MAX_POINTS {
            return Err(PortError::new(
                "f",
                format!(
                    "has {} Chebyshev coefficients along z: the fused solve takes 2 to {MAX_POINTS} (the chain of nodes takes more: slab \"chain\")",
                    dims[2]
                ),
            ));
        }
        Ok(Signature::outputs(vec![inputs[0].expect("required")]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let f = inputs[0].as_ref().expect("required");
        let coefficients;
        let f = if self.values {
            coefficients = chebyshev::transform_reference(f, true);
            &coefficients
        } else {
            f
        };
        outputs[0] = stokes_slab::chain_reference(
            self.lengths,
            self.viscosity,
            self.zmin,
            self.zmax,
            self.walls,
            f,
        );
    }
}

/// The kernel's uniform: shaders/stokes_slab/slab.wgsl's `Slab`, then the scales.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct SolveUniform {
    slab: stokes_slab::SlabUniform,
    f_scale: f32,
    bc_scale: f32,
    dz_scale: f32,
    pad2: u32,
}

impl GpuKernels for SlabSolve {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let f = io.inputs[0].expect("required");
        let ValueType::HalfComplexGrid { dims, .. } = f.ty else {
            unreachable!()
        };
        let half = half_dims(dims);
        let nk = (half[0] * half[1]) as usize;
        let n = dims[2] as usize;
        let height = self.zmax - self.zmin;
        let tau = 2.0 * std::f64::consts::PI;
        let uniform = SolveUniform {
            slab: stokes_slab::SlabUniform {
                nx: dims[0],
                ny: dims[1],
                nz: dims[2],
                nk: nk as u32,
                kx_unit: (tau / self.lengths[0]) as f32,
                ky_unit: (tau / self.lengths[1]) as f32,
                inv_eta: (1.0 / self.viscosity) as f32,
                scale: 1.0,
                height: height as f32,
                walls: self.walls,
                pad: [0; 2],
            },
            f_scale: (height * height / 4.0) as f32,
            bc_scale: (height / 2.0) as f32,
            dz_scale: (2.0 / height) as f32,
            pad2: 0,
        };
        let bvp = chebyshev_bvp::tables(&chebyshev_bvp::kappas(dims, self.lengths, height), n);
        let (wall_points, minv) =
            stokes_slab::wall_tables(self.lengths, self.zmin, self.zmax, self.walls, dims);
        let mut points: Vec<f32> = chebyshev::matrix(n, false)
            .iter()
            .map(|&v| v as f32)
            .collect();
        points.extend(wall_points);
        let (ks, wg, source) = if self.lanes {
            let l = lanes_shape(n as u32, cx.caps()).map_err(CompileError::Unsupported)?;
            let source = format!(
                "const WG: u32 = {}u;\nconst SEG: u32 = {}u;\nconst PER: u32 = {}u;\n\
                 const HALF: u32 = {}u;\nconst POINTS: u32 = {n}u;\n{}",
                l.wg,
                l.seg,
                l.per,
                l.half,
                cx.shader("chebyshev/slab_lanes.wgsl")?
            );
            (l.wg / l.seg, l.wg, source)
        } else if self.staged {
            let s = staged_shape(n as u32);
            points.extend(chebyshev::matrix(n, true).iter().map(|&v| v as f32));
            let source = format!(
                "const WG: u32 = {}u;\nconst KS: u32 = {}u;\nconst POINTS: u32 = {n}u;\n\
                 const LS: u32 = {}u;\nconst ROWS: u32 = {}u;\nconst OUTS: u32 = {}u;\n\
                 const FORWARD: bool = {};\n{}",
                s.wg,
                s.ks,
                s.stride,
                s.rows,
                s.outs,
                self.values,
                cx.shader("chebyshev/slab_staged.wgsl")?
            );
            (s.ks, s.wg, source)
        } else {
            let (ks, wg, file) = if n as u32 <= THREE_LINES_UP_TO {
                (
                    THREE_LINES_KS,
                    2 * THREE_LINES_KS,
                    "chebyshev/slab_solve.wgsl",
                )
            } else {
                let ks = wave_numbers_per_group(n as u32);
                (ks, 6 * ks, "chebyshev/slab_solve_line.wgsl")
            };
            let source = format!(
                "const WG: u32 = {wg}u;\nconst KS: u32 = {ks}u;\nconst POINTS: u32 = {n}u;\n{}{}",
                written_out_transform(n),
                cx.shader(file)?
            );
            (ks, wg, source)
        };
        let kernel = cx.kernel(&KernelSpec::new(
            if self.staged {
                "slab solve staged"
            } else if self.lanes {
                "slab solve lanes"
            } else {
                "slab solve"
            },
            source,
            &[
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::StorageRead,
                Binding::StorageRead,
                Binding::StorageRead,
                Binding::Uniform,
            ],
        ))?;
        let bvp = cx.table("slab solve bvp tables", bytemuck::cast_slice(&bvp));
        let points = cx.table("slab solve point tables", bytemuck::cast_slice(&points));
        let minv = cx.table("slab solve slit tables", bytemuck::cast_slice(&minv));
        let u = cx.uniform("slab solve shape", bytemuck::bytes_of(&uniform));
        let groups = (nk as u64).div_ceil(ks as u64);
        Ok(vec![cx.dispatch(
            &kernel,
            &[f.buffer, io.outputs[0].buffer, &bvp, &points, &minv, &u],
            cx.grid_1d(groups * wg as u64, wg),
        )])
    }
}

pub fn register(r: &mut Registry) {
    r.add(
        NodeKind::declare(
            "slab_solve",
            "the doubly periodic Stokes solve between the Chebyshev transforms in one kernel: from the forcing's Chebyshev coefficients along z (half spectrum in x, y) to the velocity's values at the Chebyshev points with the walls, as the chain chebyshev_derivative, slab_pressure_source, chebyshev_bvp, chebyshev_derivative, slab_velocity_source, chebyshev_bvp, chebyshev (inverse), slab_walls computes it (up to 32 points: 2 threads a wave number, one per part, each with its part's three velocity lines side by side in registers and the whole pressure; past 32: 6 threads a wave number, a line each, the pressure through workgroup memory; the end values through workgroup memory; per-k tables in f64 on the host); 2 to 160 points along z",
        )
        .input(PortSpec::new(
            "f",
            PortType::HalfComplexGrid,
            "the forcing's Chebyshev coefficients (3 components), or its values along z with `values`",
        ))
        .output(PortSpec::new(
            "out",
            PortType::HalfComplexGrid,
            "the velocity with the walls, values along z (3 components): irfft's input",
        ))
        .param(stokes_slab::box_param())
        .param(ParamSpec::f32_positive("viscosity", Some(1.0), "solvent viscosity eta"))
        .param(ParamSpec::number("zmin", Some(-1.0), -1e18, 1e18, "the bottom of the domain (the bottom wall)"))
        .param(ParamSpec::number("zmax", Some(1.0), -1e18, 1e18, "the top of the domain (the slit's top wall)"))
        .param(stokes_slab::walls_param())
        .param(ParamSpec::flag(
            "staged",
            false,
            "the staged kernel: 8 wave numbers a workgroup staged in workgroup memory with their tables, the dense transforms spread over 4 threads a line (for grids with few wave numbers, where the default kernel's serial chain per thread sets its time); else the kernel of 2 threads a wave number (three lines a thread) up to 32 points, of 6 (a line a thread) past them",
        ))
        .param(ParamSpec::flag(
            "lanes",
            false,
            "the lanes kernel: a wave number's z line over a segment of up to 8 subgroup lanes, the solves' recurrences as scans by shuffles (for grids with few wave numbers, where a thread's serial chain along z sets the kernel's time; needs subgroups)",
        ))
        .param(ParamSpec::flag(
            "values",
            false,
            "f holds the forcing's values along z (rfft's output) instead of its coefficients: the forward Chebyshev transform runs inside (staged only)",
        ))
        .build(|p| Ok(Box::new(SlabSolve::from_params(p)?))),
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The thread-per-line kernel's shared lines fit the workgroup memory every adapter
    /// has, at every length it takes (past THREE_LINES_UP_TO).
    #[test]
    fn the_shared_lines_fit() {
        for n in THREE_LINES_UP_TO + 1..=MAX_POINTS {
            let ks = wave_numbers_per_group(n);
            assert!(ks >= 1 && ks * (2 * n + 16) <= SHARED_WORDS, "n {n}: {ks}");
        }
        assert_eq!(wave_numbers_per_group(35), 16);
    }

    /// The lanes kernel's segment covers every length it takes with an even count of
    /// points a lane (its scans keep a parity per element index), its transform's upper
    /// half too, on subgroups of 4 to 128 lanes; none without subgroups.
    #[test]
    fn the_lanes_segment_covers_the_line() {
        let caps = |s: Option<(u32, u32)>| DeviceCaps {
            subgroups: s,
            ..DeviceCaps::baseline()
        };
        for min in [4, 8, 16, 32, 64, 128] {
            for n in 2..=MAX_POINTS {
                let l = lanes_shape(n, &caps(Some((min, 128)))).unwrap();
                assert!(l.seg <= min && l.seg.is_power_of_two(), "{min} {n}: {l:?}");
                assert!(
                    l.per.is_multiple_of(2) && l.seg * l.per >= n,
                    "{min} {n}: {l:?}"
                );
                assert!(l.seg * l.half >= n.div_ceil(2), "{min} {n}: {l:?}");
                assert!(
                    l.wg.is_multiple_of(l.seg) && l.wg <= 256,
                    "{min} {n}: {l:?}"
                );
            }
        }
        assert!(lanes_shape(31, &caps(None)).is_err());
        assert!(lanes_shape(31, &caps(Some((12, 12)))).is_err());
    }

    /// The staged kernel's workgroup memory fits the 16 KiB every adapter has, its
    /// threads are a multiple of its lines, its dense transforms' outputs all taken.
    #[test]
    fn the_staged_workgroup_fits() {
        for n in 2..=MAX_POINTS {
            let s = staged_shape(n);
            assert!(s.words() <= STAGED_WORDS, "n {n}: {s:?}");
            assert!(
                s.ks >= 1 && s.wg.is_multiple_of(6 * s.ks) && s.wg <= 256,
                "n {n}: {s:?}"
            );
            assert!(s.outs * s.wg >= 6 * s.ks * n, "n {n}: {s:?}");
            assert_eq!(s.stride % 2, 1);
        }
        let s = staged_shape(31);
        assert_eq!((s.ks, s.wg, s.outs), (8, 192, 8));
    }
}
