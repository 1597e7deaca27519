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
//!   as a dense n x n matrix computed in f64 on the host (a dedicated pass: n reads per
//!   output word, for the tens to a few hundred points these solvers take).
//! - `chebyshev_derivative`: the coefficients of df/dz = (2 / (zmax - zmin)) df/dxi by the
//!   backward recurrence c'_{k-1} = c'_{k+1} + 2 k c_k (c'_0 halved), one thread a line.

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

/// Both nodes' signature: a grid of Chebyshev lines in, the same type out.
fn same_grid(inputs: &[Option<ValueType>]) -> Result<Signature, PortError> {
    let t = inputs[0].expect("required");
    check_grid(&t)?;
    Ok(Signature::outputs(vec![t]))
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
        same_grid(inputs)
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let x = inputs[0].as_ref().expect("required");
        let (_, n, _) = lines(&x.ty).expect("checked");
        let n = n as usize;
        let m = matrix(n, self.forward);
        per_line(&x.ty, &x.data, &mut outputs[0].data, |line| {
            (0..n)
                .map(|a| (0..n).map(|b| m[a * n + b] * line[b]).sum())
                .collect()
        });
    }
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Shape {
    comps: u32,
    n: u32,
    plane: u32,
    scale: f32,
}

fn shape(t: &ValueType, scale: f64) -> Shape {
    let (comps, n, plane) = lines(t).expect("checked in infer");
    Shape {
        comps: comps as u32,
        n: n as u32,
        plane: plane as u32,
        scale: scale as f32,
    }
}

impl GpuKernels for Transform {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let x = io.inputs[0].expect("required");
        let s = shape(&x.ty, 1.0);
        let m: Vec<f32> = matrix(s.n as usize, self.forward)
            .iter()
            .map(|&v| v as f32)
            .collect();
        let wg = line_workgroup(s.n, cx.caps().max_workgroup_storage);
        let chunk = transform_chunk(s.n);
        let source = format!(
            "const WG: u32 = {wg}u;\nconst POINTS: u32 = {}u;\nconst CHUNK: u32 = {chunk}u;\n{}",
            s.n,
            cx.shader("chebyshev/transform.wgsl")?
        );
        let kernel = cx.kernel(&KernelSpec::new(
            "chebyshev transform",
            source,
            &[
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::StorageRead,
                Binding::Uniform,
            ],
        ))?;
        let table = cx.table("chebyshev matrix", bytemuck::cast_slice(&m));
        let u = cx.uniform("chebyshev shape", bytemuck::bytes_of(&s));
        Ok(vec![cx.dispatch(
            &kernel,
            &[x.buffer, io.outputs[0].buffer, &table, &u],
            cx.grid_1d(
                s.comps as u64 * s.plane as u64 * s.n.div_ceil(chunk) as u64,
                wg,
            ),
        )])
    }
}

/// Outputs per thread of the transform: all n where a thread's loops (n loads, n
/// products of n terms per output) stay within 32768 iterations, fewer for long lines
/// (lavapipe stops a thread after 65535 loop iterations).
fn transform_chunk(n: u32) -> u32 {
    (32768 / n.max(1)).saturating_sub(1).clamp(1, n.max(1))
}

/// Threads per workgroup of a kernel that keeps one line of `n` f32 words per thread in
/// workgroup memory (the transform here, chebyshev_bvp's solve): the largest power of two
/// up to 64 whose lines fit in `storage` bytes (at least 1: n is at most MAX_POINTS, whose
/// line fits the 16 KiB every adapter has).
pub fn line_workgroup(n: u32, storage: u32) -> u32 {
    let fit = (storage / (4 * n.max(1))).clamp(1, 64);
    1 << (31 - fit.leading_zeros())
}

fn derivative_kind() -> NodeKind {
    NodeKind::declare(
        "chebyshev_derivative",
        "the Chebyshev coefficients of df/dz from those of f (along z of a grid, every line and component alone): the recurrence c'_{k-1} = c'_{k+1} + 2 k c_k, times 2 / (zmax - zmin)",
    )
    .input(PortSpec::new("x", PortType::Linear, "Chebyshev coefficients along z (a real, complex or half-complex grid)"))
    .output(PortSpec::new("out", PortType::Linear, "the derivative's coefficients, the same type"))
    .param(ParamSpec::f32_positive(
        "height",
        Some(2.0),
        "zmax - zmin, the domain's extent in z (2: the derivative on [-1, 1])",
    ))
    .build(|p| {
        Ok(Box::new(Derivative {
            scale: 2.0 / p.number("height"),
        }))
    })
}

struct Derivative {
    scale: f64,
}

impl Node for Derivative {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        same_grid(inputs)
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let x = inputs[0].as_ref().expect("required");
        per_line(&x.ty, &x.data, &mut outputs[0].data, |c| {
            derivative(c, self.scale)
        });
    }
}

impl GpuKernels for Derivative {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let x = io.inputs[0].expect("required");
        let s = shape(&x.ty, self.scale);
        let kernel = cx.kernel(&KernelSpec::new(
            "chebyshev derivative",
            cx.shader("chebyshev/derivative.wgsl")?,
            &[
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::Uniform,
            ],
        ))?;
        let u = cx.uniform("chebyshev shape", bytemuck::bytes_of(&s));
        let lines = s.comps as u64 * s.plane as u64;
        Ok(vec![cx.dispatch(
            &kernel,
            &[x.buffer, io.outputs[0].buffer, &u],
            cx.grid_1d(lines, WG_1D),
        )])
    }
}

pub fn register(r: &mut Registry) {
    r.add(transform_kind());
    r.add(derivative_kind());
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A thread's loops stay within 32768 iterations, and short lines take one chunk.
    #[test]
    fn long_transforms_are_cut_into_chunks() {
        assert_eq!(transform_chunk(34), 34);
        assert_eq!(transform_chunk(180), 180);
        for n in [2u32, 181, 300, 1024] {
            let c = transform_chunk(n);
            assert!(c >= 1 && c <= n && n + c * n <= 32768, "n {n}: {c}");
        }
    }

    /// Workgroups shrink by powers of two as lines grow, never below one thread.
    #[test]
    fn lines_fit_the_workgroup_memory() {
        assert_eq!(line_workgroup(34, 32768), 64);
        assert_eq!(line_workgroup(300, 32768), 16);
        assert_eq!(line_workgroup(1024, 16384), 4);
        assert_eq!(line_workgroup(1024, 100), 1);
        for n in [2, 33, 129, 1000] {
            let wg = line_workgroup(n, 16384);
            assert!(wg.is_power_of_two() && wg * n * 4 <= 16384, "n {n}: {wg}");
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
