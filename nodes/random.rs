//! Counter-based random numbers: Philox4x32-10, the same bits in WGSL
//! (`shaders/common/philox.wgsl`) and here.
//!
//! Every draw is a pure function of (seed, stream, step, element): a node's noise does not
//! depend on dispatch shape, scheduling or fusion, and a rerun with the same seed
//! reproduces a simulation exactly. Key = (seed low 32 bits, stream); counter = (element /
//! 4, step, seed high 32 bits, 0); element e takes word e % 4 of its block.
//!
//! `random_normal` and `random_uniform` are element-wise generators, so the planner fuses
//! them into their consumers (the noise of an integrator costs no pass of its own);
//! `random_bits` writes the raw words.

use super::pointwise::{BASE, ElemCtx, Param, PointwiseKind, pointwise_kind};
use crate::gpu::DeviceCaps;
use crate::gpu::{Binding, CompileCtx, CompileError, Dispatch, KernelSpec, NodeIo, WG_1D};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamSpec, Params, PortError, PortSpec, RefCtx, Registry,
    Signature,
};
use crate::value::{PortType, RefArray, ValueType};

const M0: u32 = 0xD251_1F53;
const M1: u32 = 0xCD9E_8D57;
const W0: u32 = 0x9E37_79B9;
const W1: u32 = 0xBB67_AE85;

/// Philox4x32 with 10 rounds (Random123's philox4x32_10).
pub fn philox4x32_10(counter: [u32; 4], key: [u32; 2]) -> [u32; 4] {
    let mut c = counter;
    let mut k = key;
    for r in 0..10 {
        if r > 0 {
            k = [k[0].wrapping_add(W0), k[1].wrapping_add(W1)];
        }
        let p0 = M0 as u64 * c[0] as u64;
        let p1 = M1 as u64 * c[2] as u64;
        c = [
            (p1 >> 32) as u32 ^ c[1] ^ k[0],
            p1 as u32,
            (p0 >> 32) as u32 ^ c[3] ^ k[1],
            p0 as u32,
        ];
    }
    c
}

/// Largest seed: seeds travel through f64 graph params, exact up to 2^53.
pub const MAX_SEED: f64 = 9_007_199_254_740_991.0;

/// The block of four words holding element `idx`'s draw.
pub fn block(idx: u64, step: u64, seed: u64, stream: u32) -> [u32; 4] {
    philox4x32_10(
        [(idx >> 2) as u32, step as u32, (seed >> 32) as u32, 0],
        [seed as u32, stream],
    )
}

/// The raw word of element `idx`.
pub fn bits(idx: u64, step: u64, seed: u64, stream: u32) -> u32 {
    block(idx, step, seed, stream)[(idx & 3) as usize]
}

/// Uniform in [0, 1) with 24 bits, as the GPU computes it (exact in f32).
pub fn uniform(idx: u64, step: u64, seed: u64, stream: u32) -> f64 {
    (bits(idx, step, seed, stream) >> 8) as f64 / 16_777_216.0
}

/// Standard normal by Box-Muller on lane pairs (0,1) and (2,3), in f64.
pub fn normal(idx: u64, step: u64, seed: u64, stream: u32) -> f64 {
    let w = block(idx, step, seed, stream);
    let lane = (idx & 3) as usize;
    let (a, b) = if lane >= 2 {
        (w[2], w[3])
    } else {
        (w[0], w[1])
    };
    let open01 = |x: u32| ((x >> 8) as f64 + 1.0) / 16_777_216.0;
    let r = (-2.0 * open01(a).ln()).sqrt();
    let theta = 2.0 * std::f64::consts::PI * open01(b);
    if lane & 1 == 1 {
        r * theta.sin()
    } else {
        r * theta.cos()
    }
}

pub(crate) fn seed_param() -> ParamSpec {
    ParamSpec::integer(
        "seed",
        Some(0.0),
        0.0,
        MAX_SEED,
        "random seed; graphs usually pass \"$seed\" (set by --seed)",
    )
}

pub(crate) fn stream_param() -> ParamSpec {
    ParamSpec::integer(
        "stream",
        Some(0.0),
        0.0,
        u32::MAX as f64,
        "stream id: independent streams for the same seed (one per noise source)",
    )
}

fn shape_params() -> [ParamSpec; 2] {
    [
        ParamSpec::integer(
            "rows",
            Some(0.0),
            0.0,
            u32::MAX as f64,
            "particle count when `like` is not connected",
        ),
        ParamSpec::integer(
            "cols",
            Some(1.0),
            1.0,
            1024.0,
            "values per particle when `like` is not connected",
        ),
    ]
}

/// Seed and stream as exact bits: (seed low, seed high, stream).
fn key_bits(p: &Params) -> [Param; 3] {
    let seed = p.number("seed") as u64;
    [
        Param::Bits(seed as u32),
        Param::Bits((seed >> 32) as u32),
        Param::Bits(p.number("stream") as u32),
    ]
}

fn generated_shape(p: &Params) -> Option<ValueType> {
    let rows = p.number("rows") as u32;
    (rows > 0).then(|| ValueType::Particles {
        n: rows,
        k: p.number("cols") as u32,
    })
}

/// Seed (from its two halves) and stream back from the reference's f64 params.
fn key_of(p: &[f64]) -> (u64, u32) {
    ((p[1] as u64) << 32 | p[0] as u64, p[2] as u32)
}

