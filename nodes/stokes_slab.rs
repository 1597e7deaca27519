//! The steps of the doubly periodic Stokes solver between its Chebyshev transforms (UAMMD
//! thesis section 23; digest sections 7.2 to 7.4). Every grid is a half spectrum in x, y
//! (`rfft` over "xy") of dims [nx, ny, nz], word 2 ((c nz + z) nk + k) + part with
//! nk = (nx / 2 + 1) ny; along z either Chebyshev coefficients or values at the
//! Chebyshev-Gauss-Lobatto points (j = 0 the top, `chebyshev`'s layout). k = (kx, ky) =
//! 2 pi (x / Lx, y / Ly) with signed y; i k is zero on an unpaired Nyquist index.
//!
//! The free-space solve is p'' - k^2 p = i k.f + df_z/dz with decaying boundary conditions,
//! then eta (v'' - k^2 v) = (i k p, dp/dz) - f with the conditions that match the force-free
//! solution outside the slab: (d/dz + |k|) v(top) = alpha, (d/dz - |k|) v(bottom) = beta,
//! alpha = (-i k p(top) / (2 eta |k|), p(top) / (2 eta)), beta = (i k p(bottom) /
//! (2 eta |k|), p(bottom) / (2 eta)) (derived from p = P e^{-|k| z} above the slab, whose
//! particular velocity is z e^{-|k| z} times (-i k P / (2 eta |k|), P / (2 eta))).
//! `chebyshev_bvp` does both solves; these nodes form their sources and boundary values,
//! add the walls, and take curls:
//!
//! - `slab_pressure_source`: i k.f + (df/dz)_z from f and its derivative's coefficients.
//! - `slab_velocity_source`: ((i k p - f) / eta, (dp/dz - f_z) / eta) and the boundary
//!   values above (zero at k = 0: Dirichlet zero there).
//! - `slab_walls` (`walls`: none, bottom, slit), on values along z: for k != 0 adds the
//!   homogeneous Stokes solution that cancels the free-space velocity on the walls,
//!   [a zeta (-i k, |k|) + C] e^{-|k| zeta} + [b zeta (i k, |k|) + D] e^{|k| (zeta - Lz)},
//!   zeta = z - zmin, with a = C_z - i k.C / |k| and b = -D_z - i k.D / |k| (which make it
//!   divergence-free; its pressure is 2 eta |k| (a e^{-|k| zeta} + b e^{|k| (zeta - Lz)})).
//!   Bottom: C = -v(zmin), D = 0. Slit: (C, D) from the six wall values through a 6 x 6
//!   complex inverse per k built in f64 on the host, the growing exponential already scaled
//!   by e^{-|k| Lz} so nothing overflows. k = 0: with no wall the mode is dropped (open z: a
//!   net in-plane force per height has no bounded flow; velocities are relative to the mean
//!   flow, as in periodic FCM); bottom: v_par'' = -f_par / eta with v(zmin) = 0 and
//!   dv/dz(zmax) = 0 (bounded above): the free-space solution plus the linear function
//!   that meets both, -v(zmin) + s zeta with s = -dv/dz(zmax); slit: plus the linear
//!   function that zeroes both walls; v_z = 0 at k = 0 with a wall (no net flow through
//!   it).
//! - `slab_curl`: scale x curl from a field's coefficients and its z derivative's:
//!   (i ky v_z - dv_y/dz, dv_x/dz - i kx v_z, i kx v_y - i ky v_x).

use rustfft::num_complex::Complex64 as C64;

use crate::gpu::{
    Binding, CompileCtx, CompileError, DeviceCaps, Dispatch, KernelSpec, NodeIo, WG_1D,
};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamKind, ParamSpec, Params, PortError, PortSpec,
    RefCtx, Registry, Signature,
};
use crate::value::{PortType, RefArray, ValueType, half_dims};

use super::chebyshev;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Step {
    PressureSource,
    VelocitySource,
    Walls,
    Curl,
}

/// Wall modes, in the kernel's code order.
const WALLS: &[&str] = &["none", "bottom", "slit"];

/// The periodic lengths of a doubly periodic node (its wave numbers).
pub(crate) fn box_param() -> ParamSpec {
    ParamSpec {
        name: "box",
        kind: ParamKind::Numbers {
            len: Some(2),
            min: f64::MIN_POSITIVE,
            max: 1e18,
        },
        default: None,
        doc: "the periodic lengths [Lx, Ly] (the wave numbers)",
    }
}

struct Slab {
    step: Step,
    lengths: [f64; 2],
    viscosity: f64,
    zmin: f64,
    zmax: f64,
    walls: u32,
    scale: f64,
}

impl Slab {
    fn from_params(step: Step, p: &Params) -> Result<Self, String> {
        let b = p.numbers("box");
        let get = |name: &str, default: f64| match p.get(name) {
            Some(crate::expr::ParamValue::Number(x)) => *x,
            _ => default,
        };
        let (zmin, zmax) = (get("zmin", -1.0), get("zmax", 1.0));
        if zmax.partial_cmp(&zmin) != Some(std::cmp::Ordering::Greater) {
            return Err(format!("`zmax` {zmax} must be above `zmin` {zmin}"));
        }
        let walls = walls_code(p);
        Ok(Slab {
            step,
            lengths: [b[0], b[1]],
            viscosity: get("viscosity", 1.0),
            zmin,
            zmax,
            walls,
            scale: get("scale", 1.0),
        })
    }

