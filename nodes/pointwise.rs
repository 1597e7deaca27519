//! Element-wise arithmetic. The planner compiles these itself (fused with their
//! neighbours, or alone); each kind is a WGSL body plus its f64 CPU reference, written
//! side by side in one table row.

use crate::gpu::DeviceCaps;
use crate::node::{
    F32_PARAM_MAX, Lowering, Node, NodeKind, ParamKind, ParamSpec, Params, PointwiseBody,
    PortError, PortSpec, RefCtx, Registry, Signature,
};
use crate::value::{PortType, RefArray, ValueType};

/// A param value handed to a body: a number (f32 on the GPU), or 32 raw bits that the
/// body reads back with `bitcast<u32>(pK)` (seeds and stream ids must stay exact).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Param {
    Number(f64),
    Bits(u32),
}

impl Param {
    fn gpu(self) -> f32 {
        match self {
            Param::Number(x) => x as f32,
            Param::Bits(b) => f32::from_bits(b),
        }
    }

    fn host(self) -> f64 {
        match self {
            Param::Number(x) => x,
            Param::Bits(b) => b as f64,
        }
    }
}

/// Where an element sits, as the CPU reference of a body sees it.
#[derive(Clone, Copy, Debug)]
pub struct ElemCtx {
    /// Flat element (4-byte word) index.
    pub idx: u64,
    /// Component (see `ValueType::component_of`).
    pub comp: u32,
    /// The time step.
    pub step: u64,
}

/// One element-wise kind: a table row.
pub struct PointwiseKind {
    pub(crate) name: &'static str,
    pub(crate) doc: &'static str,
    /// (name, doc, optional). An absent optional input reads as 0.
    pub(crate) inputs: &'static [(&'static str, &'static str, bool)],
    pub(crate) params: fn() -> Vec<ParamSpec>,
    /// Param values handed to the body as p0, p1, ...
    pub(crate) flatten: fn(&Params) -> Vec<Param>,
    /// Extra shape check against the param values (per-component kinds).
    pub(crate) check: fn(&ValueType, &[f64]) -> Result<(), String>,
    /// Output type when no array input gives one (generators); `None`: a scalar.
    pub(crate) shape: fn(&Params) -> Option<ValueType>,
    /// WGSL function body; sees the inputs by port name, `idx`, `comp`, `step`, `p0`...
    pub(crate) body: &'static str,
    /// Shader files the body calls into.
    pub(crate) imports: &'static [&'static str],
    /// The body reads `step` (the engine clock is bound).
    pub(crate) uses_step: bool,
    /// The params are one value per component, padded to MAX_COMPONENTS for the body.
    pub(crate) per_component: bool,
    /// The input whose value the output is when the others are absent (`add` without
    /// its optional term): see `Node::forwards`.
    pub(crate) forwards_alone: Option<usize>,
    /// Exactly one input is present and the output is it (`either`: a graph's choice
    /// between two paths, the other left out by `enabled`).
    pub(crate) one_of: bool,
    /// Real-linear in its array inputs (sums, real factors): spectra are accepted too,
    /// since such an operation acts on real and imaginary parts alike.
    pub(crate) linear: bool,
    /// f64 reference of one element: (inputs, where, params).
    pub(crate) reference: fn(&[f64], ElemCtx, &[f64]) -> f64,
}

/// Defaults for table rows (`..BASE`).
pub(crate) const BASE: PointwiseKind = PointwiseKind {
    name: "",
    doc: "",
    inputs: &[],
    params: no_params,
    flatten: nothing,
    check: any_shape,
    shape: no_shape,
    body: "",
    imports: &[],
    uses_step: false,
    per_component: false,
    forwards_alone: None,
    one_of: false,
    linear: false,
    reference: |_, _, _| 0.0,
};

fn no_params() -> Vec<ParamSpec> {
    Vec::new()
}

fn nothing(_: &Params) -> Vec<Param> {
    Vec::new()
}

fn any_shape(_: &ValueType, _: &[f64]) -> Result<(), String> {
    Ok(())
}

fn no_shape(_: &Params) -> Option<ValueType> {
    None
}

fn components_match(t: &ValueType, p: &[f64]) -> Result<(), String> {
    let comps = match t {
        ValueType::Particles { k, .. } => *k,
        ValueType::RealGrid { comps, .. } => *comps,
        _ => 1,
    };
    if comps as usize == p.len() {
        Ok(())
    } else {
        Err(format!(
            "{} per-component values given for a value with {comps} components ({t})",
            p.len()
        ))
    }
}

