//! `chebyshev_bvp`: the two-point boundary-value problem of the doubly periodic solvers, per
//! in-plane wave number (UAMMD thesis appendix C; digest section 7.5):
//!
//!   (d^2/dz^2 - k^2) y = f on [zmin, zmax],  (d/dz + k) y(zmax) = alpha,
//!   (d/dz - k) y(zmin) = beta            (k = 0: y(zmax) = alpha, y(zmin) = beta),
//!
//! for every (kx, ky) of a half spectrum and every component, f and y as Chebyshev
//! coefficients along z (`chebyshev`), alpha and beta from an optional `boundary` grid
//! (z index 0: alpha, 1: beta; zero without it: the decaying solutions of free space).
//!
//! On xi in [-1, 1] (z = zmid + H xi / 2) the problem is y'' - kappa^2 y = (H/2)^2 f with
//! kappa = k H / 2 and the boundary values times H / 2. The unknowns are the coefficients
//! a_n of y'' and the constants Y0 = y_0 and P0 = y'_0; y' and y follow by exact
//! integration (y'_1 = (2 a_0 - a_2) / 2, y'_n = (a_{n-1} - a_{n+1}) / 2n, y_1 = P0 -
//! (a_1 - a_3) / 8, y_n = (y'_{n-1} - y'_{n+1}) / 2n), so the equations a_n - kappa^2 y_n
//! = f_n couple a_n with a_{n-2} and a_{n+2} only (A: a tridiagonal system on each parity),
//! Y0 and P0 enter rows 0 and 1 (B), and the two boundary rows (C, D) close the system. The
//! host factors A per k in f64 (Thomas: multiplier, pivot, upper entry per row), and
//! precomputes G = C A^-1 and S^-1 = (C A^-1 B - D)^-1; the GPU solves each k with one
//! thread: [Y0, P0] = S^-1 (G f - [alpha, beta]), A a = f - B [Y0, P0], then y from a. The
//! tables are strided (entry i of every k contiguous), so neighbouring threads read
//! neighbouring words.
use crate::gpu::{Binding, CompileCtx, CompileError, DeviceCaps, Dispatch, KernelSpec, NodeIo};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamSpec, PortError, PortSpec, RefCtx, Registry,
    Signature,
};
use crate::value::{PortType, RefArray, ValueType};

/// The linear relations of the integrated coefficients: y'_n and y_n as vectors over the
/// unknowns (a_0 .. a_{N-1}, Y0, P0).
#[allow(clippy::needless_range_loop)]
fn integrals(n: usize) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let m = n + 2;
    let (iy0, ip0) = (n, n + 1);
    let a = |j: usize| -> Vec<f64> {
        let mut v = vec![0.0; m];
        if j < n {
            v[j] = 1.0;
        }
        v
    };
    let combine = |terms: &[(f64, &Vec<f64>)]| -> Vec<f64> {
        let mut v = vec![0.0; m];
        for (c, t) in terms {
            for (x, y) in v.iter_mut().zip(t.iter()) {
                *x += c * y;
            }
        }
        v
    };
    // y'_n, n = 0 .. n + 1 (the two past the end are zero but are read by the formulas).
    let mut dy: Vec<Vec<f64>> = vec![vec![0.0; m]; n + 2];
    dy[0][ip0] = 1.0;
    if n > 1 {
        dy[1] = combine(&[(1.0, &a(0)), (-0.5, &a(2))]);
    }
    for k in 2..n {
        dy[k] = combine(&[(0.5 / k as f64, &a(k - 1)), (-0.5 / k as f64, &a(k + 1))]);
    }
    let mut y: Vec<Vec<f64>> = vec![vec![0.0; m]; n];
    y[0][iy0] = 1.0;
    if n > 1 {
        // y_1 = P0 - y'_2 / 2.
        y[1] = combine(&[(1.0, &dy[0]), (-0.5, &dy[2])]);
    }
    for k in 2..n {
        y[k] = combine(&[(0.5 / k as f64, &dy[k - 1]), (-0.5 / k as f64, &dy[k + 1])]);
    }
    dy.truncate(n);
    (dy, y)
}

