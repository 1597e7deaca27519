//! Chebyshev transforms along the z axis of a grid, the building blocks of solvers that are
//! periodic in x and y and bounded in z (doubly periodic Stokes and Poisson: UAMMD thesis
//! section 23 and appendix C; digest section 7.5).
//!
//! The z axis holds values at the Chebyshev-Gauss-Lobatto points xi_j = cos(pi j / (n - 1)),
//! j = 0 .. n - 1 (the top of the domain first), of the interval [zmin, zmax] mapped to
//! [-1, 1]; or the coefficients c_k of f(xi) = sum_k c_k T_k(xi). Every (x, y) line of
//! every component is transformed alone; real and imaginary parts of a spectrum alike.
//!
//! - `chebyshev` (`direction`: forward, values to coefficients, or inverse): the DCT-I
//!   c_k = (2 / (n - 1)) (1 / kappa_k) sum_j'' f_j cos(pi j k / (n - 1)) (the end terms
//!   halved, kappa_0 = kappa_{n-1} = 2, else 1) and f_j = sum_k c_k cos(pi j k / (n - 1)),
//!   as a dense n x n matrix computed in f64 on the host, for the tens to a few hundred
//!   points these solvers take: one thread per line (held in registers, n fixed when the
//!   kernel is built) and chunk of outputs (`line_product`).
//! - `chebyshev_derivative`: the coefficients of df/dz = (2 / (zmax - zmin)) df/dxi by the
//!   backward recurrence c'_{k-1} = c'_{k+1} + 2 k c_k (c'_0 halved), one thread a line,
//!   where the lines fill the GPU; on small grids the recurrence written as its matrix and
//!   run as the same dense product (every output in parallel).

use std::f64::consts::PI;

use crate::gpu::{
    Binding, CompileCtx, CompileError, DeviceCaps, Dispatch, KernelSpec, NodeIo, WG_1D,
};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamSpec, PortError, PortSpec, RefCtx, Registry,
    Signature,
};
use crate::value::{PortType, RefArray, ValueType, half_dims};

/// (components, points along z, words per z level) of a grid: the z lines are the
/// `plane` words of each level, `plane` apart.
fn lines(t: &ValueType) -> Option<(u64, u64, u64)> {
    match *t {
        ValueType::RealGrid { dims, comps } => Some((
            comps as u64,
            dims[2] as u64,
            dims[0] as u64 * dims[1] as u64,
        )),
        ValueType::ComplexGrid { dims, comps } => Some((
            comps as u64,
            dims[2] as u64,
            2 * dims[0] as u64 * dims[1] as u64,
        )),
        ValueType::HalfComplexGrid { dims, comps } => {
            let h = half_dims(dims);
            Some((comps as u64, dims[2] as u64, 2 * h[0] as u64 * h[1] as u64))
        }
        _ => None,
    }
}

/// The grid's z lines, refused with a reason for other values and fewer than 2 points.
fn check_grid(t: &ValueType) -> Result<(u64, u64, u64), PortError> {
    let (c, n, plane) = lines(t)
        .ok_or_else(|| PortError::new("x", format!("expects a real or complex grid, got {t}")))?;
    if n < 2 {
        return Err(PortError::new(
            "x",
            format!("has {n} point along z: a Chebyshev grid needs at least 2"),
        ));
    }
    if n > MAX_POINTS as u64 {
        return Err(PortError::new(
            "x",
            format!("has {n} points along z, over the {MAX_POINTS} the dense transform takes"),
        ));
    }
    Ok((c, n, plane))
}

/// Points along z the dense transform takes (its matrix is n^2 words).
pub const MAX_POINTS: u32 = 1024;

/// The Chebyshev-Gauss-Lobatto points xi_j = cos(pi j / (n - 1)).
pub fn points(n: usize) -> Vec<f64> {
    (0..n)
        .map(|j| (PI * j as f64 / (n - 1) as f64).cos())
        .collect()
}

