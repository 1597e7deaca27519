//! References and comparisons: a kind's f64 CPU reference, error measures, a node run
//! against its reference, WGSL validated by naga.

use std::collections::BTreeMap;

use mesoflow::gpu::DeviceCaps;
use mesoflow::node::{RefCtx, check_params};
use mesoflow::value::{HostArray, RefArray, ValueType};

use super::{registry, run_out};

/// Evaluates a kind's f64 CPU reference on the given inputs (one evaluation, no state).
pub fn reference(kind: &str, params: &str, inputs: &[Option<&HostArray>]) -> Vec<RefArray> {
    let k = registry().get(kind).unwrap();
    let raw: BTreeMap<String, serde_json::Value> = serde_json::from_str(params).unwrap();
    let raw = raw
        .into_iter()
        .map(|(n, v)| (n, mesoflow::expr::ParamValue::from_json(&v).unwrap()))
        .collect();
    let p = check_params(k.params(), &raw).unwrap();
    let node = k.build(&p).unwrap();
    let types: Vec<Option<ValueType>> = inputs.iter().map(|a| a.map(|a| a.ty)).collect();
    // Output types only: the baseline adapter serves (the decisions do not change them).
    let sig = node.infer(&types, &DeviceCaps::baseline()).unwrap();
    let refs: Vec<Option<RefArray>> = inputs.iter().map(|a| a.map(|a| a.to_ref())).collect();
    let mut outs: Vec<RefArray> = sig
        .outputs
        .iter()
        .map(|t| RefArray::new(*t, vec![0.0; t.words() as usize]))
        .collect();
    node.cpu_reference(&refs, &mut outs, RefCtx::default());
    outs
}

/// Largest |gpu - ref| over max(|ref|), with the index where it occurs.
pub fn rel_max_err(gpu: &HostArray, reference: &RefArray) -> (f64, usize) {
    assert_eq!(gpu.ty, reference.ty, "types differ");
    let g = gpu.data.to_f64();
    let scale = reference
        .data
        .iter()
        .fold(0.0f64, |m, x| m.max(x.abs()))
        .max(f64::MIN_POSITIVE);
    let mut worst = (0.0, 0);
    for (i, (a, b)) in g.iter().zip(&reference.data).enumerate() {
        // Equal values (infinities included) are no error.
        let e = if a == b { 0.0 } else { (a - b).abs() / scale };
        if e > worst.0 || e.is_nan() {
            worst = (e, i);
        }
    }
    worst
}

/// Relative L2 error of `got` against `want`: |got - want| / |want|.
pub fn rel_l2(got: &[f64], want: &[f64]) -> f64 {
    assert_eq!(got.len(), want.len());
    let num: f64 = got.iter().zip(want).map(|(a, b)| (a - b) * (a - b)).sum();
    let den: f64 = want.iter().map(|b| b * b).sum();
    (num / den.max(f64::MIN_POSITIVE)).sqrt()
}

/// Runs node `kind` with `params` on `inputs` and asserts its output `out` within `tol`
/// of its f64 reference, relative to the largest reference value (`what` names the case).
pub fn assert_like_reference(
    kind: &str,
    params: &str,
    inputs: &[(&str, HostArray)],
    tol: f64,
    what: &str,
) {
    let (g, r) = run_out(kind, params, inputs);
    let (err, at) = rel_max_err(&g, &r);
    assert!(
        err <= tol,
        "{what}: error {err:e} at {at} (tolerance {tol:e})"
    );
}

/// Parses and validates WGSL with naga for a device with these capabilities (subgroup
/// operations in compute shaders where they include subgroups); panics with the located
/// error, led by `name`.
pub fn validate_wgsl(name: &str, src: &str, capabilities: naga::valid::Capabilities) {
    let module = naga::front::wgsl::parse_str(src)
        .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(src)));
    let mut v = naga::valid::Validator::new(naga::valid::ValidationFlags::all(), capabilities);
    if capabilities.contains(naga::valid::Capabilities::SUBGROUP) {
        v.subgroup_stages(naga::valid::ShaderStages::COMPUTE);
        v.subgroup_operations(naga::valid::SubgroupOperationSet::all());
    }
    v.validate(&module)
        .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(src)));
}

/// erfc with relative error below 1.2e-7 (Numerical Recipes, Chebyshev fit): enough for a
/// KS distance resolved at 1e-3 and the closed-form integrals of truncated Gaussians.
pub fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let r = t
        * (-z * z - 1.26551223
            + t * (1.00002368
                + t * (0.37409196
                    + t * (0.09678418
                        + t * (-0.18628806
                            + t * (0.27886807
                                + t * (-1.13520398
                                    + t * (1.48851587 + t * (-0.82215223 + t * 0.17087277)))))))))
            .exp();
    if x >= 0.0 { r } else { 2.0 - r }
}
