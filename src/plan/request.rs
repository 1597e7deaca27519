//! Pass 1, the request: which outputs are asked for and which inputs are given, checked
//! against the graph's declarations (names, shapes, sizes shared between inputs).

use std::collections::HashMap;

use super::{PlanOptions, too_large_for};
use crate::gpu::DeviceCaps;
use crate::graph::{Dim, Graph, InputShape, Problem, Problems};
use crate::value::ValueType;

/// What the caller asks for, resolved against the graph.
pub(super) struct Request {
    /// Indices into `Graph::outputs`, in the order asked.
    pub outputs: Vec<usize>,
    /// The type of each graph input (`None`: not given, absent).
    pub input_types: Vec<Option<ValueType>>,
}

pub(super) fn resolve(
    g: &Graph,
    opts: &PlanOptions,
    caps: &DeviceCaps,
) -> Result<Request, Problems> {
    let mut problems = Vec::new();
    let outputs = match &opts.outputs {
        None => (0..g.outputs.len()).collect(),
        Some(names) => names
            .iter()
            .enumerate()
            .filter_map(|(i, n)| {
                if names[..i].contains(n) {
                    problems.push(Problem::file(
                        &g.file,
                        format!("output `{n}` is asked for twice"),
                    ));
                    return None;
                }
                let found = g.output(n);
                if found.is_none() {
                    let known: Vec<&str> = g.outputs.iter().map(|o| o.name.as_str()).collect();
                    problems.push(Problem::file(
                        &g.file,
                        format!("unknown output `{n}` (outputs: {})", known.join(", ")),
                    ));
                }
                found
            })
            .collect(),
    };
    let mut input_types = vec![None; g.inputs.len()];
    for (name, ty) in &opts.inputs {
        match g.input(name) {
            Some(i) => {
                if let Err(e) = g.inputs[i].shape.check(ty) {
                    problems.push(Problem::file(&g.file, format!("input `{name}`: {e}")));
                }
                if let Some(why) = too_large_for(caps, ty.bytes()) {
                    problems.push(Problem::file(
                        &g.file,
                        format!("input `{name}` is {ty}, {why}"),
                    ));
                }
                input_types[i] = Some(*ty);
            }
            None => {
                let known: Vec<&str> = g.inputs.iter().map(|i| i.name.as_str()).collect();
                problems.push(Problem::file(
                    &g.file,
                    format!("unknown input `{name}` (inputs: {})", known.join(", ")),
                ));
            }
        }
    }
    problems.extend(size_disagreements(g, &input_types));
    if problems.is_empty() {
        Ok(Request {
            outputs,
            input_types,
        })
    } else {
        Err(Problems(problems))
    }
}

/// Every input naming one size must agree on it.
fn size_disagreements(g: &Graph, input_types: &[Option<ValueType>]) -> Vec<Problem> {
    let mut problems = Vec::new();
    let mut seen: HashMap<&str, (u32, &str)> = HashMap::new();
    for (def, ty) in g.inputs.iter().zip(input_types) {
        let (Some(ty), Some(Dim::Size(size))) = (
            ty,
            match &def.shape {
                InputShape::Particles { rows, .. } | InputShape::Indices { rows } => Some(rows),
                _ => None,
            },
        ) else {
            continue;
        };
        let n = match ty {
            ValueType::Particles { n, .. } | ValueType::Indices { n } => *n,
            _ => continue,
        };
        match seen.get(size.as_str()) {
            Some((m, other)) if *m != n => problems.push(Problem::file(
                &g.file,
                format!(
                    "input `{}` has {n} rows but input `{other}` has {m}; both are declared with rows `{size}`",
                    def.name
                ),
            )),
            Some(_) => {}
            None => {
                seen.insert(size, (n, &def.name));
            }
        }
    }
    problems
}
