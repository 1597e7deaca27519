//! Element-wise arithmetic. The planner compiles these itself (fused with their
//! neighbours, or alone); each kind is a WGSL body plus its f64 CPU reference, written
//! side by side in one table row.

use crate::node::{
    Lowering, Node, NodeKind, ParamKind, ParamSpec, Params, PointwiseBody, PortError, PortSpec,
    RefCtx, Registry, Signature,
};
use crate::value::{PortType, RefArray, ValueType};

/// One element-wise kind.
pub struct PointwiseKind {
    name: &'static str,
    doc: &'static str,
    /// (name, doc, optional). An absent optional input reads as 0.
    inputs: &'static [(&'static str, &'static str, bool)],
    params: fn() -> Vec<ParamSpec>,
    /// Param values handed to the body as p0, p1, ...
    flatten: fn(&Params) -> Vec<f64>,
    /// Extra shape check against the param values (per-component kinds).
    check: fn(&ValueType, &[f64]) -> Result<(), String>,
    body: &'static str,
    /// The params are one value per component, padded to MAX_COMPONENTS for the body.
    per_component: bool,
    /// f64 reference of one element: (inputs, component, params).
    reference: fn(&[f64], u32, &[f64]) -> f64,
}

fn no_params() -> Vec<ParamSpec> {
    Vec::new()
}

fn nothing(_: &Params) -> Vec<f64> {
    Vec::new()
}

fn any_shape(_: &ValueType, _: &[f64]) -> Result<(), String> {
    Ok(())
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
            min: f64::MIN,
            max: f64::MAX,
        },
        default: None,
        doc,
    }
}

fn flatten_numbers(name: &'static str) -> impl Fn(&Params) -> Vec<f64> {
    move |p| p.numbers(name).to_vec()
}

/// Per-component kinds read p[comp] from an array of this many params.
const MAX_COMPONENTS: usize = 4;

/// The element-wise kinds mesoflow ships.
pub static KINDS: &[PointwiseKind] = &[
    PointwiseKind {
        name: "scale",
        doc: "out = factor * x, element-wise",
        inputs: &[("x", "values to scale", false)],
        params: || {
            vec![ParamSpec::number(
                "factor",
                None,
                f64::MIN,
                f64::MAX,
                "the factor",
            )]
        },
        flatten: |p| vec![p.number("factor")],
        check: any_shape,
        body: "return p0 * x;",
        per_component: false,
        reference: |i, _, p| p[0] * i[0],
    },
    PointwiseKind {
        name: "add",
        doc: "out = a + b, element-wise (a scalar operand is broadcast; absent b reads as 0)",
        inputs: &[("a", "first term", false), ("b", "second term", true)],
        params: no_params,
        flatten: nothing,
        check: any_shape,
        body: "return a + b;",
        per_component: false,
        reference: |i, _, _| i[0] + i[1],
    },
    PointwiseKind {
        name: "sub",
        doc: "out = a - b, element-wise (a scalar operand is broadcast)",
        inputs: &[("a", "minuend", false), ("b", "subtrahend", false)],
        params: no_params,
        flatten: nothing,
        check: any_shape,
        body: "return a - b;",
        per_component: false,
        reference: |i, _, _| i[0] - i[1],
    },
    PointwiseKind {
        name: "multiply",
        doc: "out = a * b, element-wise (a scalar operand is broadcast)",
        inputs: &[("a", "first factor", false), ("b", "second factor", false)],
        params: no_params,
        flatten: nothing,
        check: any_shape,
        body: "return a * b;",
        per_component: false,
        reference: |i, _, _| i[0] * i[1],
    },
    PointwiseKind {
        name: "divide",
        doc: "out = a / b, element-wise (a scalar operand is broadcast)",
        inputs: &[("a", "numerator", false), ("b", "denominator", false)],
        params: no_params,
        flatten: nothing,
        check: any_shape,
        body: "return a / b;",
        per_component: false,
        reference: |i, _, _| i[0] / i[1],
    },
    PointwiseKind {
        name: "axpy",
        doc: "out = alpha * x + y, element-wise",
        inputs: &[("x", "scaled term", false), ("y", "added term", false)],
        params: || {
            vec![ParamSpec::number(
                "alpha",
                None,
                f64::MIN,
                f64::MAX,
                "factor on x",
            )]
        },
        flatten: |p| vec![p.number("alpha")],
        check: any_shape,
        body: "return fma(p0, x, y);",
        per_component: false,
        reference: |i, _, p| p[0] * i[0] + i[1],
    },
    PointwiseKind {
        name: "axpby",
        doc: "out = alpha * x + beta * y, element-wise",
        inputs: &[("x", "first term", false), ("y", "second term", false)],
        params: || {
            vec![
                ParamSpec::number("alpha", None, f64::MIN, f64::MAX, "factor on x"),
                ParamSpec::number("beta", None, f64::MIN, f64::MAX, "factor on y"),
            ]
        },
        flatten: |p| vec![p.number("alpha"), p.number("beta")],
        check: any_shape,
        body: "return fma(p0, x, p1 * y);",
        per_component: false,
        reference: |i, _, p| p[0] * i[0] + p[1] * i[1],
    },
    PointwiseKind {
        name: "affine",
        doc: "out = scale * x + offset, element-wise",
        inputs: &[("x", "values", false)],
        params: || {
            vec![
                ParamSpec::number("scale", Some(1.0), f64::MIN, f64::MAX, "factor on x"),
                ParamSpec::number("offset", Some(0.0), f64::MIN, f64::MAX, "added constant"),
            ]
        },
        flatten: |p| vec![p.number("scale"), p.number("offset")],
        check: any_shape,
        body: "return fma(p0, x, p1);",
        per_component: false,
        reference: |i, _, p| p[0] * i[0] + p[1],
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
        flatten: |p| flatten_numbers("factors")(p),
        check: components_match,
        body: "var t = array<f32, 4>(p0, p1, p2, p3); return x * t[min(comp, 3u)];",
        per_component: true,
        reference: |i, c, p| i[0] * p[c as usize],
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
        flatten: |p| flatten_numbers("offsets")(p),
        check: components_match,
        body: "var t = array<f32, 4>(p0, p1, p2, p3); return x + t[min(comp, 3u)];",
        per_component: true,
        reference: |i, c, p| i[0] + p[c as usize],
    },
];