/// The n x n matrix (row-major, output index first) of the forward transform (values to
/// coefficients) or the inverse, in f64.
pub fn matrix(n: usize, forward: bool) -> Vec<f64> {
    let m = (n - 1) as f64;
    let mut t = vec![0.0; n * n];
    for a in 0..n {
        for b in 0..n {
            // cos(pi j k / (n - 1)) with the integer product reduced mod 2(n - 1), so the
            // cosine is evaluated at an angle in [0, 2 pi).
            let jk = (a * b) % (2 * (n - 1));
            let c = (PI * jk as f64 / m).cos();
            t[a * n + b] = if forward {
                let (k, j) = (a, b);
                let end_j = if j == 0 || j == n - 1 { 0.5 } else { 1.0 };
                let kappa = if k == 0 || k == n - 1 { 2.0 } else { 1.0 };
                2.0 / m / kappa * end_j * c
            } else {
                c
            };
        }
    }
    t
}

/// The derivative's coefficients from f's, on [-1, 1] times `scale`.
pub fn derivative(c: &[f64], scale: f64) -> Vec<f64> {
    let n = c.len();
    let mut d = vec![0.0; n];
    if n < 2 {
        return d;
    }
    // d_{n-1} = 0, d_{n-2} = 2 (n - 1) c_{n-1}, d_{k-1} = d_{k+1} + 2 k c_k.
    let mut next = 0.0; // d_{k+1}
    let mut here = 0.0; // d_k
    for k in (1..n).rev() {
        let prev = next + 2.0 * k as f64 * c[k];
        d[k - 1] = prev;
        next = here;
        here = prev;
    }
    d[0] *= 0.5;
    d.iter().map(|x| x * scale).collect()
}

/// Applies `f` to every z line of `x` (its components' values along z), into `out`.
fn per_line(t: &ValueType, x: &[f64], out: &mut [f64], f: impl Fn(&[f64]) -> Vec<f64>) {
    let (comps, n, plane) = lines(t).expect("checked in infer");
    let (n, plane) = (n as usize, plane as usize);
    let mut line = vec![0.0; n];
    for c in 0..comps as usize {
        for p in 0..plane {
            for (j, v) in line.iter_mut().enumerate() {
                *v = x[(c * n + j) * plane + p];
            }
            for (j, v) in f(&line).into_iter().enumerate() {
                out[(c * n + j) * plane + p] = v;
            }
        }
    }
}

fn transform_kind() -> NodeKind {
    NodeKind::declare(
        "chebyshev",
        "Chebyshev transform along z of a real or complex grid: values at the Chebyshev-Gauss-Lobatto points cos(pi j / (n - 1)) (j = 0 the top) to the coefficients of sum_k c_k T_k, or back (every x, y line and component alone; real and imaginary parts alike)",
    )
    .input(PortSpec::new("x", PortType::Linear, "a real, complex or half-complex grid"))
    .output(PortSpec::new("out", PortType::Linear, "the transformed grid, the same type"))
    .param(ParamSpec::choice(
        "direction",
        "forward",
        &["forward", "inverse"],
        "forward: values to coefficients; inverse: coefficients to values",
    ))
    .build(|p| {
        Ok(Box::new(Transform {
            forward: p.text("direction") == "forward",
        }))
    })
}

struct Transform {
    forward: bool,
}