    fn waves(&self, dims: [u32; 3]) -> Vec<([f64; 2], [bool; 2])> {
        super::spectral::plane_waves(dims, self.lengths)
    }

    /// zeta_j = z_j - zmin at the Chebyshev points of `n`.
    fn zetas(&self, n: usize) -> Vec<f64> {
        let half = (self.zmax - self.zmin) / 2.0;
        chebyshev::points(n)
            .iter()
            .map(|x| half * (1.0 + x))
            .collect()
    }

    /// The weights of dv/dz at the top (j = 0) from the values at the points: the
    /// interpolant's coefficients c = M v, then sum_k k^2 c_k (T_k'(1) = k^2), times 2/Lz.
    fn top_derivative_row(&self, n: usize) -> Vec<f64> {
        let m = chebyshev::matrix(n, true);
        let scale = 2.0 / (self.zmax - self.zmin);
        (0..n)
            .map(|j| (0..n).map(|k| (k * k) as f64 * m[k * n + j]).sum::<f64>() * scale)
            .collect()
    }
}

/// The f64 reference of the chain from the forcing's Chebyshev coefficients `f` (3
/// components, a half spectrum over [Lx, Ly]) to the velocity's values along z with the
/// walls (`walls`: 0 none, 1 bottom, 2 slit), node by node as graphs/lib/
/// dpstokes_mobility.json runs them: chebyshev_derivative (f_z), slab_pressure_source,
/// chebyshev_bvp, chebyshev_derivative, slab_velocity_source, chebyshev_bvp with the
/// boundary values, the inverse chebyshev, slab_walls (`slab_solve`'s reference).
pub(crate) fn chain_reference(
    lengths: [f64; 2],
    viscosity: f64,
    zmin: f64,
    zmax: f64,
    walls: u32,
    f: &RefArray,
) -> RefArray {
    let (dims, _) = half_spectrum(&Some(f.ty)).expect("a half spectrum");
    let nz = dims[2] as usize;
    let height = zmax - zmin;
    let grid = |comps: u32, data: Vec<f64>| {
        RefArray::new(ValueType::HalfComplexGrid { dims, comps }, data)
    };
    let step = |step: Step| Slab {
        step,
        lengths,
        viscosity,
        zmin,
        zmax,
        walls,
        scale: 1.0,
    };
    let plane = f.data.len() / (3 * nz);
    let scale = 2.0 / height;
    let dfz = chebyshev::derivative_reference(f, 2, 1, scale);
    let mut source = [grid(1, vec![0.0; nz * plane])];
    step(Step::PressureSource).reference(&[Some(f.clone()), Some(dfz)], &mut source);
    let [source] = source;
    let p = super::chebyshev_bvp::reference(lengths, height, &source, None);
    let dp = chebyshev::derivative_reference(&p, 0, 0, scale);
    let mut sources = [
        grid(3, vec![0.0; 3 * nz * plane]),
        RefArray::new(
            ValueType::HalfComplexGrid {
                dims: [dims[0], dims[1], 2],
                comps: 3,
            },
            vec![0.0; 3 * 2 * plane],
        ),
    ];
    step(Step::VelocitySource).reference(&[Some(f.clone()), Some(p), Some(dp)], &mut sources);
    let [rhs, boundary] = sources;
    let v = super::chebyshev_bvp::reference(lengths, height, &rhs, Some(&boundary));
    let values = chebyshev::transform_reference(&v, false);
    let mut out = [grid(3, vec![0.0; 3 * nz * plane])];
    step(Step::Walls).reference(&[Some(values)], &mut out);
    let [out] = out;
    out
}

/// The per-k and per-point tables of the walls in f32: zeta_j and the top derivative row
/// (n each), and for the slit the 6 x 6 complex inverse per k, word ((r 6 + c) 2 + part)
/// nk + k after them (shaders/stokes_slab/walls.wgsl, slab_solve.wgsl).
pub(crate) fn wall_tables(
    lengths: [f64; 2],
    zmin: f64,
    zmax: f64,
    walls: u32,
    dims: [u32; 3],
) -> (Vec<f32>, Vec<f32>) {
    let s = Slab {
        step: Step::Walls,
        lengths,
        viscosity: 1.0,
        zmin,
        zmax,
        walls,
        scale: 1.0,
    };
    let nz = dims[2] as usize;
    let mut points: Vec<f32> = s.zetas(nz).iter().map(|&z| z as f32).collect();
    points.extend(s.top_derivative_row(nz).iter().map(|&w| w as f32));
    let mut per_k = Vec::new();
    if walls == 2 {
        let waves = s.waves(dims);
        let nk = waves.len();
        per_k.resize(72 * nk, 0.0);
        let height = zmax - zmin;
        for (kk, (k, _)) in waves.into_iter().enumerate() {
            if k == [0.0, 0.0] {
                continue;
            }
            let m = slit_inverse(k, height);
            for (r, row) in m.iter().enumerate() {
                for (c, x) in row.iter().enumerate() {
                    let w = (r * 6 + c) * 2;
                    per_k[w * nk + kk] = x.re as f32;
                    per_k[(w + 1) * nk + kk] = x.im as f32;
                }
            }
        }
    }
    (points, per_k)
}

