//! Spectral operations: functions of the wave vector applied to all components of a
//! spectrum at once. Placed between a forward and an inverse transform they are folded
//! into the forward transform's last pass (see `src/plan/spectral.rs`), so a convolution
//! costs no pass over the grid of its own.
//!
//! Wave vectors are in physical units of the periodic box (lengths Lx, Ly, Lz):
//! k = 2 pi (kx / Lx, ky / Ly, kz / Lz), with signed wave numbers (index i on an axis of n
//! points is i for i <= n/2, else i - n).

use std::f64::consts::PI;

use crate::node::{
    Lowering, Node, NodeKind, ParamKind, ParamSpec, Params, PortError, PortSpec, RefCtx, Registry,
    Signature, SpectralBody,
};
use crate::value::{PortType, RefArray, ValueType, half_dims};

/// The signed wave number of index `i` on an axis of `n` points (see the module doc).
pub fn wave_number(i: u32, n: u32) -> i64 {
    if i > n / 2 {
        i as i64 - n as i64
    } else {
        i as i64
    }
}

fn box_param() -> ParamSpec {
    ParamSpec {
        name: "box",
        kind: ParamKind::Numbers {
            len: Some(3),
            min: 0.0,
            max: f64::INFINITY,
        },
        default: Some(crate::expr::ParamValue::Numbers(vec![1.0, 1.0, 1.0])),
        doc: "periodic box lengths (Lx, Ly, Lz): k = 2 pi (kx/Lx, ky/Ly, kz/Lz)",
    }
}

/// The f64 operation at one wave vector (physical units) on the components, with the
/// kind's own params (after the box lengths).
type Apply = fn(k: [f64; 3], p: &[f64], v: &mut [[f64; 2]]);

struct SpectralKind {
    name: &'static str,
    doc: &'static str,
    params: fn() -> Vec<ParamSpec>,
    /// Components the operation needs (`None`: any count).
    comps: Option<u32>,
    /// f64 params of the reference: the box lengths, then the kind's own.
    values: fn(&Params) -> Vec<f64>,
    /// f32 params of the WGSL body (computed in f64 from `values`, rounded once).
    gpu_params: fn(&[f64]) -> Vec<f32>,
    body: &'static str,
    apply: Apply,
}

static KINDS: &[SpectralKind] = &[
    SpectralKind {
        name: "spectral_filter",
        doc: "Gaussian filter of a spectrum: every component times exp(-sigma^2 |k|^2 / 2), k in units of the box",
        params: || {
            vec![
                ParamSpec::number(
                    "sigma",
                    None,
                    0.0,
                    f64::INFINITY,
                    "filter width (a length)",
                ),
                box_param(),
            ]
        },
        comps: None,
        values: |p| {
            let b = p.numbers("box");
            vec![b[0], b[1], b[2], p.number("sigma")]
        },
        // p0 = -sigma^2 (2 pi)^2 / 2, p1..3 = 1/L: exp(p0 |k/L|^2) with integer k.
        gpu_params: |v| {
            vec![
                (-0.5 * v[3] * v[3] * 4.0 * PI * PI) as f32,
                (1.0 / v[0]) as f32,
                (1.0 / v[1]) as f32,
                (1.0 / v[2]) as f32,
            ]
        },
        body: "let q = vec3<f32>(k) * vec3<f32>(spectral_params[1], spectral_params[2], spectral_params[3]);
    let g = exp(spectral_params[0] * dot(q, q));
    var u = v;
    for (var c = 0u; c < SPECTRAL_COMPS; c++) {
        u[c] = u[c] * g;
    }
    return u;",
        apply: |k, p, v| {
            let g = (-0.5 * p[0] * p[0] * (k[0] * k[0] + k[1] * k[1] + k[2] * k[2])).exp();
            for x in v.iter_mut() {
                x[0] *= g;
                x[1] *= g;
            }
        },
    },
    SpectralKind {
        name: "solenoidal_projection",
        doc: "projection of a 3-component spectrum onto divergence-free fields: (I - k k^T / |k|^2) f; the k = 0 mode is kept",
        params: || vec![box_param()],
        comps: Some(3),
        values: |p| p.numbers("box").to_vec(),
        // Only the direction of k matters: k/L without 2 pi.
        gpu_params: |v| v.iter().map(|l| (1.0 / l) as f32).collect(),
        body: "let q = vec3<f32>(k) * vec3<f32>(spectral_params[0], spectral_params[1], spectral_params[2]);
    let q2 = dot(q, q);
    if (q2 == 0.0) {
        return v;
    }
    let h = q * inverseSqrt(q2);
    let d = h.x * v[0] + h.y * v[1] + h.z * v[2];
    var u = v;
    u[0] = v[0] - h.x * d;
    u[1] = v[1] - h.y * d;
    u[2] = v[2] - h.z * d;
    return u;",
        apply: |k, _, v| {
            let k2 = k[0] * k[0] + k[1] * k[1] + k[2] * k[2];
            if k2 == 0.0 {
                return;
            }
            // k is real: project the real and imaginary parts alike.
            let d = [0, 1].map(|part| (0..3).map(|i| k[i] * v[i][part]).sum::<f64>() / k2);
            for (ki, vi) in k.iter().zip(v.iter_mut()) {
                vi[0] -= ki * d[0];
                vi[1] -= ki * d[1];
            }
        },
    },
];