impl Node for Transform {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let t = inputs[0].expect("required");
        check_grid(&t)?;
        Ok(Signature::outputs(vec![t]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        outputs[0] = transform_reference(inputs[0].as_ref().expect("required"), self.forward);
    }
}

/// The f64 reference of `chebyshev`: every z line of `x` through the dense transform
/// (values to coefficients when `forward`, else back).
pub(crate) fn transform_reference(x: &RefArray, forward: bool) -> RefArray {
    let (_, n, _) = lines(&x.ty).expect("a grid");
    let n = n as usize;
    let m = matrix(n, forward);
    let mut out = vec![0.0; x.data.len()];
    per_line(&x.ty, &x.data, &mut out, |line| {
        (0..n)
            .map(|a| (0..n).map(|b| m[a * n + b] * line[b]).sum())
            .collect()
    });
    RefArray::new(x.ty, out)
}

/// The f64 reference of `chebyshev_derivative`: `count` components of `x` from `first`
/// (0: all the rest), their coefficients differentiated along z times `scale`.
pub(crate) fn derivative_reference(x: &RefArray, first: u64, count: u64, scale: f64) -> RefArray {
    let (comps, n, plane) = lines(&x.ty).expect("a grid");
    let taken = components_taken(comps, first, count);
    let block = (n * plane) as usize;
    let from = first as usize * block;
    let t = with_comps(x.ty, taken as u32);
    let mut out = vec![0.0; taken as usize * block];
    per_line(
        &t,
        &x.data[from..from + taken as usize * block],
        &mut out,
        |c| derivative(c, scale),
    );
    RefArray::new(t, out)
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
/// The uniform of both line kernels (transform.wgsl, derivative.wgsl): `lines` of the
/// output, the factor the recurrence scales by (unused by the dense product).
struct Shape {
    comps: u32,
    n: u32,
    plane: u32,
    scale: f32,
    /// Words of x before the first component taken.
    x_offset: u32,
    pad: [u32; 3],
}

/// Threads per workgroup of the kernels that give each thread a z line (the dense
/// products here, chebyshev_bvp's solve).
pub const LINE_WG: u32 = 64;

/// Threads a dense line product is spread over at least, where the grid has fewer lines:
/// enough to fill a large GPU (an H100 holds 270k), so small grids do not leave it idle
/// behind n serial sums per thread.
const FILL_THREADS: u64 = 1 << 17;

/// Outputs per thread of a dense product along `lines` lines of n points: all n where the
/// lines alone give FILL_THREADS threads, fewer for small grids, and never so many that a
/// thread loops more than 32768 times (n loads, n terms per output; lavapipe stops a
/// thread after 65535 loop iterations).
fn product_chunk(n: u32, lines: u64) -> u32 {
    let n = n.max(1);
    let bound = (32768 / n).saturating_sub(1).clamp(1, n);
    let chunks = FILL_THREADS.div_ceil(lines.max(1)).min(n as u64) as u32;
    bound.min(n.div_ceil(chunks.max(1))).max(1)
}

/// Records out = M x along every z line of the output, read from input 0 from word
/// `x_offset` on (M: n x n, row-major, computed in f64 on the host and used in f32). One
/// thread per line and chunk of outputs (shaders/chebyshev/transform.wgsl).
fn line_product(
    cx: &mut CompileCtx<'_>,
    io: &NodeIo<'_>,
    label: &str,
    m: &[f64],
    x_offset: u32,
) -> Result<Vec<Dispatch>, CompileError> {
    let x = io.inputs[0].expect("required");
    let (comps, n, plane) = lines(&io.outputs[0].ty).expect("checked in infer");
    let shape = Shape {
        comps: comps as u32,
        n: n as u32,
        plane: plane as u32,
        scale: 1.0,
        x_offset,
        pad: [0; 3],
    };
    let chunk = product_chunk(n as u32, comps * plane);
    // The matrix in workgroup memory where it fits the 16 KiB every adapter has (n up to
    // 64; H100, 33 points: 0.044 -> 0.027 ms at 10^5 lines, 0.255 -> 0.176 at 10^6).
    let shared = n * n * 4 <= 16 << 10;
    let words = if shared { n * n } else { 1 };
    let source = format!(
        "const WG: u32 = {LINE_WG}u;\nconst POINTS: u32 = {n}u;\nconst CHUNK: u32 = {chunk}u;\n\
         const SHARED_MATRIX: bool = {shared};\nconst MATRIX_WORDS: u32 = {words}u;\n{}",
        cx.shader("chebyshev/transform.wgsl")?
    );
    let kernel = cx.kernel(&KernelSpec::new(
        label,
        source,
        &[
            Binding::StorageRead,
            Binding::StorageReadWrite,
            Binding::StorageRead,
            Binding::Uniform,
        ],
    ))?;
    let m32: Vec<f32> = m.iter().map(|&v| v as f32).collect();
    let table = cx.table(label, bytemuck::cast_slice(&m32));
    let u = cx.uniform(label, bytemuck::bytes_of(&shape));
    Ok(vec![cx.dispatch(
        &kernel,
        &[x.buffer, io.outputs[0].buffer, &table, &u],
        cx.grid_1d(comps * plane * n.div_ceil(chunk as u64), LINE_WG),
    )])
}

impl GpuKernels for Transform {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let (_, n, _) = lines(&io.inputs[0].expect("required").ty).expect("checked in infer");
        line_product(
            cx,
            io,
            "chebyshev transform",
            &matrix(n as usize, self.forward),
            0,
        )
    }
}

fn derivative_kind() -> NodeKind {
    NodeKind::declare(
        "chebyshev_derivative",
        "the Chebyshev coefficients of df/dz from those of f (along z of a grid, every line and component alone; `count` components from `first`, all by default): the recurrence c'_{k-1} = c'_{k+1} + 2 k c_k, times 2 / (zmax - zmin)",
    )
    .input(PortSpec::new("x", PortType::Linear, "Chebyshev coefficients along z (a real, complex or half-complex grid)"))
    .output(PortSpec::new("out", PortType::Linear, "the derivative's coefficients, the same type with the components taken"))
    .param(ParamSpec::f32_positive(
        "height",
        Some(2.0),
        "zmax - zmin, the domain's extent in z (2: the derivative on [-1, 1])",
    ))
    .param(ParamSpec::integer(
        "first",
        Some(0.0),
        0.0,
        1024.0,
        "the first component differentiated",
    ))
    .param(ParamSpec::integer(
        "count",
        Some(0.0),
        0.0,
        1024.0,
        "how many components (0: all from `first`)",
    ))
    .build(|p| {
        Ok(Box::new(Derivative {
            scale: 2.0 / p.number("height"),
            first: p.number("first") as u64,
            count: p.number("count") as u64,
        }))
    })
}

struct Derivative {
    scale: f64,
    /// The components differentiated: `count` from `first` (0: all the rest).
    first: u64,
    count: u64,
}

impl Derivative {
    /// The components taken from an input of `comps`.
    fn taken(&self, comps: u64) -> u64 {
        components_taken(comps, self.first, self.count)
    }
}

/// `count` components from `first` of `comps` (0: all the rest).
fn components_taken(comps: u64, first: u64, count: u64) -> u64 {
    if count == 0 {
        comps.saturating_sub(first)
    } else {
        count
    }
}

/// The same grid with `comps` components.
fn with_comps(t: ValueType, comps: u32) -> ValueType {
    match t {
        ValueType::RealGrid { dims, .. } => ValueType::RealGrid { dims, comps },
        ValueType::ComplexGrid { dims, .. } => ValueType::ComplexGrid { dims, comps },
        ValueType::HalfComplexGrid { dims, .. } => ValueType::HalfComplexGrid { dims, comps },
        other => other,
    }
}

/// How `chebyshev_derivative` runs, decided from the number of lines: the recurrence (n
/// serial steps a line, each word read and written once) where the lines fill the GPU,
/// the dense product (every output in parallel, n terms each) where they are few.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum DerivativePlan {
    Recurrence,
    Dense,
}