fn per_component_param(name: &'static str, doc: &'static str) -> ParamSpec {
    ParamSpec {
        name,
        kind: ParamKind::Numbers {
            len: None,
            min: -F32_PARAM_MAX,
            max: F32_PARAM_MAX,
        },
        default: None,
        doc,
    }
}

fn numbers(p: &Params, names: &[&str]) -> Vec<Param> {
    names.iter().map(|n| Param::Number(p.number(n))).collect()
}

/// Per-component kinds read p[comp] from an array of this many params.
const MAX_COMPONENTS: usize = 4;

/// The element-wise kinds mesoflow ships.
pub static KINDS: &[PointwiseKind] = &[
    PointwiseKind {
        name: "constant",
        doc: "a constant value: a scalar, or a particle array when rows > 0 (or shaped like `like`)",
        inputs: &[("like", "shape template (its values are not read)", true)],
        params: || {
            vec![
                ParamSpec::f32_factor("value", None, "the value"),
                ParamSpec::integer(
                    "rows",
                    Some(0.0),
                    0.0,
                    u32::MAX as f64,
                    "particle count (0: a scalar) when `like` is not connected",
                ),
                ParamSpec::integer(
                    "cols",
                    Some(1.0),
                    1.0,
                    1024.0,
                    "values per particle when `like` is not connected",
                ),
            ]
        },
        flatten: |p| numbers(p, &["value"]),
        shape: |p| {
            let rows = p.number("rows") as u32;
            (rows > 0).then(|| ValueType::Particles {
                n: rows,
                k: p.number("cols") as u32,
            })
        },
        body: "return p0;",
        reference: |_, _, p| p[0],
        ..BASE
    },
    PointwiseKind {
        name: "scale",
        doc: "out = factor * x, element-wise",
        inputs: &[("x", "values to scale", false)],
        params: || vec![ParamSpec::f32_factor("factor", None, "the factor")],
        flatten: |p| numbers(p, &["factor"]),
        body: "return p0 * x;",
        reference: |i, _, p| p[0] * i[0],
        linear: true,
        ..BASE
    },
    PointwiseKind {
        name: "add",
        doc: "out = a + b, element-wise (a scalar operand is broadcast; absent b reads as 0)",
        inputs: &[("a", "first term", false), ("b", "second term", true)],
        body: "return a + b;",
        reference: |i, _, _| i[0] + i[1],
        linear: true,
        forwards_alone: Some(0),
        ..BASE
    },
    PointwiseKind {
        name: "either",
        doc: "out = whichever of a and b is present (exactly one: a graph choosing between two paths, the other left out by `enabled`); never runs a kernel",
        inputs: &[("a", "one choice", true), ("b", "the other choice", true)],
        body: "return a + b;",
        reference: |i, _, _| i[0] + i[1],
        linear: true,
        one_of: true,
        ..BASE
    },
    PointwiseKind {
        name: "sub",
        doc: "out = a - b, element-wise (a scalar operand is broadcast)",
        inputs: &[("a", "minuend", false), ("b", "subtrahend", false)],
        body: "return a - b;",
        reference: |i, _, _| i[0] - i[1],
        linear: true,
        ..BASE
    },
    PointwiseKind {
        name: "multiply",
        doc: "out = a * b, element-wise (a scalar operand is broadcast, and a one-column particle array over the columns of the other: charges times fields)",
        inputs: &[("a", "first factor", false), ("b", "second factor", false)],
        body: "return a * b;",
        reference: |i, _, _| i[0] * i[1],
        ..BASE
    },
    PointwiseKind {
        name: "divide",
        doc: "out = a / b, element-wise (a scalar operand is broadcast)",
        inputs: &[("a", "numerator", false), ("b", "denominator", false)],
        body: "return a / b;",
        reference: |i, _, _| i[0] / i[1],
        ..BASE
    },
    PointwiseKind {
        name: "axpy",
        doc: "out = alpha * x + y, element-wise",
        inputs: &[("x", "scaled term", false), ("y", "added term", false)],
        params: || vec![ParamSpec::f32_factor("alpha", None, "factor on x")],
        flatten: |p| numbers(p, &["alpha"]),
        body: "return fma(p0, x, y);",
        reference: |i, _, p| p[0] * i[0] + i[1],
        linear: true,
        ..BASE
    },
    PointwiseKind {
        name: "axpby",
        doc: "out = alpha * x + beta * y, element-wise",
        inputs: &[("x", "first term", false), ("y", "second term", false)],
        params: || {
            vec![
                ParamSpec::f32_factor("alpha", None, "factor on x"),
                ParamSpec::f32_factor("beta", None, "factor on y"),
            ]
        },
        flatten: |p| numbers(p, &["alpha", "beta"]),
        body: "return fma(p0, x, p1 * y);",
        reference: |i, _, p| p[0] * i[0] + p[1] * i[1],
        linear: true,
        ..BASE
    },
    PointwiseKind {
        name: "affine",
        doc: "out = scale * x + offset, element-wise",
        inputs: &[("x", "values", false)],
        params: || {
            vec![
                ParamSpec::f32_factor("scale", Some(1.0), "factor on x"),
                ParamSpec::f32_factor("offset", Some(0.0), "added constant"),
            ]
        },
        flatten: |p| numbers(p, &["scale", "offset"]),
        body: "return fma(p0, x, p1);",
        reference: |i, _, p| p[0] * i[0] + p[1],
        ..BASE
    },
    PointwiseKind {
        name: "scale_components",
        doc: "out = x * factors[component], one factor per column of a particle array (or grid component)",
        inputs: &[("x", "values", false)],
        params: || {
            vec![per_component_param(
                "factors",
                "one factor per component, at most 4",
            )]
        },
        flatten: |p| {
            p.numbers("factors")
                .iter()
                .map(|&x| Param::Number(x))
                .collect()
        },
        check: components_match,
        body: "var t = array<f32, 4>(p0, p1, p2, p3); return x * t[min(comp, 3u)];",
        per_component: true,
        reference: |i, e, p| i[0] * p[e.comp as usize],
        ..BASE
    },
    PointwiseKind {
        name: "offset_components",
        doc: "out = x + offsets[component], one offset per column of a particle array (or grid component)",
        inputs: &[("x", "values", false)],
        params: || {
            vec![per_component_param(
                "offsets",
                "one offset per component, at most 4",
            )]
        },
        flatten: |p| {
            p.numbers("offsets")
                .iter()
                .map(|&x| Param::Number(x))
                .collect()
        },
        check: components_match,
        body: "var t = array<f32, 4>(p0, p1, p2, p3); return x + t[min(comp, 3u)];",
        per_component: true,
        reference: |i, e, p| i[0] + p[e.comp as usize],
        ..BASE
    },
    PointwiseKind {
        name: "wall_force",
        doc: "the WCA repulsion of flat walls on particles (N x 3 positions -> N x 3 forces): F_z = 24 eps (2 (sigma/h)^12 - (sigma/h)^6) / h for h < 2^(1/6) sigma, h the distance to the plane z = bottom (pushing up) and to z = top (pushing down); the x and y columns 0. h is taken at least sigma / 2, so a particle that crossed a wall is pushed back with a bounded force",
        inputs: &[("x", "positions (N x 3)", false)],
        params: || {
            vec![
                ParamSpec::f32_factor("bottom", Some(-1e18), "z of the bottom wall (-1e18: none)"),
                ParamSpec::f32_factor("top", Some(1e18), "z of the top wall (1e18: none)"),
                ParamSpec::f32_nonnegative("epsilon", Some(1.0), "energy scale eps"),
                ParamSpec::f32_positive(
                    "sigma",
                    Some(1.0),
                    "length scale sigma (the force vanishes from 2^(1/6) sigma)",
                ),
            ]
        },
        flatten: |p| numbers(p, &["bottom", "top", "epsilon", "sigma"]),
        check: three_columns,
        body: "if (comp != 2u) { return 0.0; }
    let cut = 1.122462048309373 * p3;
    var f = 0.0;
    let hb = x - p0;
    if (hb < cut) {
        let h = max(hb, 0.5 * p3);
        let s2 = (p3 / h) * (p3 / h);
        let s6 = s2 * s2 * s2;
        f = f + 24.0 * p2 * (2.0 * s6 * s6 - s6) / h;
    }
    let ht = p1 - x;
    if (ht < cut) {
        let h = max(ht, 0.5 * p3);
        let s2 = (p3 / h) * (p3 / h);
        let s6 = s2 * s2 * s2;
        f = f - 24.0 * p2 * (2.0 * s6 * s6 - s6) / h;
    }
    return f;",
        per_component: false,
        reference: |i, e, p| {
            if e.comp != 2 {
                return 0.0;
            }
            let (eps, sigma) = (p[2], p[3]);
            let wca = |d: f64| {
                if d >= 2f64.powf(1.0 / 6.0) * sigma {
                    return 0.0;
                }
                let h = d.max(0.5 * sigma);
                let s6 = (sigma / h).powi(6);
                24.0 * eps * (2.0 * s6 * s6 - s6) / h
            };
            wca(i[0] - p[0]) - wca(p[1] - i[0])
        },
        ..BASE
    },
    PointwiseKind {
        name: "unwrap",
        doc: "out = unwrapped + the minimum image of (after - before), per component: an unwrapped trajectory advanced by one step of the wrapped one (positions wrapped into a periodic box before and after the step); exact while a step moves a particle less than half the box along each axis. Per component a box length, 0 for an open axis (the plain difference)",
        inputs: &[
            (
                "unwrapped",
                "the unwrapped positions before the step",
                false,
            ),
            ("before", "the wrapped positions before the step", false),
            ("after", "the wrapped positions after the step", false),
        ],
        params: || {
            vec![ParamSpec {
                name: "box",
                kind: ParamKind::Numbers {
                    len: None,
                    min: 0.0,
                    max: F32_PARAM_MAX,
                },
                default: None,
                doc: "the box length along each component (column), at most 4; 0: an open axis",
            }]
        },
        flatten: |p| p.numbers("box").iter().map(|&x| Param::Number(x)).collect(),
        check: components_match,
        body: "var t = array<f32, 4>(p0, p1, p2, p3);
    let l = t[min(comp, 3u)];
    let d = after - before;
    if (l > 0.0) {
        return unwrapped + (d - l * floor(d / l + 0.5));
    }
    return unwrapped + d;",
        per_component: true,
        reference: |i, e, p| i[0] + minimum_image_step(i[2] - i[1], p[e.comp as usize]),
        ..BASE
    },
];

