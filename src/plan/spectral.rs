//! Spectral nodes in plans ([`Lowering::Spectral`]): folding one into the forward
//! transform that produces its input, and the kernel of one that runs alone.
//!
//! A spectral node is folded when it reads the only output of a node that can apply it
//! in its last pass on this device ([`crate::node::GpuKernels::folds_spectral`]), nothing
//! else reads that output and it is not needed after the phase. The transform then writes
//! the spectral node's output and its own output is never stored, so rfft -> Green
//! function -> irfft makes no pass over the grid beyond the transforms' own.
//!
//! When the spectral node's output in turn has one reader, an inverse transform whose
//! first pass runs along the axis of the forward transform's last
//! ([`crate::node::GpuKernels::first_pass`], [`crate::node::GpuKernels::folds_inverse`]),
//! that pass runs in the forward transform's last too (lines transformed, multiplied,
//! transformed back while in the workgroup), and the inverse transform starts from its
//! second pass ([`Unit::AfterFold`]): one pass over the grid less. What the forward
//! launch stores in the spectral node's output is then that half-way result, which only
//! the inverse reads.

use std::collections::{BTreeMap, HashMap};
use std::fmt::Write;

use super::fuse::{FuseCtx, Unit};
use crate::gpu::{DeviceCaps, WG_1D};
use crate::graph::Source;
use crate::node::{Lowering, SpectralBody};
use crate::value::{ValueType, half_dims};

/// Replaces each foldable (transform, spectral node) pair of single launches by one
/// [`Unit::Folded`] at the transform's place (the spectral node reads nothing else, so
/// everything after it can follow the transform). Not done without fusion.
pub fn fold(
    ctx: &FuseCtx,
    units: Vec<Unit>,
    caps: &DeviceCaps,
    input_types: &dyn Fn(usize) -> Vec<Option<ValueType>>,
) -> Vec<Unit> {
    if !ctx.fuse {
        return units;
    }
    let mut readers: HashMap<Source, usize> = HashMap::new();
    for &n in ctx.order {
        for s in &ctx.g.nodes[n].inputs {
            *readers.entry(*s).or_default() += 1;
        }
    }
    let single = |n: usize| {
        units
            .iter()
            .any(|u| matches!(u, Unit::Single(m) if *m == n))
    };
    let mut folds: BTreeMap<usize, (usize, Option<usize>)> = BTreeMap::new();
    for &b in ctx.order {
        let inst = &ctx.g.nodes[b];
        if !matches!(inst.node.lowering(), Lowering::Spectral(_)) || !single(b) {
            continue;
        }
        let [src @ Source::Node { node: a, port: 0 }] = inst.inputs[..] else {
            continue;
        };
        let producer = &ctx.g.nodes[a];
        let Lowering::Kernels(k) = producer.node.lowering() else {
            continue;
        };
        if single(a)
            && producer.output_ports.len() == 1
            && readers.get(&src) == Some(&1)
            && !(ctx.escapes)(src)
            && k.folds_spectral(&input_types(a), caps)
        {
            // The inverse transform that alone reads the spectral node's output may
            // leave its first pass to this launch.
            let out = Source::Node { node: b, port: 0 };
            let reader = ctx
                .order
                .iter()
                .copied()
                .find(|&c| ctx.g.nodes[c].inputs.contains(&out));
            let inverse = reader.filter(|&c| {
                readers.get(&out) == Some(&1)
                    && !(ctx.escapes)(out)
                    && single(c)
                    && ctx.g.nodes[c].inputs.len() == 1
                    && match ctx.g.nodes[c].node.lowering() {
                        Lowering::Kernels(kc) => kc
                            .first_pass(&input_types(c), caps)
                            .is_some_and(|f| k.folds_inverse(&input_types(a), caps, &f)),
                        _ => false,
                    }
            });
            folds.insert(a, (b, inverse));
        }
    }
    let folded = |n: usize| folds.values().any(|&(b, _)| b == n);
    let after = |n: usize| folds.values().any(|&(_, c)| c == Some(n));
    units
        .into_iter()
        .filter_map(|u| match u {
            Unit::Single(n) if folded(n) => None,
            Unit::Single(n) if after(n) => Some(Unit::AfterFold(n)),
            Unit::Single(n) => Some(match folds.get(&n) {
                Some(&(b, inverse)) => Unit::Folded {
                    transform: n,
                    spectral: b,
                    inverse,
                },
                None => Unit::Single(n),
            }),
            other => Some(other),
        })
        .collect()
}

/// The kernel of a spectral node that runs alone on a spectrum of type `ty`: one thread
/// per wave vector, all components. Bindings: params, input (when `reads_input`; else the
/// body sees zeros, as a generator), output, then the engine clock when the body reads
/// the step.
pub fn standalone_source(body: &SpectralBody, ty: &ValueType, reads_input: bool) -> String {
    let (dims, comps, half) = match *ty {
        ValueType::HalfComplexGrid { dims, comps } => (dims, comps, true),
        ValueType::ComplexGrid { dims, comps } => (dims, comps, false),
        other => unreachable!("spectral nodes infer spectra, got {other}"),
    };
    let s = if half { half_dims(dims) } else { dims };
    let cells = s[0] as u64 * s[1] as u64 * s[2] as u64;
    let [nx, ny, nz] = dims;
    let mut w = String::from(
        "// A spectral node's function over a spectrum (generated by mesoflow).\n#import common/index.wgsl\n#import common/wave.wgsl\n\n@group(0) @binding(0) var<storage, read> spectral_params: array<f32>;\n",
    );
    let mut binding = 1;
    if reads_input {
        writeln!(
            w,
            "@group(0) @binding({binding}) var<storage, read> src: array<vec2<f32>>;"
        )
        .expect("String");
        binding += 1;
    }
    writeln!(
        w,
        "@group(0) @binding({binding}) var<storage, read_write> dst: array<vec2<f32>>;"
    )
    .expect("String");
    if body.uses_step {
        writeln!(
            w,
            "@group(0) @binding({}) var<storage, read> clock: array<u32>;",
            binding + 1
        )
        .expect("String");
    }
    w.push_str(&body.function(comps));
    let kx = if half {
        "i32(ix)".to_string()
    } else {
        format!("wave_number(ix, {nx}u)")
    };
    writeln!(
        w,
        "\n@compute @workgroup_size({WG_1D})\nfn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,\n        @builtin(local_invocation_index) lid: u32) {{\n    let i = flat_index(wid, nwg, lid, {WG_1D}u);\n    if (i >= {cells}u) {{ return; }}\n    let ix = i % {sx}u; let iy = (i / {sx}u) % {sy}u; let iz = i / {sxy}u;\n    var v: array<vec2<f32>, SPECTRAL_COMPS>;",
        sx = s[0],
        sy = s[1],
        sxy = s[0] * s[1]
    )
    .expect("String");
    if reads_input {
        for c in 0..comps as u64 {
            writeln!(w, "    v[{c}] = src[{}u + i];", c * cells).expect("String");
        }
    }
    writeln!(
        w,
        "    let u = spectral(vec3<i32>({kx}, wave_number(iy, {ny}u), wave_number(iz, {nz}u)), vec3<u32>({nx}u, {ny}u, {nz}u), v);"
    )
    .expect("String");
    for c in 0..comps as u64 {
        writeln!(w, "    dst[{}u + i] = u[{c}];", c * cells).expect("String");
    }
    w.push_str("}\n");
    // The body's imports name embedded files (its node's tests compile it).
    crate::gpu::shaders::resolve(&w)
        .expect("common/index.wgsl, common/wave.wgsl and the body's imports are embedded")
}