impl NodeKind for &'static PointwiseKind {
    fn name(&self) -> &'static str {
        self.name
    }

    fn doc(&self) -> &'static str {
        self.doc
    }

    fn inputs(&self) -> Vec<PortSpec> {
        self.inputs
            .iter()
            .map(|&(n, d, opt)| {
                let p = PortSpec::new(n, PortType::RealArray, d);
                if opt { p.optional() } else { p }
            })
            .collect()
    }

    fn outputs(&self) -> Vec<PortSpec> {
        vec![PortSpec::new(
            "out",
            PortType::RealArray,
            "result, shaped like the non-scalar inputs",
        )]
    }

    fn params(&self) -> Vec<ParamSpec> {
        (self.params)()
    }

    fn build(&self, params: &Params) -> Result<Box<dyn Node>, String> {
        let values = (self.flatten)(params);
        if self.per_component && values.len() > MAX_COMPONENTS {
            return Err(format!(
                "at most {MAX_COMPONENTS} per-component values are supported, got {}",
                values.len()
            ));
        }
        let mut gpu_params: Vec<f32> = values.iter().map(|&x| x as f32).collect();
        if self.per_component {
            gpu_params.resize(MAX_COMPONENTS, 0.0);
        }
        Ok(Box::new(PointwiseNode {
            kind: self,
            values,
            gpu_params,
        }))
    }
}

struct PointwiseNode {
    kind: &'static PointwiseKind,
    values: Vec<f64>,
    gpu_params: Vec<f32>,
}

impl Node for PointwiseNode {
    fn infer(&self, inputs: &[Option<ValueType>]) -> Result<Signature, PortError> {
        let mut shape: Option<(usize, ValueType)> = None;
        for (i, t) in inputs.iter().enumerate() {
            let Some(t) = t else { continue };
            if *t == ValueType::Scalar {
                continue;
            }
            match shape {
                None => shape = Some((i, *t)),
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
        let out = shape.map(|(_, t)| t).unwrap_or(ValueType::Scalar);
        (self.kind.check)(&out, &self.values)
            .map_err(|e| PortError::new(self.kind.inputs[0].0, e))?;
        Ok(Signature::outputs(vec![out]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Pointwise(PointwiseBody {
            body: self.kind.body.to_string(),
            params: self.gpu_params.clone(),
        })
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _cx: RefCtx) {
        let out = &mut outputs[0];
        let mut args = vec![0.0; inputs.len()];
        for idx in 0..out.data.len() {
            for (a, inp) in args.iter_mut().zip(inputs) {
                *a = match inp {
                    None => 0.0,
                    Some(r) if r.data.len() == 1 => r.data[0],
                    Some(r) => r.data[idx],
                };
            }
            out.data[idx] =
                (self.kind.reference)(&args, out.ty.component_of(idx as u64), &self.values);
        }
    }
}

pub fn register(r: &mut Registry) {
    for k in KINDS {
        r.add(k);
    }
}