/// The `walls` param of the nodes that add the walls' flow.
pub(crate) fn walls_param() -> ParamSpec {
    ParamSpec::choice(
        "walls",
        "none",
        WALLS,
        "none (open z), bottom (no slip at zmin), slit (no slip at zmin and zmax)",
    )
}

/// The wall mode's code (0 none, 1 bottom, 2 slit) of a node's `walls` param.
pub(crate) fn walls_code(p: &Params) -> u32 {
    match p.get("walls") {
        Some(crate::expr::ParamValue::Text(w)) => {
            WALLS.iter().position(|x| x == w).expect("choice checked") as u32
        }
        _ => 0,
    }
}

/// The 6 x 6 map of the slit's unknowns (C, D) to the wall values (bottom, top) at one k,
/// and its inverse (f64; Gaussian elimination with partial pivoting).
fn slit_inverse(k: [f64; 2], height: f64) -> [[C64; 6]; 6] {
    let kabs = (k[0] * k[0] + k[1] * k[1]).sqrt();
    let e = (-kabs * height).exp();
    let i = C64::new(0.0, 1.0);
    let mut m = [[C64::new(0.0, 0.0); 6]; 6];
    for col in 0..6 {
        let mut x = [C64::new(0.0, 0.0); 6];
        x[col] = C64::new(1.0, 0.0);
        let (c, d) = (&x[..3], &x[3..]);
        let a = c[2] - i * (k[0] * c[0] + k[1] * c[1]) / kabs;
        let b = -d[2] - i * (k[0] * d[0] + k[1] * d[1]) / kabs;
        for r in 0..3 {
            // zeta = 0: C + D e^{-|k| Lz}; zeta = Lz: [a Lz (-i k, |k|) + C] e + b Lz (i k, |k|) + D.
            m[r][col] = c[r] + d[r] * e;
            let (sa, sb) = if r < 2 {
                (-i * k[r], i * k[r])
            } else {
                (C64::new(kabs, 0.0), C64::new(kabs, 0.0))
            };
            m[3 + r][col] = (a * height * sa + c[r]) * e + b * height * sb + d[r];
        }
    }
    invert6(m)
}

fn invert6(mut a: [[C64; 6]; 6]) -> [[C64; 6]; 6] {
    let mut inv = [[C64::new(0.0, 0.0); 6]; 6];
    for (r, row) in inv.iter_mut().enumerate() {
        row[r] = C64::new(1.0, 0.0);
    }
    for c in 0..6 {
        let p = (c..6)
            .max_by(|&x, &y| a[x][c].norm().total_cmp(&a[y][c].norm()))
            .expect("rows");
        a.swap(c, p);
        inv.swap(c, p);
        let pivot = a[c][c];
        for j in 0..6 {
            a[c][j] /= pivot;
            inv[c][j] /= pivot;
        }
        for r in 0..6 {
            if r != c {
                let f = a[r][c];
                for j in 0..6 {
                    let (ac, ic) = (a[c][j], inv[c][j]);
                    a[r][j] -= f * ac;
                    inv[r][j] -= f * ic;
                }
            }
        }
    }
    inv
}

/// Reads and writes complex words of a half spectrum's data.
struct Spectrum<'a> {
    data: &'a [f64],
    nz: usize,
    nk: usize,
}

impl Spectrum<'_> {
    fn at(&self, c: usize, z: usize, k: usize) -> C64 {
        let w = 2 * ((c * self.nz + z) * self.nk + k);
        C64::new(self.data[w], self.data[w + 1])
    }
}

fn put(out: &mut [f64], nz: usize, nk: usize, c: usize, z: usize, k: usize, v: C64) {
    let w = 2 * ((c * nz + z) * nk + k);
    out[w] = v.re;
    out[w + 1] = v.im;
}

fn half_spectrum(t: &Option<ValueType>) -> Option<([u32; 3], u32)> {
    match *t {
        Some(ValueType::HalfComplexGrid { dims, comps }) => Some((dims, comps)),
        _ => None,
    }
}