/// The full (N + 2) x (N + 2) system of one k on [-1, 1] (rows: the N equations, then top
/// and bottom), for the f64 reference and the host's precomputation.
fn system(n: usize, kappa: f64) -> Vec<Vec<f64>> {
    let (dy, y) = integrals(n);
    let m = n + 2;
    let mut rows = Vec::with_capacity(m);
    for k in 0..n {
        let mut r = vec![0.0; m];
        if k < n {
            r[k] += 1.0;
        }
        for (x, v) in r.iter_mut().zip(&y[k]) {
            *x -= kappa * kappa * v;
        }
        rows.push(r);
    }
    let mut top = vec![0.0; m];
    let mut bottom = vec![0.0; m];
    for k in 0..n {
        let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
        for j in 0..m {
            if kappa == 0.0 {
                // Dirichlet: y(1) = sum y_n, y(-1) = sum (-1)^n y_n.
                top[j] += y[k][j];
                bottom[j] += sign * y[k][j];
            } else {
                top[j] += dy[k][j] + kappa * y[k][j];
                bottom[j] += sign * (dy[k][j] - kappa * y[k][j]);
            }
        }
    }
    rows.push(top);
    rows.push(bottom);
    rows
}

/// Solves a dense system by Gaussian elimination with partial pivoting (f64).
fn dense_solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Vec<f64> {
    let m = b.len();
    for c in 0..m {
        let p = (c..m)
            .max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))
            .expect("rows");
        a.swap(c, p);
        b.swap(c, p);
        for r in c + 1..m {
            let f = a[r][c] / a[c][c];
            if f != 0.0 {
                let pivot_row = a[c].clone();
                for (x, p) in a[r][c..].iter_mut().zip(&pivot_row[c..]) {
                    *x -= f * p;
                }
                b[r] -= f * b[c];
            }
        }
    }
    let mut x = vec![0.0; m];
    for r in (0..m).rev() {
        let s: f64 = (r + 1..m).map(|k| a[r][k] * x[k]).sum();
        x[r] = (b[r] - s) / a[r][r];
    }
    x
}

/// y's coefficients for f's and the boundary values, on [-1, 1], by the dense system: the
/// f64 reference.
pub fn solve_reference(f: &[f64], kappa: f64, alpha: f64, beta: f64) -> Vec<f64> {
    let n = f.len();
    let mut rhs = f.to_vec();
    rhs.push(alpha);
    rhs.push(beta);
    let x = dense_solve(system(n, kappa), rhs);
    let (_, y) = integrals(n);
    y.iter()
        .map(|row| row.iter().zip(&x).map(|(c, v)| c * v).sum())
        .collect()
}

/// The per-k tables (f64) the kernel reads: Thomas factors of A (multiplier l, inverse
/// pivot q, upper entry u per row), G = C A^-1 (2 x N) and S^-1 (2 x 2).
#[derive(Clone, Debug)]
pub struct Factors {
    pub l: Vec<f64>,
    pub q: Vec<f64>,
    pub u: Vec<f64>,
    pub g: [Vec<f64>; 2],
    pub s_inv: [f64; 4],
}

/// Thomas factors of A (its rows n couple a_{n-2}, a_n, a_{n+2}).
fn factor(a: &[Vec<f64>], n: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let (mut l, mut q, mut u) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    for r in 0..n {
        u[r] = if r + 2 < n { a[r][r + 2] } else { 0.0 };
        let mut d = a[r][r];
        if r >= 2 {
            l[r] = a[r][r - 2] * q[r - 2];
            d -= l[r] * u[r - 2];
        }
        q[r] = 1.0 / d;
    }
    (l, q, u)
}

/// Solves A x = b with the factors.
fn thomas(l: &[f64], q: &[f64], u: &[f64], b: &[f64]) -> Vec<f64> {
    let n = b.len();
    let mut w = b.to_vec();
    for r in 2..n {
        w[r] -= l[r] * w[r - 2];
    }
    let mut x = vec![0.0; n];
    for r in (0..n).rev() {
        let up = if r + 2 < n { u[r] * x[r + 2] } else { 0.0 };
        x[r] = (w[r] - up) * q[r];
    }
    x
}