/// The minimum image of a difference `d` along an axis of length `l` (0: open), as
/// `unwrap`'s body takes it: d - l floor(d / l + 1/2).
fn minimum_image_step(d: f64, l: f64) -> f64 {
    if l > 0.0 {
        d - l * (d / l + 0.5).floor()
    } else {
        d
    }
}

/// Positions of 3-D particles (the walls are planes of constant z).
fn three_columns(t: &ValueType, _: &[f64]) -> Result<(), String> {
    match t {
        ValueType::Particles { k: 3, .. } => Ok(()),
        other => Err(format!("expected positions (N x 3), got {other}")),
    }
}

/// The node kind of a table row.
pub(crate) fn pointwise_kind(row: &'static PointwiseKind) -> NodeKind {
    let ty = if row.linear {
        PortType::Linear
    } else {
        PortType::RealArray
    };
    let inputs = row.inputs.iter().map(move |&(n, d, opt)| {
        let p = PortSpec::new(n, ty, d);
        if opt { p.optional() } else { p }
    });
    NodeKind::declare(row.name, row.doc)
        .inputs(inputs)
        .output(PortSpec::new(
            "out",
            ty,
            "result, shaped like the non-scalar inputs",
        ))
        .params((row.params)())
        .build(move |params| {
            let values = (row.flatten)(params);
            if row.per_component && values.len() > MAX_COMPONENTS {
                return Err(format!(
                    "at most {MAX_COMPONENTS} per-component values are supported, got {}",
                    values.len()
                ));
            }
            let mut gpu_params: Vec<f32> = values.iter().map(|v| v.gpu()).collect();
            if row.per_component {
                gpu_params.resize(MAX_COMPONENTS, 0.0);
            }
            Ok(Box::new(PointwiseNode {
                kind: row,
                values: values.iter().map(|v| v.host()).collect(),
                gpu_params,
                generated: (row.shape)(params),
            }))
        })
}