impl Slab {
    fn input_names(&self) -> &'static [&'static str] {
        match self.step {
            Step::PressureSource => &["f", "df"],
            Step::VelocitySource => &["f", "p", "dp"],
            Step::Walls => &["v"],
            Step::Curl => &["x", "dx"],
        }
    }

    /// The components each input must have.
    fn input_comps(&self) -> &'static [u32] {
        match self.step {
            Step::PressureSource => &[3, 1],
            Step::VelocitySource => &[3, 1, 1],
            Step::Walls => &[3],
            Step::Curl => &[3, 3],
        }
    }

    #[allow(clippy::needless_range_loop)]
    fn reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray]) {
        let (dims, _) = half_spectrum(&inputs[0].as_ref().map(|a| a.ty)).expect("checked");
        let nz = dims[2] as usize;
        let waves = self.waves(dims);
        let nk = waves.len();
        let spec = |i: usize| Spectrum {
            data: &inputs[i].as_ref().expect("required").data,
            nz,
            nk,
        };
        let i = C64::new(0.0, 1.0);
        let paired = |k: [f64; 2], nyq: [bool; 2]| [0, 1].map(|a| if nyq[a] { 0.0 } else { k[a] });
        match self.step {
            Step::PressureSource => {
                let (f, df) = (spec(0), spec(1));
                for (kk, &(k, nyq)) in waves.iter().enumerate() {
                    let q = paired(k, nyq);
                    for z in 0..nz {
                        let v =
                            i * (q[0] * f.at(0, z, kk) + q[1] * f.at(1, z, kk)) + df.at(0, z, kk);
                        put(&mut outputs[0].data, nz, nk, 0, z, kk, v);
                    }
                }
            }
            Step::VelocitySource => {
                let (f, p, dp) = (spec(0), spec(1), spec(2));
                let eta = self.viscosity;
                let (rhs, rest) = outputs.split_at_mut(1);
                for (kk, &(k, nyq)) in waves.iter().enumerate() {
                    let q = paired(k, nyq);
                    let (mut top, mut bottom) = (C64::new(0.0, 0.0), C64::new(0.0, 0.0));
                    for z in 0..nz {
                        let pz = p.at(0, z, kk);
                        top += pz;
                        bottom += if z % 2 == 1 { -pz } else { pz };
                        for c in 0..3 {
                            let drive = if c == 2 {
                                dp.at(0, z, kk)
                            } else {
                                i * q[c] * pz
                            };
                            put(
                                &mut rhs[0].data,
                                nz,
                                nk,
                                c,
                                z,
                                kk,
                                (drive - f.at(c, z, kk)) / eta,
                            );
                        }
                    }
                    let kabs = (k[0] * k[0] + k[1] * k[1]).sqrt();
                    let zero = C64::new(0.0, 0.0);
                    for c in 0..3 {
                        let (alpha, beta) = if kabs == 0.0 {
                            (zero, zero)
                        } else if c < 2 {
                            (
                                -i * q[c] * top / (2.0 * eta * kabs),
                                i * q[c] * bottom / (2.0 * eta * kabs),
                            )
                        } else {
                            (top / (2.0 * eta), bottom / (2.0 * eta))
                        };
                        put(&mut rest[0].data, 2, nk, c, 0, kk, alpha);
                        put(&mut rest[0].data, 2, nk, c, 1, kk, beta);
                    }
                }
            }
            Step::Walls => {
                let v = spec(0);
                let zeta = self.zetas(nz);
                let row = self.top_derivative_row(nz);
                let height = self.zmax - self.zmin;
                let out = &mut outputs[0].data;
                for (kk, &(k, _)) in waves.iter().enumerate() {
                    let kabs = (k[0] * k[0] + k[1] * k[1]).sqrt();
                    let zero = C64::new(0.0, 0.0);
                    if kabs == 0.0 {
                        let slope: Vec<C64> = (0..2)
                            .map(|c| -(0..nz).map(|j| row[j] * v.at(c, j, kk)).sum::<C64>())
                            .collect();
                        for j in 0..nz {
                            let t = zeta[j] / height;
                            for c in 0..3 {
                                let x = match (self.walls, c) {
                                    (0, _) | (_, 2) => zero,
                                    (1, _) => {
                                        v.at(c, j, kk) - v.at(c, nz - 1, kk) + zeta[j] * slope[c]
                                    }
                                    _ => {
                                        v.at(c, j, kk)
                                            - v.at(c, nz - 1, kk) * (1.0 - t)
                                            - v.at(c, 0, kk) * t
                                    }
                                };
                                put(out, nz, nk, c, j, kk, x);
                            }
                        }
                        continue;
                    }
                    let (mut cc, mut dd) = ([zero; 3], [zero; 3]);
                    if self.walls >= 1 {
                        for c in 0..3 {
                            cc[c] = -v.at(c, nz - 1, kk);
                        }
                    }
                    if self.walls == 2 {
                        let minv = slit_inverse(k, height);
                        let u: Vec<C64> = (0..6)
                            .map(|r| {
                                if r < 3 {
                                    -v.at(r, nz - 1, kk)
                                } else {
                                    -v.at(r - 3, 0, kk)
                                }
                            })
                            .collect();
                        for r in 0..3 {
                            cc[r] = (0..6).map(|c| minv[r][c] * u[c]).sum();
                            dd[r] = (0..6).map(|c| minv[3 + r][c] * u[c]).sum();
                        }
                    }
                    let a = cc[2] - i * (k[0] * cc[0] + k[1] * cc[1]) / kabs;
                    let b = -dd[2] - i * (k[0] * dd[0] + k[1] * dd[1]) / kabs;
                    for j in 0..nz {
                        let z = zeta[j];
                        let (decay, grow) = ((-kabs * z).exp(), (kabs * (z - height)).exp());
                        for c in 0..3 {
                            let (sa, sb) = if c < 2 {
                                (-i * k[c], i * k[c])
                            } else {
                                (C64::new(kabs, 0.0), C64::new(kabs, 0.0))
                            };
                            let corr = (a * z * sa + cc[c]) * decay + (b * z * sb + dd[c]) * grow;
                            put(out, nz, nk, c, j, kk, v.at(c, j, kk) + corr);
                        }
                    }
                }
            }
            Step::Curl => {
                let (x, dx) = (spec(0), spec(1));
                let out = &mut outputs[0].data;
                for (kk, &(k, nyq)) in waves.iter().enumerate() {
                    let q = paired(k, nyq);
                    for z in 0..nz {
                        let (vx, vy, vz) = (x.at(0, z, kk), x.at(1, z, kk), x.at(2, z, kk));
                        let w = [
                            i * q[1] * vz - dx.at(1, z, kk),
                            dx.at(0, z, kk) - i * q[0] * vz,
                            i * (q[0] * vy - q[1] * vx),
                        ];
                        for (c, w) in w.into_iter().enumerate() {
                            put(out, nz, nk, c, z, kk, self.scale * w);
                        }
                    }
                }
            }
        }
    }
}