impl NodeKind for &'static SpectralKind {
    fn name(&self) -> &'static str {
        self.name
    }

    fn doc(&self) -> &'static str {
        self.doc
    }

    fn inputs(&self) -> Vec<PortSpec> {
        vec![PortSpec::new(
            "x",
            PortType::Spectrum,
            "a spectrum (half spectrum of rfft, or full spectrum of fft)",
        )]
    }

    fn outputs(&self) -> Vec<PortSpec> {
        vec![PortSpec::new(
            "out",
            PortType::Spectrum,
            "the result, shaped like the input",
        )]
    }

    fn params(&self) -> Vec<ParamSpec> {
        (self.params)()
    }

    fn build(&self, params: &Params) -> Result<Box<dyn Node>, String> {
        let values = (self.values)(params);
        if values[..3].iter().any(|&l| l <= 0.0) {
            return Err(format!(
                "box lengths must be positive, got {:?}",
                &values[..3]
            ));
        }
        Ok(Box::new(SpectralNode {
            kind: self,
            body: SpectralBody {
                body: self.body.to_string(),
                params: (self.gpu_params)(&values),
            },
            values,
        }))
    }
}

struct SpectralNode {
    kind: &'static SpectralKind,
    values: Vec<f64>,
    body: SpectralBody,
}

impl Node for SpectralNode {
    fn infer(&self, inputs: &[Option<ValueType>]) -> Result<Signature, PortError> {
        let t = inputs
            .first()
            .copied()
            .flatten()
            .ok_or_else(|| PortError::new("x", "a spectral node needs a spectrum"))?;
        let comps = match t {
            ValueType::ComplexGrid { comps, .. } | ValueType::HalfComplexGrid { comps, .. } => {
                comps
            }
            other => return Err(PortError::new("x", format!("{other} is not a spectrum"))),
        };
        if let Some(c) = self.kind.comps
            && c != comps
        {
            return Err(PortError::new(
                "x",
                format!("{} needs {c} components, got {t}", self.kind.name),
            ));
        }
        Ok(Signature::outputs(vec![t]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Spectral(self.body.clone())
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _cx: RefCtx) {
        let Some(x) = &inputs[0] else { return };
        let (dims, comps, half) = match x.ty {
            ValueType::ComplexGrid { dims, comps } => (dims, comps as usize, false),
            ValueType::HalfComplexGrid { dims, comps } => (dims, comps as usize, true),
            _ => return,
        };
        let s = if half { half_dims(dims) } else { dims };
        let cells = (s[0] * s[1] * s[2]) as usize;
        let out = &mut outputs[0].data;
        out.copy_from_slice(&x.data);
        let mut v = vec![[0.0; 2]; comps];
        for cell in 0..cells {
            let c32 = cell as u32;
            let (ix, iy, iz) = (c32 % s[0], (c32 / s[0]) % s[1], c32 / (s[0] * s[1]));
            let kx = if half {
                ix as i64
            } else {
                wave_number(ix, dims[0])
            };
            let ki = [kx, wave_number(iy, dims[1]), wave_number(iz, dims[2])];
            let k = [0, 1, 2].map(|a| 2.0 * PI * ki[a] as f64 / self.values[a]);
            for (c, vc) in v.iter_mut().enumerate() {
                let i = 2 * (c * cells + cell);
                *vc = [x.data[i], x.data[i + 1]];
            }
            (self.kind.apply)(k, &self.values[3..], &mut v);
            for (c, vc) in v.iter().enumerate() {
                let i = 2 * (c * cells + cell);
                out[i] = vc[0];
                out[i + 1] = vc[1];
            }
        }
    }
}

pub fn register(r: &mut Registry) {
    for k in KINDS {
        r.add(k);
    }
}