/// Solves A^T x = b with the factors of A (A = L U, A^T = U^T L^T).
fn thomas_transposed(l: &[f64], q: &[f64], u: &[f64], b: &[f64]) -> Vec<f64> {
    let n = b.len();
    // U^T w = b: U has pivots 1/q and upper entries u at +2.
    let mut w = vec![0.0; n];
    for r in 0..n {
        let low = if r >= 2 { u[r - 2] * w[r - 2] } else { 0.0 };
        w[r] = (b[r] - low) * q[r];
    }
    // L^T x = w: L has ones and multipliers l at -2.
    let mut x = w.clone();
    for r in (0..n).rev() {
        if r + 2 < n {
            x[r] -= l[r + 2] * x[r + 2];
        }
    }
    x
}

/// The tables of one k (kappa the rescaled wave number).
pub fn factors(n: usize, kappa: f64) -> Factors {
    let sys = system(n, kappa);
    let a: Vec<Vec<f64>> = sys[..n].iter().map(|r| r[..n].to_vec()).collect();
    let (l, q, u) = factor(&a, n);
    // B: the columns of Y0 and P0 in the N equations; C: the boundary rows over a; D: over
    // Y0, P0.
    let b: [Vec<f64>; 2] = [0, 1].map(|c| sys[..n].iter().map(|r| r[n + c]).collect());
    let c: [Vec<f64>; 2] = [0, 1].map(|r| sys[n + r][..n].to_vec());
    let d = [sys[n][n], sys[n][n + 1], sys[n + 1][n], sys[n + 1][n + 1]];
    let g = c.clone().map(|row| thomas_transposed(&l, &q, &u, &row));
    let ainv_b = b.clone().map(|col| thomas(&l, &q, &u, &col));
    let dot = |x: &[f64], y: &[f64]| x.iter().zip(y).map(|(a, b)| a * b).sum::<f64>();
    // S = C A^-1 B - D.
    let s = [
        dot(&c[0], &ainv_b[0]) - d[0],
        dot(&c[0], &ainv_b[1]) - d[1],
        dot(&c[1], &ainv_b[0]) - d[2],
        dot(&c[1], &ainv_b[1]) - d[3],
    ];
    let det = s[0] * s[3] - s[1] * s[2];
    let s_inv = [s[3] / det, -s[1] / det, -s[2] / det, s[0] / det];
    Factors { l, q, u, g, s_inv }
}

/// y's coefficients through the factors, as the kernel computes them (f64).
pub fn solve(fac: &Factors, f: &[f64], kappa: f64, alpha: f64, beta: f64) -> Vec<f64> {
    let n = f.len();
    let dot = |x: &[f64], y: &[f64]| x.iter().zip(y).map(|(a, b)| a * b).sum::<f64>();
    let r = [dot(&fac.g[0], f) - alpha, dot(&fac.g[1], f) - beta];
    let y0 = fac.s_inv[0] * r[0] + fac.s_inv[1] * r[1];
    let p0 = fac.s_inv[2] * r[0] + fac.s_inv[3] * r[1];
    // A a = f - B [Y0, P0]: B is -kappa^2 at (0, Y0) and (1, P0).
    let mut rhs = f.to_vec();
    rhs[0] += kappa * kappa * y0;
    if n > 1 {
        rhs[1] += kappa * kappa * p0;
    }
    let a = thomas(&fac.l, &fac.q, &fac.u, &rhs);
    let (_, y) = integrals(n);
    let mut x = a;
    x.push(y0);
    x.push(p0);
    y.iter()
        .map(|row| row.iter().zip(&x).map(|(c, v)| c * v).sum())
        .collect()
}

/// |k| of every (x, y) index of the half spectrum of a grid of `dims` over [Lx, Ly].
fn wave_numbers(dims: [u32; 3], lengths: [f64; 2]) -> Vec<f64> {
    crate::nodes::spectral::plane_waves(dims, lengths)
        .into_iter()
        .map(|(k, _)| (k[0] * k[0] + k[1] * k[1]).sqrt())
        .collect()
}