impl Node for Slab {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let names = self.input_names();
        let (dims, _) = half_spectrum(&inputs[0]).expect("port type checked");
        for ((name, want), t) in names.iter().zip(self.input_comps()).zip(inputs) {
            let Some((d, comps)) = half_spectrum(t) else {
                unreachable!("port type checked")
            };
            if d != dims || comps != *want {
                return Err(PortError::new(
                    *name,
                    format!(
                        "must be a half spectrum of {}x{}x{} cells with {want} components, got {}",
                        dims[0],
                        dims[1],
                        dims[2],
                        t.expect("required")
                    ),
                ));
            }
        }
        if dims[2] < 2 {
            return Err(PortError::new(
                names[0],
                "needs at least 2 points along z".to_string(),
            ));
        }
        let grid = |d: [u32; 3], comps: u32| ValueType::HalfComplexGrid { dims: d, comps };
        Ok(Signature::outputs(match self.step {
            Step::PressureSource => vec![grid(dims, 1)],
            Step::VelocitySource => vec![grid(dims, 3), grid([dims[0], dims[1], 2], 3)],
            Step::Walls | Step::Curl => vec![grid(dims, 3)],
        }))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        self.reference(inputs, outputs);
    }
}

/// The kernels' uniform (shaders/stokes_slab/slab.wgsl).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct SlabUniform {
    pub nx: u32,
    pub ny: u32,
    pub nz: u32,
    pub nk: u32,
    pub kx_unit: f32,
    pub ky_unit: f32,
    pub inv_eta: f32,
    pub scale: f32,
    pub height: f32,
    pub walls: u32,
    pub pad: [u32; 2],
}

impl GpuKernels for Slab {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let first = io.inputs[0].expect("required");
        let (dims, _) = half_spectrum(&Some(first.ty)).expect("checked");
        let half = half_dims(dims);
        let (nk, nz) = ((half[0] * half[1]) as usize, dims[2] as usize);
        let tau = 2.0 * std::f64::consts::PI;
        let uniform = SlabUniform {
            nx: dims[0],
            ny: dims[1],
            nz: dims[2],
            nk: nk as u32,
            kx_unit: (tau / self.lengths[0]) as f32,
            ky_unit: (tau / self.lengths[1]) as f32,
            inv_eta: (1.0 / self.viscosity) as f32,
            scale: self.scale as f32,
            height: (self.zmax - self.zmin) as f32,
            walls: self.walls,
            pad: [0; 2],
        };
        let (name, file) = match self.step {
            Step::PressureSource => ("slab pressure source", "stokes_slab/pressure_source.wgsl"),
            Step::VelocitySource => ("slab velocity source", "stokes_slab/velocity_source.wgsl"),
            Step::Walls => ("slab walls", "stokes_slab/walls.wgsl"),
            Step::Curl => ("slab curl", "stokes_slab/curl.wgsl"),
        };
        let u = cx.uniform(name, bytemuck::bytes_of(&uniform));
        let mut bindings = vec![Binding::StorageRead; io.inputs.len()];
        bindings.extend(vec![Binding::StorageReadWrite; io.outputs.len()]);
        let mut buffers: Vec<&wgpu::Buffer> = io
            .inputs
            .iter()
            .map(|b| b.expect("required").buffer)
            .collect();
        buffers.extend(io.outputs.iter().map(|o| o.buffer));
        let table;
        if self.step == Step::Walls {
            let (mut words, per_k) =
                wall_tables(self.lengths, self.zmin, self.zmax, self.walls, dims);
            words.extend(per_k);
            table = cx.table("slab walls tables", bytemuck::cast_slice(&words));
            bindings.push(Binding::StorageRead);
            buffers.push(&table);
        }
        bindings.push(Binding::Uniform);
        buffers.push(&u);
        let kernel = cx.kernel(&KernelSpec::new(name, cx.shader(file)?, &bindings))?;
        // One thread per (z, k) in every step.
        let threads = (nk * nz) as u64;
        Ok(vec![cx.dispatch(
            &kernel,
            &buffers,
            cx.grid_1d(threads, WG_1D),
        )])
    }
}

/// The half-width of the ES window (shape `beta`) whose rotational self-mobility is
/// 1 / (8 pi eta a^3): with the torque spread as half the curl of the window, mu_r =
/// (1 / (6 eta)) int phi^2 d^3x (Parseval), and a unit-integral ES of half-width alpha has
/// int phi_1d^2 dx = I(2 beta) / (alpha I(beta)^2), I the shape's integral over a unit
/// half-width (its square is the shape of 2 beta); so alpha = a (4 pi / 3)^(1/3) I(2 beta)
/// / I(beta)^2. (The Gaussian's twin is a / (6 sqrt(pi))^(1/3).)
pub fn es_torque_half_width(radius: f64, beta: f64) -> f64 {
    use crate::nodes::spread::window::es_integral;
    let i = es_integral(beta, 1.0);
    radius * (4.0 * std::f64::consts::PI / 3.0).cbrt() * es_integral(2.0 * beta, 1.0) / (i * i)
}