impl std::fmt::Display for DerivativePlan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            DerivativePlan::Recurrence => "strategy: recurrence, one thread a line",
            DerivativePlan::Dense => "strategy: dense product, chunks of outputs a thread",
        })
    }
}

/// Lines from which the recurrence beats the dense product (H100, 33 points: dense 0.011
/// against 0.015 ms at 11160 lines, recurrence 0.016 against 0.042 ms at 107730; the
/// crossing was not measured finer).
const RECURRENCE_LINES: u64 = 1 << 15;

impl Node for Derivative {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let t = inputs[0].expect("required");
        let (comps, _, plane) = check_grid(&t)?;
        let taken = self.taken(comps);
        if taken == 0 || self.first + taken > comps {
            return Err(PortError::new(
                "x",
                format!(
                    "has {comps} components: components {} to {} cannot be taken (params `first` {}, `count` {})",
                    self.first,
                    self.first + taken.max(1) - 1,
                    self.first,
                    self.count
                ),
            ));
        }
        let plan = if taken * plane >= RECURRENCE_LINES {
            DerivativePlan::Recurrence
        } else {
            DerivativePlan::Dense
        };
        Ok(Signature::outputs(vec![with_comps(t, taken as u32)]).with_plan(plan))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let x = inputs[0].as_ref().expect("required");
        outputs[0] = derivative_reference(x, self.first, self.count, self.scale);
    }
}