fn bvp_kind() -> NodeKind {
    NodeKind::declare(
        "chebyshev_bvp",
        "per in-plane wave number k of a half spectrum, the Chebyshev coefficients along z of y solving (d2/dz2 - k^2) y = f on [zmin, zmax] with (d/dz + k) y(zmax) = alpha, (d/dz - k) y(zmin) = beta (k = 0: y(zmax) = alpha, y(zmin) = beta); alpha, beta from `boundary` or 0 (the decaying solutions of free space). Per-k tables in f64 on the host (Schur complement of a banded system), one thread per k and component",
    )
    .input(PortSpec::new(
        "f",
        PortType::HalfComplexGrid,
        "f's Chebyshev coefficients along z (the half spectrum in x, y)",
    ))
    .input(
        PortSpec::new(
            "boundary",
            PortType::HalfComplexGrid,
            "alpha (z index 0) and beta (index 1) per k and component: a half spectrum of the same x, y dims with 2 points along z",
        )
        .optional(),
    )
    .output(PortSpec::new("out", PortType::HalfComplexGrid, "y's Chebyshev coefficients"))
    .param(super::stokes_slab::box_param())
    .param(ParamSpec::number("zmin", Some(-1.0), -1e18, 1e18, "the bottom of the domain"))
    .param(ParamSpec::number("zmax", Some(1.0), -1e18, 1e18, "the top of the domain"))
    .param(ParamSpec::choice(
        "order",
        "auto",
        &["auto", "components", "waves"],
        "how threads are laid out: components (each component's wave numbers in a row: the lines' reads contiguous), waves (a wave number's components side by side: its tables read once from memory), auto (waves where the tables outgrow the cache)",
    ))
    .build(|p| {
        let b = p.numbers("box");
        let (zmin, zmax) = (p.number("zmin"), p.number("zmax"));
        if zmax <= zmin {
            return Err(format!("`zmax` {zmax} must be above `zmin` {zmin}"));
        }
        Ok(Box::new(Bvp {
            lengths: [b[0], b[1]],
            height: zmax - zmin,
            order: match p.text("order") {
                "components" => Some(false),
                "waves" => Some(true),
                _ => None,
            },
        }))
    })
}

struct Bvp {
    lengths: [f64; 2],
    height: f64,
    /// Whether threads go wave number first (a k's components side by side); None: by
    /// the tables' size.
    order: Option<bool>,
}