/// The reference for the open mode (no wall): the self-mobility (xx, zz; eta = 1) of a
/// separable window in a fluid periodic in x, y (sides lx, ly) and unbounded in z,
/// without the in-plane k = 0 mode, (1 / (lx ly)) sum over k_par != 0 of int dkz / (2 pi)
/// |phi^(k)|^2 (1 - k_a^2 / k^2) / k^2, with phi^ the window's 1-D transform (`phi_hat`,
/// negligible beyond `kmax`); f64, the kz integral by the trapezoid rule on 4000 steps.
pub fn open_self_mobility(phi_hat: impl Fn(f64) -> f64, kmax: f64, lx: f64, ly: f64) -> (f64, f64) {
    use std::f64::consts::PI;
    let (nx, ny) = (
        (kmax * lx / (2.0 * PI)).ceil() as i64,
        (kmax * ly / (2.0 * PI)).ceil() as i64,
    );
    let nz = 4000;
    let dkz = kmax / nz as f64;
    let square = |k: f64| phi_hat(k).powi(2);
    let along_z: Vec<f64> = (0..=nz).map(|m| square(m as f64 * dkz)).collect();
    let along = |n: i64, l: f64| -> Vec<f64> {
        (-n..=n).map(|i| square(2.0 * PI * i as f64 / l)).collect()
    };
    let (sx, sy) = (along(nx, lx), along(ny, ly));
    let (mut xx, mut zz) = (0.0, 0.0);
    for i in -nx..=nx {
        for j in -ny..=ny {
            let (kx, ky) = (2.0 * PI * i as f64 / lx, 2.0 * PI * j as f64 / ly);
            let q2 = kx * kx + ky * ky;
            if (i == 0 && j == 0) || q2 > kmax * kmax {
                continue;
            }
            let plane = sx[(i + nx) as usize] * sy[(j + ny) as usize];
            for (m, sz) in along_z.iter().enumerate() {
                let kz = m as f64 * dkz;
                let k2 = q2 + kz * kz;
                let w = if m == 0 { 0.5 } else { 1.0 } * dkz / PI;
                let g = plane * sz / k2 * w;
                xx += g * (1.0 - kx * kx / k2);
                zz += g * (1.0 - kz * kz / k2);
            }
        }
    }
    (xx / (lx * ly), zz / (lx * ly))
}

/// The ES shape per cell the window spans, beta / w, of the doubly periodic windows. With
/// the half-width a length the grid resolves the window at exactly w cells (FCM's ES
/// ties the cell to the window instead), and a softer shape than FCM's 2.3 aliases less:
/// the open-mode self-mobility at 1e-3 (w = 5, box 16, tests/it/dpstokes.rs's three
/// placements, on a cell face and near the padded top among them) was off by at most
/// 2.2e-3 at 2.3, 2.7e-4 at 1.7, 1.8e-4 at 1.8, 1.1e-4 at 1.9 and 3e-4 at 2.0 and 2.1
/// (lavapipe, f32). libMobility's DPStokes uses 1.714 at w = 6.
pub const ES_BETA_PER_CELL: f64 = 1.9;