/// Whether two particle arrays of the same rows differ only in that one has a single
/// column (broadcast over the other's columns).
pub fn row_broadcast(a: &ValueType, b: &ValueType) -> bool {
    match (a, b) {
        (ValueType::Particles { n, k }, ValueType::Particles { n: m, k: l }) => {
            n == m && k != l && (*k == 1 || *l == 1)
        }
        _ => false,
    }
}

fn column_count(t: &ValueType) -> u32 {
    match t {
        ValueType::Particles { k, .. } => *k,
        _ => 1,
    }
}

struct PointwiseNode {
    kind: &'static PointwiseKind,
    values: Vec<f64>,
    gpu_params: Vec<f32>,
    generated: Option<ValueType>,
}

impl Node for PointwiseNode {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        if self.kind.one_of && inputs.iter().filter(|t| t.is_some()).count() != 1 {
            let names: Vec<&str> = self.kind.inputs.iter().map(|p| p.0).collect();
            return Err(PortError::new(
                self.kind.inputs[0].0,
                format!(
                    "exactly one of {} must be present (the others left out by `enabled`), {} are",
                    names.join(", "),
                    inputs.iter().filter(|t| t.is_some()).count()
                ),
            ));
        }
        let mut shape: Option<(usize, ValueType)> = None;
        for (i, t) in inputs.iter().enumerate() {
            let Some(t) = t else { continue };
            if *t == ValueType::Scalar {
                continue;
            }
            match shape {
                None => shape = Some((i, *t)),
                // One column per particle is broadcast over the columns of the other
                // operands (charges times fields), as a scalar is over every element.
                Some((_, s)) if row_broadcast(&s, t) && column_count(t) > column_count(&s) => {
                    shape = Some((i, *t));
                }
                Some((_, s)) if row_broadcast(&s, t) => {}
                Some((j, s)) if s != *t => {
                    return Err(PortError::new(
                        self.kind.inputs[i].0,
                        format!(
                            "is {t} but `{}` is {s}; element-wise operands must match (or be scalars)",
                            self.kind.inputs[j].0
                        ),
                    ));
                }
                _ => {}
            }
        }
        let out = shape
            .map(|(_, t)| t)
            .or(self.generated)
            .unwrap_or(ValueType::Scalar);
        if matches!(
            out,
            ValueType::ComplexGrid { .. } | ValueType::HalfComplexGrid { .. }
        ) && let Some(i) = inputs.iter().position(|t| *t == Some(ValueType::Scalar))
        {
            return Err(PortError::new(
                self.kind.inputs[i].0,
                format!("a scalar cannot be broadcast over the complex values of {out}"),
            ));
        }
        let port = self.kind.inputs.first().map(|p| p.0).unwrap_or("out");
        (self.kind.check)(&out, &self.values).map_err(|e| PortError::new(port, e))?;
        Ok(Signature::outputs(vec![out]))
    }

    fn forwards(&self, inputs: &[Option<ValueType>]) -> Option<usize> {
        if self.kind.one_of {
            let present: Vec<usize> = (0..inputs.len()).filter(|&i| inputs[i].is_some()).collect();
            return (present.len() == 1).then(|| present[0]);
        }
        let i = self.kind.forwards_alone?;
        let others_absent = inputs
            .iter()
            .enumerate()
            .all(|(j, t)| j == i || t.is_none());
        (others_absent && inputs.get(i).copied().flatten().is_some()).then_some(i)
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Pointwise(PointwiseBody {
            body: self.kind.body.to_string(),
            params: self.gpu_params.clone(),
            imports: self.kind.imports.iter().map(|s| s.to_string()).collect(),
            uses_step: self.kind.uses_step,
        })
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], cx: RefCtx) {
        let out = &mut outputs[0];
        let mut args = vec![0.0; inputs.len()];
        for idx in 0..out.data.len() {
            for (a, inp) in args.iter_mut().zip(inputs) {
                *a = match inp {
                    None => 0.0,
                    Some(r) if r.data.len() == 1 => r.data[0],
                    // A one-column particle array broadcast over the columns.
                    Some(r) if r.data.len() < out.data.len() => {
                        r.data[idx / (out.data.len() / r.data.len())]
                    }
                    Some(r) => r.data[idx],
                };
            }
            let at = ElemCtx {
                idx: idx as u64,
                comp: out.ty.component_of(idx as u64),
                step: cx.step,
            };
            out.data[idx] = (self.kind.reference)(&args, at, &self.values);
        }
    }
}

pub fn register(r: &mut Registry) {
    for row in KINDS {
        r.add(pointwise_kind(row));
    }
}
