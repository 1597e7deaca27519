//! Krylov (Lanczos) evaluation of f(M) z for a symmetric positive definite operator M
//! given only through its product: the node's loop body (any nodes that read its `basis`
//! output and end in its `product` input) computes M v for the current basis vector.
//!
//! GPU: the basis vectors, the three-term recurrence and the final combination
//! (shaders/lanczos/lanczos.wgsl). Host, in f64, after every iteration: the tridiagonal
//! T_k from alpha and beta, its eigendecomposition (cyclic Jacobi), y_k = |z| f(T_k) e1,
//! and the stopping rule of Ando et al. (2012), eq. 27: the relative change
//! |y_k - y_(k-1)| / |y_k| at most `tolerance`. The answer is V_k y_k.

use crate::gpu::DeviceCaps;
use crate::gpu::{Binding, CompileCtx, CompileError, KernelSpec, NodeIo};
use crate::node::{
    Decision, GpuIterative, IterativeKernels, LoopError, Lowering, Node, NodeKind, ParamSpec,
    PortError, PortSpec, RefCtx, Registry, Signature,
};
use crate::value::{PortType, RefArray, ValueType};

const WG: u64 = 256;

fn lanczos_kind() -> NodeKind {
    NodeKind::declare(
        "lanczos",
        "f(M) z by Lanczos iteration for an SPD operator M given by the loop body (basis -> nodes -> product), stopping at a relative change below the tolerance",
    )
    .input(PortSpec::new(
        "z",
        PortType::Particles(None),
        "the vector (W for Brownian noise)",
    ))
    .input(
        PortSpec::new(
            "product",
            PortType::Particles(None),
            "M basis: the loop body's result for the current basis vector",
        )
        .iterate(),
    )
    .output(PortSpec::new("out", PortType::Particles(None), "f(M) z"))
    .output(
        PortSpec::new(
            "basis",
            PortType::Particles(None),
            "the current Lanczos vector: the loop body computes M basis from it",
        )
        .iterate(),
    )
    .param(ParamSpec::number(
        "tolerance",
        Some(1e-3),
        1e-7,
        0.5,
        "stop when the relative change of the iterate falls below this (f32 limits it to about 1e-6)",
    ))
    .param(ParamSpec::integer(
        "max_iterations",
        Some(100.0),
        1.0,
        1000.0,
        "iteration cap: not converging within it is an error (it also sizes the basis storage: cap + 3 vectors)",
    ))
    .param(ParamSpec::choice(
        "function",
        "sqrt",
        &["sqrt", "inverse_sqrt"],
        "f: M^(1/2) z (Brownian noise) or M^(-1/2) z",
    ))
    .build(|p| {
        Ok(Box::new(Lanczos {
            tolerance: p.number("tolerance"),
            max_iterations: p.number("max_iterations") as u32,
            inverse: p.text("function") == "inverse_sqrt",
        }))
    })
}

pub struct Lanczos {
    tolerance: f64,
    max_iterations: u32,
    inverse: bool,
}

/// Word offsets into the `small` buffer (see the shader): counter, |z|, alpha, beta,
/// answer (m, coefficients), partial sums a and b.
#[derive(Clone, Copy, Debug)]
struct Layout {
    max_iter: u32,
    parts: u32,
}