/// The doubly periodic Stokes plan (graphs/dpstokes.json). Windows, forces and torques
/// apart (the torques' narrower, and resolved by the grid only with `rotation`):
/// - `es` (the default): exponential-of-semicircle windows with a half-width as a length,
///   so the hydrodynamic radius is exactly a on whatever grid the FFT-friendly rounding
///   gives. Forces: w = `fcm::plan::es_support` cells across (FCM's ES rule: 5 at 1e-3)
///   at beta = `ES_BETA_PER_CELL` w, the half-width a / (a / alpha of that shape,
///   `fcm::plan::es_window_radius`); torques: w + 1 cells (rotation has no 1/k^2 to damp
///   aliasing), the half-width from the rotational mobility (`es_torque_half_width`). The
///   cell is the width over its cells.
/// - `gaussian`: FCM's Gaussians, a / sqrt(pi) (forces) and a / (6 sqrt(pi))^(1/3)
///   (torques), FCM's cells per standard deviation at the tolerance
///   (`fcm::plan::gaussian_upsampling`, of the torque width with `rotation`), supports by
///   the window library's Gaussian rule.
///
/// Then: cells FFT-friendly in x and y, at most the cell above; the Chebyshev domain
/// [zmin, zmax] padded by the half support on each open side (none: both; bottom: above);
/// points so the spacing at mid-height, (Lz / 2) pi / (points - 1), is at most the x
/// cell. Returns [nx, ny, points, zlo, zhi, support, torque_support, width,
/// torque_width, beta, torque_beta]: width the Gaussian's standard deviation or the ES
/// half-width, beta 0 for the Gaussian.
#[allow(clippy::too_many_arguments)]
pub fn plan(
    lengths: &[f64],
    radius: f64,
    tolerance: f64,
    zmin: f64,
    zmax: f64,
    walls: &str,
    rotation: bool,
    kernel: &str,
) -> Result<Vec<f64>, String> {
    use crate::nodes::fcm::plan::{
        es_support, es_window_radius, gaussian_upsampling, gaussian_width, torque_width,
    };
    use crate::nodes::spread::window::{Window, gaussian_support};
    if lengths.len() != 2 {
        return Err(format!(
            "box must be [Lx, Ly], got {} lengths",
            lengths.len()
        ));
    }
    if zmax.partial_cmp(&zmin) != Some(std::cmp::Ordering::Greater) || !(zmax - zmin).is_finite() {
        return Err(format!("zmax ({zmax}) must lie above zmin ({zmin})"));
    }
    let Some(wall_code) = WALLS.iter().position(|w| *w == walls) else {
        return Err(format!("walls must be none, bottom or slit, got `{walls}`"));
    };
    // Per window: width, beta, and the cell it asks for.
    let (width, torque, beta, torque_beta, h_force, h_torque) = match kernel {
        "es" => {
            let w = es_support(tolerance);
            let (beta, torque_beta) = (
                ES_BETA_PER_CELL * w as f64,
                ES_BETA_PER_CELL * (w + 1) as f64,
            );
            // A window of 2 cells has a half-width of one: its radius in cells is a / alpha.
            let alpha = radius / es_window_radius(beta, 2);
            let alpha_t = es_torque_half_width(radius, torque_beta);
            (
                alpha,
                alpha_t,
                beta,
                torque_beta,
                2.0 * alpha / w as f64,
                2.0 * alpha_t / (w + 1) as f64,
            )
        }
        "gaussian" => {
            let (sigma, sigma_t) = (gaussian_width(radius), torque_width(radius));
            let g = gaussian_upsampling(tolerance);
            (sigma, sigma_t, 0.0, 0.0, sigma / g, sigma_t / g)
        }
        other => {
            return Err(format!("kernel must be es or gaussian, got `{other}`"));
        }
    };
    let h0 = if rotation {
        h_force.min(h_torque)
    } else {
        h_force
    };
    let mut cells = [0u32; 2];
    for (a, l) in lengths.iter().enumerate() {
        let n = (l / h0).ceil();
        if n > crate::nodes::fft::plan::MAX_LENGTH as f64 {
            return Err(format!(
                "box length {l} needs {n} cells of {h0:.4} (radius {radius}, tolerance {tolerance}): over the {} an FFT axis takes",
                crate::nodes::fft::plan::MAX_LENGTH
            ));
        }
        cells[a] = crate::nodes::fft::next_friendly((n as u32).max(4));
    }
    let hx = lengths[0] / cells[0] as f64;
    let h_min = hx.min(lengths[1] / cells[1] as f64);
    // Cells visited per axis, and the half support as a length (the z padding).
    let (support, torque_support, half, half_t) = if kernel == "es" {
        // The window library's rule: the cells the half-width spans on the finest axis.
        let cells_of = |w: f64, b: f64| {
            Window::from_params("es", w, 0, b, tolerance, h_min).map(|w| w.support())
        };
        (
            cells_of(width, beta)?,
            cells_of(torque, torque_beta)?,
            width,
            torque,
        )
    } else {
        let (s, st) = (
            gaussian_support(width, tolerance, hx),
            gaussian_support(torque, tolerance, hx),
        );
        (s, st, s as f64 * hx / 2.0, st as f64 * hx / 2.0)
    };
    let pad = if rotation { half.max(half_t) } else { half };
    let (zlo, zhi) = match wall_code {
        0 => (zmin - pad, zmax + pad),
        1 => (zmin, zmax + pad),
        _ => (zmin, zmax),
    };
    let points = ((std::f64::consts::PI * (zhi - zlo) / (2.0 * hx)).ceil() as u64 + 1).max(5);
    if points > chebyshev::MAX_POINTS as u64 {
        return Err(format!(
            "the z domain [{zlo}, {zhi}] needs {points} Chebyshev points at cell {hx:.4}: over the {} the transforms take",
            chebyshev::MAX_POINTS
        ));
    }
    Ok(vec![
        cells[0] as f64,
        cells[1] as f64,
        points as f64,
        zlo,
        zhi,
        support as f64,
        torque_support as f64,
        width,
        torque,
        beta,
        torque_beta,
    ])
}

fn spectrum_port(name: &'static str, doc: &'static str) -> PortSpec {
    PortSpec::new(name, PortType::HalfComplexGrid, doc)
}

fn kind(
    name: &'static str,
    doc: &'static str,
    ports: &[(&'static str, &'static str)],
) -> crate::node::KindDecl {
    let mut k = NodeKind::declare(name, doc);
    for &(port, pdoc) in ports {
        k = k.input(spectrum_port(port, pdoc));
    }
    k.param(box_param())
}

