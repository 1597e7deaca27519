//! The moves of S1: the Euler-Maruyama step of Brownian disks (eq. 1) and the
//! self-propulsion of active Brownian particles (eq. 10), element-wise (fused by the
//! planner with their neighbours), each wrapping into the box.
//!
//! **Noise convention (S1 eq. 1, sections 2.2 and 2.4).** The displacement is
//! v dt + xi sqrt(D dt) per component, xi standard normal clipped to [-3, 3]: the paper's
//! noise amplitude is sqrt(D dt), not sqrt(2 D dt), so its D is twice the physical
//! diffusion coefficient, and clipping (not re-drawing) the tails leaves each component a
//! variance of `clipped_variance(3)` = 0.995007 (not 1): free disks diffuse with
//! MSD_2D(t) = 2 x 0.995007 D t, a bias of -0.5 % in D that the paper accepts.
//!
//! The angle of an active particle (S1 eq. 11, theta += sqrt(2 D dt) n) needs no node of
//! its own: `random_normal` with std sqrt(2 D dt) added to the angles.

use super::super::pointwise::{BASE, ElemCtx, Param, PointwiseKind, pointwise_kind};
use super::super::random::{normal, seed_param, stream_param};
use super::{box_param, wrap};
use crate::node::{ParamSpec, Params, Registry};
use crate::value::ValueType;

/// The variance of a standard normal clipped to [-c, c]: the part of E[Z^2] inside plus
/// c^2 times the mass outside, (1 - 2Q) - 2 c phi(c) + 2 c^2 Q with Q = P(Z > c).
pub fn clipped_variance(c: f64) -> f64 {
    let q = 0.5 * libm::erfc(c / std::f64::consts::SQRT_2);
    let phi = (-0.5 * c * c).exp() / (2.0 * std::f64::consts::PI).sqrt();
    (1.0 - 2.0 * q) - 2.0 * c * phi + 2.0 * c * c * q
}

fn two_columns(t: &ValueType, _: &[f64]) -> Result<(), String> {
    match t {
        ValueType::Particles { k: 2, .. } => Ok(()),
        other => Err(format!("expected 2-D positions (N x 2), got {other}")),
    }
}

fn box_pair(p: &Params) -> [Param; 2] {
    let b = p.numbers("box");
    [Param::Number(b[0]), Param::Number(b[1])]
}

/// Seed and stream as exact bits (seed low, seed high, stream), as `random_normal` has them.
fn key(p: &Params) -> [Param; 3] {
    let seed = p.number("seed") as u64;
    [
        Param::Bits(seed as u32),
        Param::Bits((seed >> 32) as u32),
        Param::Bits(p.number("stream") as u32),
    ]
}

fn key_of(p: &[f64]) -> (u64, u32) {
    ((p[1] as u64) << 32 | p[0] as u64, p[2] as u32)
}

pub static KINDS: &[PointwiseKind] = &[
    PointwiseKind {
        name: "brownian_step_2d",
        doc: "S1 eq. 1: x + v dt + xi sqrt(D dt) per component, xi a standard normal (seed, stream, step, element) clipped to [-clip, clip], wrapped into the box. The paper's convention: D is twice the physical diffusion coefficient; clipping at 3 leaves xi a variance of 0.995007, so MSD_2D = 2 x 0.995007 D t",
        inputs: &[
            ("x", "positions (N x 2)", false),
            ("v", "velocities (forces in velocity units, S1 eq. 1; absent: 0)", true),
        ],
        params: || {
            vec![
                seed_param(),
                stream_param(),
                ParamSpec::f32_nonnegative("dt", None, "time step"),
                ParamSpec::f32_nonnegative(
                    "diffusion",
                    None,
                    "D of S1 eq. 1: the noise is sqrt(D dt) per component",
                ),
                ParamSpec::number(
                    "clip",
                    Some(3.0),
                    0.0,
                    1e3,
                    "the normal draws are clipped to [-clip, clip] (S1 section 2.4: 3)",
                ),
                box_param(),
            ]
        },
        flatten: |p| {
            let [lo, hi, stream] = key(p);
            let [lx, ly] = box_pair(p);
            vec![
                lo,
                hi,
                stream,
                Param::Number(p.number("dt")),
                Param::Number((p.number("diffusion") * p.number("dt")).sqrt()),
                Param::Number(p.number("clip")),
                lx,
                ly,
            ]
        },
        check: two_columns,
        body: "let xi = clamp(philox_normal(idx, step, bitcast<u32>(p0), bitcast<u32>(p1), bitcast<u32>(p2)), -p5, p5);
    let y = x + v * p3 + p4 * xi;
    let l = select(p7, p6, comp == 0u);
    if (l > 0.0) {
        return y - l * floor((y + 0.5 * l) / l);
    }
    return y;",
        imports: &["common/philox.wgsl"],
        uses_step: true,
        reference: |i, e: ElemCtx, p| {
            let (seed, stream) = key_of(p);
            let xi = normal(e.idx, e.step, seed, stream).clamp(-p[5], p[5]);
            let y = i[0] + i[1] * p[3] + p[4] * xi;
            wrap(y, if e.comp == 0 { p[6] } else { p[7] })
        },
        ..BASE
    },
    PointwiseKind {
        name: "abp_move_2d",
        doc: "S1 eq. 10, the self-propulsion of active Brownian particles: x + speed dt (cos theta, sin theta), wrapped into the box (the angle diffuses by random_normal with std sqrt(2 D dt), S1 eq. 11)",
        inputs: &[
            ("x", "positions (N x 2)", false),
            ("angle", "theta per particle (N x 1)", false),
        ],
        params: || {
            vec![
                ParamSpec::f32_factor("speed", None, "V0"),
                ParamSpec::f32_nonnegative("dt", None, "time step"),
                box_param(),
            ]
        },
        flatten: |p| {
            let [lx, ly] = box_pair(p);
            vec![Param::Number(p.number("speed") * p.number("dt")), lx, ly]
        },
        check: two_columns,
        body: "let y = x + p0 * select(sin(angle), cos(angle), comp == 0u);
    let l = select(p2, p1, comp == 0u);
    if (l > 0.0) {
        return y - l * floor((y + 0.5 * l) / l);
    }
    return y;",
        reference: |i, e: ElemCtx, p| {
            let d = if e.comp == 0 { i[1].cos() } else { i[1].sin() };
            wrap(i[0] + p[0] * d, if e.comp == 0 { p[1] } else { p[2] })
        },
        ..BASE
    },
];

pub fn register(r: &mut Registry) {
    for row in KINDS {
        r.add(pointwise_kind(row));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// S1 section 2.4's clipping at 3 standard deviations (the digest's 0.995007), and
    /// the limits: no clipping leaves the variance 1, clipping at 0 leaves nothing.
    #[test]
    fn clipped_variance_is_the_documented_bias() {
        assert!((clipped_variance(3.0) - 0.995_007_7).abs() < 1e-6);
        assert!((clipped_variance(40.0) - 1.0).abs() < 1e-15);
        assert_eq!(clipped_variance(0.0), 0.0);
    }
}