impl Layout {
    fn new(n: u64, max_iter: u32) -> Self {
        Layout {
            max_iter,
            parts: n.div_ceil(WG).clamp(1, WG) as u32,
        }
    }
    fn alpha(&self) -> u32 {
        4
    }
    // alpha and beta hold max_iter + 1 entries: the executor may run one speculative
    // iteration past the cap before the host stops the loop.
    fn beta(&self) -> u32 {
        4 + self.max_iter + 1
    }
    fn answer(&self) -> u32 {
        4 + 2 * (self.max_iter + 1)
    }
    fn partial_a(&self) -> u32 {
        self.answer() + 1 + self.max_iter
    }
    fn partial_b(&self) -> u32 {
        self.partial_a() + self.parts
    }
    fn words(&self) -> u32 {
        self.partial_b() + self.parts
    }
    /// The status the host reads: counter, |z|, alpha and beta.
    fn status_words(&self) -> u32 {
        self.answer()
    }
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Shape {
    n: u32,
    max_iter: u32,
    parts: u32,
    alpha: u32,
    beta: u32,
    answer: u32,
    partial_a: u32,
    partial_b: u32,
}

impl Node for Lanczos {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let z = inputs[0].expect("required");
        if let Some(p) = inputs[1]
            && p != z
        {
            return Err(PortError::new(
                "product",
                format!("is {p} but z is {z}: the operator must map a vector to one of its shape"),
            ));
        }
        let layout = Layout::new(z.words(), self.max_iterations);
        Ok(Signature::outputs(vec![z, z]).with_scratch(vec![
            (self.max_iterations as u64 + 3) * z.bytes(),
            4 * layout.words() as u64,
        ]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Iterative(self)
    }

    fn notes(&self, inputs: &[Option<ValueType>]) -> Vec<String> {
        let words = inputs[0].map(|t| t.words()).unwrap_or(0);
        vec![format!(
            "{} by Lanczos, relative change <= {:e}, at most {} iterations ({} basis vectors of {words} words); one host round trip per iteration",
            if self.inverse {
                "M^(-1/2) z"
            } else {
                "M^(1/2) z"
            },
            self.tolerance,
            self.max_iterations,
            self.max_iterations + 3,
        )]
    }

    /// There is no reference for the node alone: M exists only as the loop body. The
    /// tests assemble M and compare with its eigendecomposition; this fills NaN so that
    /// nothing can mistake it for a result.
    fn cpu_reference(&self, _: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        for o in outputs {
            o.data.fill(f64::NAN);
        }
    }
}

impl GpuIterative for Lanczos {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<IterativeKernels, CompileError> {
        let z = io.inputs[0].expect("required");
        let product = io.inputs[1].expect("the planner connects the loop");
        let n = z.ty.words();
        let layout = Layout::new(n, self.max_iterations);
        let shape = Shape {
            n: n as u32,
            max_iter: self.max_iterations,
            parts: layout.parts,
            alpha: layout.alpha(),
            beta: layout.beta(),
            answer: layout.answer(),
            partial_a: layout.partial_a(),
            partial_b: layout.partial_b(),
        };
        let shape = cx.uniform("lanczos shape", bytemuck::bytes_of(&shape));
        let source = cx.shader("lanczos/lanczos.wgsl")?;
        let bindings = [
            Binding::StorageRead,
            Binding::StorageRead,
            Binding::StorageReadWrite,
            Binding::StorageReadWrite,
            Binding::StorageReadWrite,
            Binding::StorageReadWrite,
            Binding::Uniform,
        ];
        let (rows, small) = (io.scratch[0], io.scratch[1]);
        let buffers = [
            z.buffer,
            product.buffer,
            io.outputs[0].buffer,
            io.outputs[1].buffer,
            rows,
            small,
            &shape,
        ];
        let combine_groups = cx.grid_1d(n, WG as u32);
        let mut dispatch = |entry: &str, groups: [u32; 3]| -> Result<_, CompileError> {
            let k = cx.kernel(
                &KernelSpec::new(format!("lanczos {entry}"), source.clone(), &bindings)
                    .entry(entry),
            )?;
            Ok(cx.dispatch(&k, &buffers, groups))
        };
        let parts = [layout.parts, 1, 1];
        let start = vec![
            dispatch("start_partial", parts)?,
            dispatch("start_scale", parts)?,
        ];
        let iterate = vec![
            dispatch("dot_partial", parts)?,
            dispatch("update", parts)?,
            dispatch("next_vector", parts)?,
            dispatch("advance", [1, 1, 1])?,
        ];
        let finish = vec![dispatch("combine", combine_groups)?];
        Ok(IterativeKernels {
            start,
            iterate,
            finish,
            status: small.clone(),
            status_bytes: 4 * layout.status_words() as u64,
            answer: small.clone(),
            answer_offset: 4 * layout.answer() as u64,
            gpu_stop: None,
        })
    }