impl Node for Bvp {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let Some(ValueType::HalfComplexGrid { dims, comps }) = inputs[0] else {
            unreachable!("port type checked")
        };
        if dims[2] < 2 || dims[2] > crate::nodes::chebyshev::MAX_POINTS {
            return Err(PortError::new(
                "f",
                format!(
                    "has {} Chebyshev coefficients along z: 2 to {} are taken",
                    dims[2],
                    crate::nodes::chebyshev::MAX_POINTS
                ),
            ));
        }
        if let Some(ValueType::HalfComplexGrid {
            dims: bd,
            comps: bc,
        }) = inputs[1]
            && (bd[0] != dims[0] || bd[1] != dims[1] || bd[2] != 2 || bc != comps)
        {
            return Err(PortError::new(
                "boundary",
                format!(
                    "must be a half spectrum of {}x{}x2 cells and {comps} components, got {}",
                    dims[0],
                    dims[1],
                    inputs[1].expect("matched")
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
        outputs[0] = reference(self.lengths, self.height, f, inputs[1].as_ref());
    }
}

/// The f64 reference of `chebyshev_bvp` on [Lx, Ly] and a domain of `height`: y's
/// coefficients for f's (a half spectrum), alpha and beta from `boundary` or 0, by the
/// dense system per k, component and part (also `slab_solve`'s reference).
pub(crate) fn reference(
    lengths: [f64; 2],
    height: f64,
    f: &RefArray,
    boundary: Option<&RefArray>,
) -> RefArray {
    let ValueType::HalfComplexGrid { dims, comps } = f.ty else {
        unreachable!()
    };
    let kappas = kappas(dims, lengths, height);
    let nk = kappas.len();
    let n = dims[2] as usize;
    let half = height / 2.0;
    let mut out = vec![0.0; f.data.len()];
    for c in 0..comps as usize {
        for (ki, &kappa) in kappas.iter().enumerate() {
            for part in 0..2 {
                let at = |z: usize| 2 * ((c * n + z) * nk + ki) + part;
                let line: Vec<f64> = (0..n).map(|z| half * half * f.data[at(z)]).collect();
                let (alpha, beta) = match boundary {
                    Some(b) => {
                        let bat = |z: usize| 2 * ((c * 2 + z) * nk + ki) + part;
                        let scale = if kappa == 0.0 { 1.0 } else { half };
                        (scale * b.data[bat(0)], scale * b.data[bat(1)])
                    }
                    None => (0.0, 0.0),
                };
                let y = solve_reference(&line, kappa, alpha, beta);
                for (z, v) in y.into_iter().enumerate() {
                    out[at(z)] = v;
                }
            }
        }
    }
    RefArray::new(f.ty, out)
}

/// Rows of the per-k tables of `tables`: l, q, u, g0, g1 (n each), s_inv (4), kappa^2,
/// whether k is 0.
pub(crate) fn table_rows(n: usize) -> usize {
    5 * n + 6
}

/// The per-k tables the solve kernels read (shaders/chebyshev/bvp.wgsl, slab_solve.wgsl),
/// built in f64 and stored in f32, strided: row i of every k contiguous (word i nk + k).
pub(crate) fn tables(kappas: &[f64], n: usize) -> Vec<f32> {
    let nk = kappas.len();
    let mut table = vec![0f32; table_rows(n) * nk];
    for (ki, &kappa) in kappas.iter().enumerate() {
        let fac = factors(n, kappa);
        let mut put = |row: usize, v: f64| table[row * nk + ki] = v as f32;
        for i in 0..n {
            put(i, fac.l[i]);
            put(n + i, fac.q[i]);
            put(2 * n + i, fac.u[i]);
            put(3 * n + i, fac.g[0][i]);
            put(4 * n + i, fac.g[1][i]);
        }
        for (j, s) in fac.s_inv.iter().enumerate() {
            put(5 * n + j, *s);
        }
        put(5 * n + 4, kappa * kappa);
        put(5 * n + 5, if kappa == 0.0 { 1.0 } else { 0.0 });
    }
    table
}

/// kappa = |k| H / 2 of every k of a half spectrum of `dims` over [Lx, Ly].
pub(crate) fn kappas(dims: [u32; 3], lengths: [f64; 2], height: f64) -> Vec<f64> {
    wave_numbers(dims, lengths)
        .into_iter()
        .map(|k| k * height / 2.0)
        .collect()
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Shape {
    nk: u32,
    n: u32,
    comps: u32,
    has_boundary: u32,
    /// (H/2)^2 on f, H/2 on alpha and beta where k > 0.
    f_scale: f32,
    bc_scale: f32,
    pad: [u32; 2],
}

impl GpuKernels for Bvp {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let f = io.inputs[0].expect("required");
        let ValueType::HalfComplexGrid { dims, comps } = f.ty else {
            unreachable!()
        };
        let kappas = kappas(dims, self.lengths, self.height);
        let (nk, n) = (kappas.len(), dims[2] as usize);
        let table = tables(&kappas, n);
        let half = self.height / 2.0;
        let shape = Shape {
            nk: nk as u32,
            n: n as u32,
            comps,
            has_boundary: u32::from(io.inputs[1].is_some()),
            f_scale: (half * half) as f32,
            bc_scale: half as f32,
            pad: [0; 2],
        };
        // Each thread (k, component, real or imaginary part) keeps its line of n words in
        // a private array whose size is fixed when the kernel is built, so the loops
        // unroll and the line stays in registers (spilled for long lines).
        let wg = crate::nodes::chebyshev::LINE_WG;
        // Threads in k-major order (a k's components side by side) where the tables
        // outgrow the cache: each k's tables are then read once from memory (H100, 33
        // points, 3 components: 0.300 -> 0.274 ms at 600 x 600, but 0.038 -> 0.044 at 189 x
        // 189, whose 12 MB of tables stay in cache).
        let k_major = self
            .order
            .unwrap_or(table.len() as u64 * 4 > crate::nodes::spread::LARGE_GRID_BYTES);
        let source = format!(
            "const WG: u32 = {wg}u;\nconst POINTS: u32 = {n}u;\nconst K_MAJOR: bool = {k_major};\n{}",
            cx.shader("chebyshev/bvp.wgsl")?
        );
        let kernel = cx.kernel(&KernelSpec::new(
            "chebyshev bvp",
            source,
            &[
                Binding::StorageRead,
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::StorageRead,
                Binding::Uniform,
            ],
        ))?;
        let tables = cx.table("chebyshev bvp tables", bytemuck::cast_slice(&table));
        let u = cx.uniform("chebyshev bvp shape", bytemuck::bytes_of(&shape));
        let boundary = io.inputs[1].map(|b| b.buffer).unwrap_or(f.buffer);
        Ok(vec![cx.dispatch(
            &kernel,
            &[f.buffer, boundary, io.outputs[0].buffer, &tables, &u],
            cx.grid_1d(nk as u64 * comps as u64 * 2, wg),
        )])
    }
}

pub fn register(r: &mut Registry) {
    r.add(bvp_kind());
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The factored solve agrees with the dense system, k = 0 and k > 0, small and large.
    #[test]
    fn schur_solve_matches_the_dense_system() {
        for n in [2usize, 3, 5, 16, 33] {
            for kappa in [0.0, 0.3, 2.0, 40.0] {
                let f: Vec<f64> = (0..n)
                    .map(|i| ((i * 7 + 3) % 11) as f64 / 5.0 - 1.0)
                    .collect();
                let (alpha, beta) = (0.7, -1.3);
                let dense = solve_reference(&f, kappa, alpha, beta);
                let fac = factors(n, kappa);
                let fast = solve(&fac, &f, kappa, alpha, beta);
                let scale = dense.iter().fold(1e-30f64, |m, x| m.max(x.abs()));
                for (a, b) in fast.iter().zip(&dense) {
                    assert!(
                        (a - b).abs() < 1e-10 * scale,
                        "n {n} kappa {kappa}: {a} vs {b}"
                    );
                }
            }
        }
    }

    /// A manufactured solution: y = cos(2 xi) + xi^3 solves y'' - kappa^2 y = f with its
    /// own boundary values, to spectral accuracy.
    #[test]
    fn a_manufactured_solution_is_recovered() {
        let n = 24;
        let kappa = 1.7;
        let xs = crate::nodes::chebyshev::points(n);
        let y = |x: f64| (2.0 * x).cos() + x * x * x;
        let dy = |x: f64| -2.0 * (2.0 * x).sin() + 3.0 * x * x;
        let d2y = |x: f64| -4.0 * (2.0 * x).cos() + 6.0 * x;
        let fv: Vec<f64> = xs.iter().map(|&x| d2y(x) - kappa * kappa * y(x)).collect();
        let m = crate::nodes::chebyshev::matrix(n, true);
        let fc: Vec<f64> = (0..n)
            .map(|k| (0..n).map(|j| m[k * n + j] * fv[j]).sum())
            .collect();
        let alpha = dy(1.0) + kappa * y(1.0);
        let beta = dy(-1.0) - kappa * y(-1.0);
        let yc = solve(&factors(n, kappa), &fc, kappa, alpha, beta);
        let back = crate::nodes::chebyshev::matrix(n, false);
        for (j, &x) in xs.iter().enumerate() {
            let v: f64 = (0..n).map(|k| back[j * n + k] * yc[k]).sum();
            assert!((v - y(x)).abs() < 1e-10, "y({x}) = {v}, want {}", y(x));
        }
    }
}