const LIKE: &[(&str, &str, bool)] = &[(
    "like",
    "shape template (its values are not read); or give rows and cols",
    true,
)];

/// The element-wise generators.
pub static GENERATORS: &[PointwiseKind] = &[
    PointwiseKind {
        name: "random_normal",
        doc: "normal random numbers (mean, std), a pure function of (seed, stream, step, element)",
        inputs: LIKE,
        params: || {
            let [rows, cols] = shape_params();
            vec![
                seed_param(),
                stream_param(),
                ParamSpec::f32_factor("mean", Some(0.0), "mean"),
                ParamSpec::f32_nonnegative("std", Some(1.0), "standard deviation"),
                rows,
                cols,
            ]
        },
        flatten: |p| {
            let [lo, hi, stream] = key_bits(p);
            vec![
                lo,
                hi,
                stream,
                Param::Number(p.number("mean")),
                Param::Number(p.number("std")),
            ]
        },
        shape: generated_shape,
        body: "return fma(p4, philox_normal(idx, step, bitcast<u32>(p0), bitcast<u32>(p1), bitcast<u32>(p2)), p3);",
        imports: &["common/philox.wgsl"],
        uses_step: true,
        reference: |_, e: ElemCtx, p| {
            let (seed, stream) = key_of(p);
            p[3] + p[4] * normal(e.idx, e.step, seed, stream)
        },
        ..BASE
    },
    PointwiseKind {
        name: "random_uniform",
        doc: "uniform random numbers in [low, high), a pure function of (seed, stream, step, element)",
        inputs: LIKE,
        params: || {
            let [rows, cols] = shape_params();
            vec![
                seed_param(),
                stream_param(),
                ParamSpec::f32_factor("low", Some(0.0), "lower bound"),
                ParamSpec::f32_factor("high", Some(1.0), "upper bound"),
                rows,
                cols,
            ]
        },
        flatten: |p| {
            let [lo, hi, stream] = key_bits(p);
            vec![
                lo,
                hi,
                stream,
                Param::Number(p.number("low")),
                Param::Number(p.number("high")),
            ]
        },
        shape: generated_shape,
        body: "return fma(p4 - p3, philox_uniform(idx, step, bitcast<u32>(p0), bitcast<u32>(p1), bitcast<u32>(p2)), p3);",
        imports: &["common/philox.wgsl"],
        uses_step: true,
        reference: |_, e: ElemCtx, p| {
            let (seed, stream) = key_of(p);
            p[3] + (p[4] - p[3]) * uniform(e.idx, e.step, seed, stream)
        },
        ..BASE
    },
];

/// `random_bits`: raw Philox words as u32 indices.
fn random_bits_kind() -> NodeKind {
    NodeKind::declare(
        "random_bits",
        "raw Philox4x32-10 words (u32), a pure function of (seed, stream, step, element)",
    )
    .output(PortSpec::new("out", PortType::Indices, "random words"))
    .param(seed_param())
    .param(stream_param())
    .param(ParamSpec::integer(
        "count",
        None,
        0.0,
        u32::MAX as f64,
        "number of words",
    ))
    .build(|p| {
        Ok(Box::new(RandomBits {
            seed: p.number("seed") as u64,
            stream: p.number("stream") as u32,
            count: p.number("count") as u32,
        }))
    })
}

struct RandomBits {
    seed: u64,
    stream: u32,
    count: u32,
}

impl Node for RandomBits {
    fn infer(&self, _: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        Ok(Signature::outputs(vec![ValueType::Indices {
            n: self.count,
        }]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, _: &[Option<RefArray>], outputs: &mut [RefArray], cx: RefCtx) {
        for (i, v) in outputs[0].data.iter_mut().enumerate() {
            *v = bits(i as u64, cx.step, self.seed, self.stream) as f64;
        }
    }
}

impl GpuKernels for RandomBits {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let kernel = cx.kernel(&KernelSpec::new(
            "random_bits",
            cx.shader("random/bits.wgsl")?,
            &[
                Binding::StorageReadWrite,
                Binding::StorageRead,
                Binding::Uniform,
            ],
        ))?;
        let params = [
            self.count,
            self.seed as u32,
            (self.seed >> 32) as u32,
            self.stream,
        ];
        let uniform = cx.uniform("random_bits params", bytemuck::cast_slice(&params));
        let groups = cx.grid_1d(self.count as u64, WG_1D);
        Ok(vec![cx.dispatch(
            &kernel,
            &[io.outputs[0].buffer, cx.clock, &uniform],
            groups,
        )])
    }
}

pub fn register(r: &mut Registry) {
    for row in GENERATORS {
        r.add(pointwise_kind(row));
    }
    r.add(random_bits_kind());
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Random123's known-answer vectors for philox4x32_10 (kat_vectors).
    #[test]
    fn known_answers() {
        assert_eq!(
            philox4x32_10([0; 4], [0; 2]),
            [0x6627e8d5, 0xe169c58d, 0xbc57ac4c, 0x9b00dbd8]
        );
        assert_eq!(
            philox4x32_10([u32::MAX; 4], [u32::MAX; 2]),
            [0x408f276d, 0x41c83b0e, 0xa20bc7c6, 0x6d5451fd]
        );
        assert_eq!(
            philox4x32_10(
                [0x243f6a88, 0x85a308d3, 0x13198a2e, 0x03707344],
                [0xa4093822, 0x299f31d0]
            ),
            [0xd16cfe09, 0x94fdcceb, 0x5001e420, 0x24126ea1]
        );
    }
}