    fn decide(&self, iterations: usize, status: &[u8]) -> Result<Decision, LoopError> {
        let words: &[u32] = bytemuck::cast_slice(status);
        let layout = Layout::new(1, self.max_iterations);
        let f = |w: u32| f32::from_bits(w) as f64;
        let counter = words[0] as usize;
        if counter != iterations {
            return Err(LoopError::Internal(format!(
                "the GPU counted {counter} iterations, the host {iterations}"
            )));
        }
        let norm = f(words[1]);
        if !norm.is_finite() {
            return Err(LoopError::Input(format!(
                "the input vector z is not finite (|z| = {norm})"
            )));
        }
        let answer = |coefficients: &[f64]| -> Decision {
            let mut bytes = (coefficients.len() as u32).to_le_bytes().to_vec();
            for c in coefficients {
                bytes.extend_from_slice(&(*c as f32).to_le_bytes());
            }
            Decision::Finish(bytes)
        };
        if norm == 0.0 {
            return Ok(answer(&[]));
        }
        let k = iterations;
        let alpha: Vec<f64> = (0..k)
            .map(|i| f(words[(layout.alpha() as usize) + i]))
            .collect();
        let beta: Vec<f64> = (0..k)
            .map(|i| f(words[(layout.beta() as usize) + i]))
            .collect();
        if alpha.iter().chain(&beta).any(|x| !x.is_finite()) {
            return Err(LoopError::Operator(format!(
                "the operator returned non-finite values (NaN or inf) at iteration {k}"
            )));
        }
        let y = self.coefficients(&alpha, &beta[..k - 1])?;
        let scale = alpha.iter().map(|a| a.abs()).fold(0.0, f64::max);
        // A zero beta: the basis spans an invariant subspace, and y is exact.
        let breakdown = beta[k - 1] <= 1e-6 * scale;
        let done = |y: Vec<f64>| Ok(answer(&y.iter().map(|c| c * norm).collect::<Vec<_>>()));
        if breakdown {
            return done(y);
        }
        if k >= 2 {
            let previous = self.coefficients(&alpha[..k - 1], &beta[..k - 2])?;
            let change = (0..k)
                .map(|i| {
                    let d = y[i] - previous.get(i).copied().unwrap_or(0.0);
                    d * d
                })
                .sum::<f64>()
                .sqrt()
                / y.iter().map(|c| c * c).sum::<f64>().sqrt();
            if change <= self.tolerance {
                return done(y);
            }
            if k >= self.max_iterations as usize {
                return Err(LoopError::NoConvergence(format!(
                    "no convergence after {k} iterations (max_iterations): the relative change is {change:.3e}, above the tolerance {:e}; raise max_iterations or the tolerance (is M badly conditioned?)",
                    self.tolerance
                )));
            }
        } else if k >= self.max_iterations as usize {
            return done(y);
        }
        Ok(Decision::Continue)
    }
}

impl Lanczos {
    /// f(T) e1 for the tridiagonal T with diagonal `alpha` and off-diagonal `beta`.
    fn coefficients(&self, alpha: &[f64], beta: &[f64]) -> Result<Vec<f64>, LoopError> {
        let k = alpha.len();
        let mut t = vec![0.0; k * k];
        for i in 0..k {
            t[i * k + i] = alpha[i];
            if i + 1 < k {
                t[i * k + i + 1] = beta[i];
                t[(i + 1) * k + i] = beta[i];
            }
        }
        let (values, vectors) = symmetric_eigen(&t, k);
        let largest = values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        // f32 products leave eigenvalues of T a few ulps off; clear negatives are an
        // operator that is not positive definite.
        let floor = -1e-5 * largest;
        let mut y = vec![0.0; k];
        for (j, &lambda) in values.iter().enumerate() {
            if lambda < floor {
                return Err(LoopError::Operator(format!(
                    "the operator is not positive definite: Lanczos found the eigenvalue {lambda:.6e} (largest {largest:.6e})"
                )));
            }
            let f = if self.inverse {
                if lambda <= 1e-7 * largest {
                    return Err(LoopError::Operator(format!(
                        "the operator is singular to f32 precision (eigenvalue {lambda:.3e} of largest {largest:.3e}): M^(-1/2) is not defined"
                    )));
                }
                1.0 / lambda.sqrt()
            } else {
                lambda.max(0.0).sqrt()
            };
            // (P f(L) P^T e1)_i = sum_j P_ij f(l_j) P_0j
            let w = f * vectors[j];
            for (i, yi) in y.iter_mut().enumerate() {
                *yi += vectors[i * k + j] * w;
            }
        }
        Ok(y)
    }
}

/// Eigenvalues and eigenvectors (columns of the row-major k x k result) of a symmetric
/// matrix, by cyclic Jacobi rotations in f64: small k (Lanczos T), full accuracy.
pub fn symmetric_eigen(a: &[f64], k: usize) -> (Vec<f64>, Vec<f64>) {
    let mut a = a.to_vec();
    let mut v = vec![0.0; k * k];
    for i in 0..k {
        v[i * k + i] = 1.0;
    }
    for _sweep in 0..100 {
        let off: f64 = (0..k)
            .flat_map(|i| (0..k).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i * k + j] * a[i * k + j])
            .sum();
        let total: f64 = a.iter().map(|x| x * x).sum();
        if off <= 1e-30 * total || off == 0.0 {
            break;
        }
        for p in 0..k {
            for q in p + 1..k {
                let apq = a[p * k + q];
                if apq == 0.0 {
                    continue;
                }
                let theta = (a[q * k + q] - a[p * k + p]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for r in 0..k {
                    let arp = a[r * k + p];
                    let arq = a[r * k + q];
                    a[r * k + p] = c * arp - s * arq;
                    a[r * k + q] = s * arp + c * arq;
                }
                for r in 0..k {
                    let apr = a[p * k + r];
                    let aqr = a[q * k + r];
                    a[p * k + r] = c * apr - s * aqr;
                    a[q * k + r] = s * apr + c * aqr;
                }
                for r in 0..k {
                    let vrp = v[r * k + p];
                    let vrq = v[r * k + q];
                    v[r * k + p] = c * vrp - s * vrq;
                    v[r * k + q] = s * vrp + c * vrq;
                }
            }
        }
    }
    ((0..k).map(|i| a[i * k + i]).collect(), v)
}

/// A dense matrix times a vector: small operators assembled on the host (a mobility
/// matrix for a few particles, a test matrix for `lanczos`).
fn matvec_kind() -> NodeKind {
    NodeKind::declare(
        "matvec",
        "A x for a dense square matrix A (n x n rows) and a vector x of n words (any particle shape)",
    )
    .input(PortSpec::new(
        "matrix",
        PortType::Particles(None),
        "A, n rows of n",
    ))
    .input(PortSpec::new(
        "x",
        PortType::Particles(None),
        "x, n words in all",
    ))
    .output(PortSpec::new(
        "out",
        PortType::Particles(None),
        "A x, shaped like x",
    ))
    .build(|_| Ok(Box::new(Matvec)))
}

struct Matvec;

impl Node for Matvec {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let (Some(ValueType::Particles { n: rows, k: cols }), Some(x)) = (inputs[0], inputs[1])
        else {
            unreachable!("port types checked")
        };
        if rows != cols || rows as u64 != x.words() {
            return Err(PortError::new(
                "matrix",
                format!(
                    "is {rows} x {cols}; it must be square with as many columns as x has words ({})",
                    x.words()
                ),
            ));
        }
        Ok(Signature::outputs(vec![x]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let a = &inputs[0].as_ref().expect("required").data;
        let x = &inputs[1].as_ref().expect("required").data;
        let n = x.len();
        for (i, out) in outputs[0].data.iter_mut().enumerate() {
            *out = (0..n).map(|j| a[i * n + j] * x[j]).sum();
        }
    }
}

impl crate::node::GpuKernels for Matvec {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<crate::gpu::Dispatch>, CompileError> {
        let a = io.inputs[0].expect("required");
        let x = io.inputs[1].expect("required");
        let n = x.ty.words();
        let kernel = cx.kernel(&KernelSpec::new(
            "matvec",
            cx.shader("lanczos/matvec.wgsl")?,
            &[
                Binding::StorageRead,
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::Uniform,
            ],
        ))?;
        let shape = cx.uniform("matvec shape", bytemuck::bytes_of(&(n as u32)));
        Ok(vec![cx.dispatch(
            &kernel,
            &[a.buffer, x.buffer, io.outputs[0].buffer, &shape],
            cx.grid_1d(n, WG as u32),
        )])
    }
}

pub fn register(r: &mut Registry) {
    r.add(lanczos_kind());
    r.add(matvec_kind());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobi_diagonalises() {
        let a = [4.0, 1.0, 0.0, 1.0, 3.0, 0.5, 0.0, 0.5, 2.0];
        let (l, v) = symmetric_eigen(&a, 3);
        for j in 0..3 {
            for i in 0..3 {
                let av: f64 = (0..3).map(|m| a[i * 3 + m] * v[m * 3 + j]).sum();
                assert!((av - l[j] * v[i * 3 + j]).abs() < 1e-12);
            }
        }
        assert!((l.iter().sum::<f64>() - 9.0).abs() < 1e-12);
    }

    #[test]
    fn coefficients_of_a_diagonal_tridiagonal() {
        let node = Lanczos {
            tolerance: 1e-6,
            max_iterations: 10,
            inverse: false,
        };
        // T = diag(4, 9) with no coupling: f(T) e1 = (2, 0).
        let y = node.coefficients(&[4.0, 9.0], &[0.0]).unwrap();
        assert!((y[0] - 2.0).abs() < 1e-14 && y[1].abs() < 1e-14);
        let err = node.coefficients(&[-1.0, 9.0], &[0.0]).unwrap_err();
        assert!(
            matches!(&err, LoopError::Operator(m) if m.contains("not positive definite")),
            "{err}"
        );
    }

    #[test]
    fn scalar_params_have_defaults() {
        let kind = lanczos_kind();
        let specs = kind.params();
        assert!(specs.iter().all(|s| s.default.is_some()));
        assert!(matches!(
            specs[0].default,
            Some(crate::expr::ParamValue::Number(_))
        ));
    }
}