pub fn register(r: &mut Registry) {
    r.add(
        kind(
            "slab_pressure_source",
            "the source of the doubly periodic Stokes pressure, i k.f + d f_z/dz, from the forcing's Chebyshev coefficients along z (half spectrum in x, y) and its z derivative's (`chebyshev_derivative`)",
            &[("f", "the forcing's coefficients (3 components)"), ("df", "the coefficients of the z derivative of its z component (1 component: chebyshev_derivative with first 2, count 1)")],
        )
        .output(spectrum_port("out", "the source's coefficients (1 component)"))
        .build(|p| Ok(Box::new(Slab::from_params(Step::PressureSource, p)?))),
    );
    r.add(
        kind(
            "slab_velocity_source",
            "the sources ((i k p - f) / eta, (dp/dz - f_z) / eta) of the doubly periodic Stokes velocity and its boundary values for `chebyshev_bvp` (the force-free exterior's: alpha = (-i k p(zmax) / (2 eta |k|), p(zmax) / (2 eta)), beta = (i k p(zmin) / (2 eta |k|), p(zmin) / (2 eta)); 0 at k = 0)",
            &[
                ("f", "the forcing's coefficients (3 components)"),
                ("p", "the pressure's coefficients (1 component)"),
                ("dp", "the coefficients of its z derivative (1 component)"),
            ],
        )
        .param(ParamSpec::f32_positive("viscosity", Some(1.0), "solvent viscosity eta"))
        .output(spectrum_port("rhs", "the velocity sources' coefficients (3 components)"))
        .output(spectrum_port("boundary", "alpha (z index 0) and beta (1) per k and component: 2 points along z"))
        .build(|p| Ok(Box::new(Slab::from_params(Step::VelocitySource, p)?))),
    );
    r.add(
        kind(
            "slab_walls",
            "the walls of the doubly periodic Stokes solver on the free-space velocity (values at the Chebyshev points along z, half spectrum in x, y): for k != 0 the homogeneous Stokes flow that cancels it on the walls (bottom: zmin; slit: both), the k = 0 mode of each wall mode (none: dropped; bottom: zero at zmin, free above; slit: zero at both; v_z = 0)",
            &[("v", "the free-space velocity, values along z (3 components)")],
        )
        .param(ParamSpec::number("zmin", Some(-1.0), -1e18, 1e18, "the bottom of the domain (the bottom wall)"))
        .param(ParamSpec::number("zmax", Some(1.0), -1e18, 1e18, "the top of the domain (the slit's top wall)"))
        .param(walls_param())
        .output(spectrum_port("out", "the velocity with the walls (3 components)"))
        .build(|p| Ok(Box::new(Slab::from_params(Step::Walls, p)?))),
    );
    r.add(
        kind(
            "slab_curl",
            "scale x curl of a field from its Chebyshev coefficients along z (half spectrum in x, y) and its z derivative's: (i ky v_z - dv_y/dz, dv_x/dz - i kx v_z, i kx v_y - i ky v_x); i k zero on unpaired Nyquist indices",
            &[("x", "the field's coefficients (3 components)"), ("dx", "its z derivative's (3 components)")],
        )
        .param(ParamSpec::f32_factor("scale", Some(1.0), "factor on the curl (1/2: the fluid's angular velocity, or the forcing of spread torques)"))
        .output(spectrum_port("out", "the curl's coefficients (3 components)"))
        .build(|p| Ok(Box::new(Slab::from_params(Step::Curl, p)?))),
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The slit's inverse maps the wall values back to themselves through the flow: C, D
    /// from (u_b, u_t), then the flow evaluated at both walls, and is finite at large k Lz.
    #[test]
    fn the_slit_flow_takes_the_wall_values() {
        let i = C64::new(0.0, 1.0);
        for (k, height) in [
            ([0.3f64, -0.2], 2.0),
            ([2.0, 1.0], 5.0),
            ([40.0, 30.0], 10.0),
        ] {
            let kabs = (k[0] * k[0] + k[1] * k[1]).sqrt();
            let minv = slit_inverse(k, height);
            let u: Vec<C64> = (0..6)
                .map(|r| C64::new(r as f64 - 2.5, 0.5 * r as f64))
                .collect();
            let mut x = [C64::new(0.0, 0.0); 6];
            for r in 0..6 {
                x[r] = (0..6).map(|c| minv[r][c] * u[c]).sum();
                assert!(x[r].norm().is_finite());
            }
            let (c, d) = (&x[..3], &x[3..]);
            let a = c[2] - i * (k[0] * c[0] + k[1] * c[1]) / kabs;
            let b = -d[2] - i * (k[0] * d[0] + k[1] * d[1]) / kabs;
            let flow = |z: f64, comp: usize| -> C64 {
                let (sa, sb) = if comp < 2 {
                    (-i * k[comp], i * k[comp])
                } else {
                    (C64::new(kabs, 0.0), C64::new(kabs, 0.0))
                };
                (a * z * sa + c[comp]) * (-kabs * z).exp()
                    + (b * z * sb + d[comp]) * (kabs * (z - height)).exp()
            };
            for comp in 0..3 {
                assert!((flow(0.0, comp) - u[comp]).norm() < 1e-9, "bottom {comp}");
                assert!(
                    (flow(height, comp) - u[3 + comp]).norm() < 1e-9,
                    "top {comp}"
                );
            }
            // Divergence-free: i k.v_par + dv_z/dz = 0, checked by a central difference.
            let z = 0.37 * height;
            let hstep = 1e-5 * height;
            let div = i * (k[0] * flow(z, 0) + k[1] * flow(z, 1))
                + (flow(z + hstep, 2) - flow(z - hstep, 2)) / (2.0 * hstep);
            let scale = (0..6).map(|r| u[r].norm()).fold(0.0, f64::max) * kabs;
            assert!(div.norm() < 1e-5 * scale, "divergence {div}");
        }
    }

    /// The derivative row differentiates polynomials of degree below n exactly.
    #[test]
    fn the_top_derivative_row_is_exact_on_polynomials() {
        let s = Slab {
            step: Step::Walls,
            lengths: [1.0, 1.0],
            viscosity: 1.0,
            zmin: -0.5,
            zmax: 2.5,
            walls: 1,
            scale: 1.0,
        };
        let n = 9;
        let z: Vec<f64> = s.zetas(n).iter().map(|x| x + s.zmin).collect();
        let row = s.top_derivative_row(n);
        let got: f64 = row.iter().zip(&z).map(|(w, z)| w * z.powi(5)).sum();
        let want = 5.0 * s.zmax.powi(4);
        assert!((got - want).abs() < 1e-9 * want, "{got} vs {want}");
    }
}
