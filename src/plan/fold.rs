//! Folding spectral nodes ([`Lowering::Spectral`]) into the forward transform that
//! produces their input ([`Lowering::Transform`], the capability of `crate::transform`).
//!
//! A spectral node is folded when it reads the only output of a transform that can apply
//! it in its last pass on this device ([`crate::transform::Transform::hosts_spectral`]), nothing
//! else reads that output and it is not needed after the phase. The transform then writes
//! the spectral node's output and its own output is never stored, so rfft -> Green
//! function -> irfft makes no pass over the grid beyond the transforms' own.
//!
//! A spectral node whose output has another component count than its input (a Green
//! function that also differentiates: `poisson`, 1 in, up to 4 out) is not folded: the
//! passes are generated for one count of lines in and out, so it runs alone
//! ([`crate::transform::standalone_dispatch`]), one pass over the grid more. Correct,
//! and the transforms around it keep their own counts.
//!
//! When the spectral node's output in turn has one reader, an inverse transform whose
//! first pass runs along the axis of the forward transform's last
//! ([`crate::transform::Transform::first_pass`], [`crate::transform::Transform::hosts_inverse`]),
//! that pass runs in the forward transform's last too (lines transformed, multiplied,
//! transformed back while in the workgroup), and the inverse transform starts from its
//! second pass ([`Unit::AfterFold`]): one pass over the grid less. What the forward
//! launch stores in the spectral node's output is then that half-way result, which only
//! the inverse reads.

use std::collections::{BTreeMap, HashMap};

use super::fuse::{FuseCtx, Unit};
use crate::gpu::DeviceCaps;
use crate::graph::{NodeId, Source};
use crate::node::Lowering;
use crate::value::ValueType;

/// Replaces each foldable (transform, spectral node) pair of single launches by one
/// [`Unit::Folded`] at the transform's place (the spectral node reads nothing else, so
/// everything after it can follow the transform). Not done without fusion.
pub fn fold(
    ctx: &FuseCtx,
    units: Vec<Unit>,
    caps: &DeviceCaps,
    input_types: &dyn Fn(NodeId) -> Vec<Option<ValueType>>,
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
    let single = |n: NodeId| {
        units
            .iter()
            .any(|u| matches!(u, Unit::Single(m) if *m == n))
    };
    let mut folds: BTreeMap<NodeId, (NodeId, Option<NodeId>)> = BTreeMap::new();
    for &b in ctx.order {
        let inst = &ctx.g.nodes[b];
        if !matches!(inst.node().lowering(), Lowering::Spectral(_)) || !single(b) {
            continue;
        }
        let [src @ Source::Node { node: a, port: 0 }] = inst.inputs[..] else {
            continue;
        };
        // Same count in and out (see the module doc): the output type is the input's.
        let same_shape = ctx.types[b]
            .outputs()
            .is_some_and(|o| o.first().copied() == input_types(b).first().copied().flatten());
        if !same_shape {
            continue;
        }
        let producer = &ctx.g.nodes[a];
        let Lowering::Transform(k) = producer.node().lowering() else {
            continue;
        };
        if single(a)
            && producer.output_ports.len() == 1
            && readers.get(&src) == Some(&1)
            && !(ctx.escapes)(src)
            && k.hosts_spectral(&input_types(a), caps)
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
                    && match ctx.g.nodes[c].node().lowering() {
                        Lowering::Transform(kc) => kc
                            .first_pass(&input_types(c), caps)
                            .is_some_and(|f| k.hosts_inverse(&input_types(a), caps, &f)),
                        _ => false,
                    }
            });
            folds.insert(a, (b, inverse));
        }
    }
    let folded = |n: NodeId| folds.values().any(|&(b, _)| b == n);
    let after = |n: NodeId| folds.values().any(|&(_, c)| c == Some(n));
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
