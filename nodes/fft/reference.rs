//! f64 CPU references of the transforms (rustfft), with numpy's conventions: the
//! yardstick the GPU kernels are tested against.

use num_complex::Complex64;
use rustfft::{FftDirection, FftPlanner};

use super::plan::Kind;
use crate::value::{RefArray, ValueType, half_dims};

/// Unnormalised complex transforms, in place, along every axis in `axes`, of `comps`
/// grids of `dims` (x fastest, component-major).
fn c2c(data: &mut [Complex64], dims: [usize; 3], comps: usize, axes: [bool; 3], inverse: bool) {
    let dir = if inverse {
        FftDirection::Inverse
    } else {
        FftDirection::Forward
    };
    let cells = dims[0] * dims[1] * dims[2];
    let mut planner = FftPlanner::new();
    for axis in (0..3).filter(|&a| axes[a] && dims[a] > 1) {
        let n = dims[axis];
        let stride: usize = dims[..axis].iter().product();
        let fft = planner.plan_fft(n, dir);
        // Strided lines are gathered in blocks of neighbours, so the host reads whole
        // cache lines (the bench checks 384^3 grids).
        const BLOCK: usize = 64;
        let mut lines = vec![Complex64::default(); n * BLOCK.min(stride)];
        for c in 0..comps {
            for outer in 0..cells / (n * stride) {
                for first in (0..stride).step_by(BLOCK) {
                    let count = BLOCK.min(stride - first);
                    let base = c * cells + outer * n * stride + first;
                    let buf = &mut lines[..n * count];
                    for i in 0..n {
                        for b in 0..count {
                            buf[b * n + i] = data[base + i * stride + b];
                        }
                    }
                    fft.process(buf);
                    for i in 0..n {
                        for b in 0..count {
                            data[base + i * stride + b] = buf[b * n + i];
                        }
                    }
                }
            }
        }
    }
}

fn complex(words: &[f64]) -> Vec<Complex64> {
    words
        .chunks_exact(2)
        .map(|p| Complex64::new(p[0], p[1]))
        .collect()
}

fn words(values: &[Complex64]) -> Vec<f64> {
    values.iter().flat_map(|v| [v.re, v.im]).collect()
}

fn usize3(d: [u32; 3]) -> [usize; 3] {
    d.map(|x| x as usize)
}

/// The transform `kind` over `axes` of `input` into `output` (types as inferred).
pub fn transform(kind: Kind, axes: [bool; 3], input: &RefArray, output: &mut RefArray) {
    let (dims, comps) = match input.ty {
        ValueType::RealGrid { dims, comps }
        | ValueType::ComplexGrid { dims, comps }
        | ValueType::HalfComplexGrid { dims, comps } => (dims, comps as usize),
        other => unreachable!("FFT input {other}"),
    };
    let d = usize3(dims);
    let active = |a: usize| axes[a] && d[a] > 1;
    let n_total: usize = (0..3).filter(|&a| active(a)).map(|a| d[a]).product();
    let cells = d[0] * d[1] * d[2];
    match kind {
        Kind::Forward | Kind::Inverse => {
            let mut v = complex(&input.data);
            c2c(&mut v, d, comps, axes, kind == Kind::Inverse);
            if kind == Kind::Inverse {
                v.iter_mut().for_each(|x| *x /= n_total as f64);
            }
            output.data = words(&v);
        }
        Kind::RealForward => {
            let mut v: Vec<Complex64> =
                input.data.iter().map(|&x| Complex64::new(x, 0.0)).collect();
            c2c(&mut v, d, comps, axes, false);
            let h = usize3(half_dims(dims));
            let mut out = Vec::with_capacity(h[0] * h[1] * h[2] * comps);
            for c in 0..comps {
                for row in 0..d[1] * d[2] {
                    let base = c * cells + row * d[0];
                    out.extend_from_slice(&v[base..base + h[0]]);
                }
            }
            output.data = words(&out);
        }
        Kind::RealInverse => {
            let h = usize3(half_dims(dims));
            let mut v = complex(&input.data);
            c2c(&mut v, h, comps, [false, axes[1], axes[2]], true);
            // Along x: the Hermitian extension's inverse transform, real part (the
            // imaginary parts of X[0] and X[nx/2] drop out, as in numpy's irfft).
            let nx = d[0];
            let fft = FftPlanner::new().plan_fft_inverse(nx);
            let mut line = vec![Complex64::default(); nx];
            let mut out = Vec::with_capacity(cells * comps);
            for row in 0..comps * d[1] * d[2] {
                let half = &v[row * h[0]..(row + 1) * h[0]];
                for (k, x) in line.iter_mut().enumerate() {
                    *x = if k < h[0] {
                        half[k]
                    } else {
                        half[nx - k].conj()
                    };
                }
                fft.process(&mut line);
                out.extend(line.iter().map(|x| x.re / n_total as f64));
            }
            output.data = out;
        }
    }
}