impl GpuKernels for Derivative {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let x = io.inputs[0].expect("required");
        let (_, n, plane) = lines(&x.ty).expect("checked in infer");
        let (comps, _, _) = lines(&io.outputs[0].ty).expect("checked in infer");
        let x_offset = (self.first * n * plane) as u32;
        if *io.plan::<DerivativePlan>() == DerivativePlan::Dense {
            return line_product(
                cx,
                io,
                "chebyshev derivative",
                &derivative_matrix(n as usize, self.scale),
                x_offset,
            );
        }
        let shape = Shape {
            comps: comps as u32,
            n: n as u32,
            plane: plane as u32,
            scale: self.scale as f32,
            x_offset,
            pad: [0; 3],
        };
        let kernel = cx.kernel(&KernelSpec::new(
            "chebyshev derivative",
            cx.shader("chebyshev/derivative.wgsl")?,
            &[
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::Uniform,
            ],
        ))?;
        let u = cx.uniform("chebyshev derivative shape", bytemuck::bytes_of(&shape));
        Ok(vec![cx.dispatch(
            &kernel,
            &[x.buffer, io.outputs[0].buffer, &u],
            cx.grid_1d(comps * plane, WG_1D),
        )])
    }
}

/// The recurrence as a matrix: c'_k = scale (1 / kappa_k) sum over j > k with j - k odd of
/// 2 j c_j (kappa_0 = 2, else 1), so the derivative runs as a dense product (every output
/// in parallel) rather than n serial steps per line.
fn derivative_matrix(n: usize, scale: f64) -> Vec<f64> {
    let mut m = vec![0.0; n * n];
    for k in 0..n {
        let half = if k == 0 { 0.5 } else { 1.0 };
        for j in (k + 1..n).step_by(2) {
            m[k * n + j] = scale * half * 2.0 * j as f64;
        }
    }
    m
}

pub fn register(r: &mut Registry) {
    r.add(transform_kind());
    r.add(derivative_kind());
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Small grids take short chunks (more threads), large grids whole lines, and no
    /// thread loops more than 32768 times.
    #[test]
    fn line_products_fill_the_gpu_and_stay_under_lavapipes_loop_limit() {
        assert_eq!(product_chunk(33, 1 << 20), 33);
        assert_eq!(product_chunk(33, 11160), 3);
        assert_eq!(product_chunk(33, 1), 1);
        for n in [2u32, 33, 181, 300, 1024] {
            for lines in [1u64, 1000, 1 << 17, 1 << 22] {
                let c = product_chunk(n, lines);
                assert!(
                    c >= 1 && c <= n && n + c * n <= 32768,
                    "n {n} lines {lines}: {c}"
                );
            }
        }
    }

    /// The derivative's matrix is its recurrence.
    #[test]
    fn the_derivative_matrix_is_the_recurrence() {
        let n = 9;
        let m = derivative_matrix(n, 0.7);
        for e in 0..n {
            let mut c = vec![0.0; n];
            c[e] = 1.0;
            let want = derivative(&c, 0.7);
            for k in 0..n {
                assert!((m[k * n + e] - want[k]).abs() < 1e-12, "({k}, {e})");
            }
        }
    }

    /// The forward matrix inverts the inverse one, in f64.
    #[test]
    fn forward_and_inverse_are_inverse() {
        for n in [2, 3, 8, 33] {
            let (f, b) = (matrix(n, true), matrix(n, false));
            for i in 0..n {
                for j in 0..n {
                    let v: f64 = (0..n).map(|k| f[i * n + k] * b[k * n + j]).sum();
                    let want = if i == j { 1.0 } else { 0.0 };
                    assert!((v - want).abs() < 1e-12, "n {n} [{i}][{j}] = {v}");
                }
            }
        }
    }
}
