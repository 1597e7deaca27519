//! Checking a graph file without a GPU (`mesoflow validate`): loaded with its defaults and
//! planned for its declared inputs against device-independent capabilities.

use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;

use super::{PlanOptions, plan};
use crate::gpu::DeviceCaps;
use crate::graph::{self, LoadOptions, Problems};
use crate::node::Registry;
use crate::value::ValueType;

/// What [`validate_file`] found in a valid graph file.
#[derive(Clone, Debug)]
pub struct Validation {
    pub nodes: usize,
    /// Launches every step runs (`Plan::launches_every_step`): the plan's, or where
    /// outputs plan separately, the most any of them needs.
    pub launches: usize,
    /// Outputs that plan only without the optional inputs, or not at all, with the
    /// default params (each with the problems met).
    pub notes: Vec<String>,
}

impl fmt::Display for Validation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.notes.is_empty() {
            write!(
                f,
                "{} nodes, {} launches per step",
                self.nodes, self.launches
            )
        } else {
            write!(
                f,
                "{} nodes, up to {} launches per step\nnotes:\n{}",
                self.nodes,
                self.launches,
                self.notes.join("\n")
            )
        }
    }
}

/// Capabilities for checks that do not depend on a device: the baseline's, with no
/// binding or buffer size limit.
fn structural_caps() -> DeviceCaps {
    DeviceCaps {
        max_binding: u64::MAX,
        max_buffer: u64::MAX,
        ..DeviceCaps::baseline()
    }
}

/// Loads a graph file with its defaults and plans its outputs as `run` does when given
/// its required inputs only ([`graph::Graph::declared_input_types`]: optional inputs
/// absent). Some outputs or optional inputs may need other params than the defaults
/// (FCM's rotation needs its finer grid): the file is valid when some output plans, and
/// the outputs that do not, or that do not with the optional inputs given as well, are
/// reported as notes; otherwise the error is the problems of planning everything.
pub fn validate_file(registry: &Registry, path: &Path) -> Result<Validation, Problems> {
    let g = graph::load(path, registry, &LoadOptions::default())?;
    let required = g.declared_input_types();
    let all = g.declared_input_types_with_optional();
    let caps = structural_caps();
    let plan_with = |inputs: &BTreeMap<String, ValueType>, outputs: Option<Vec<String>>| {
        let opts = PlanOptions {
            outputs,
            inputs: inputs.clone(),
            fuse: true,
            in_place: true,
        };
        plan(&g, &opts, &caps)
    };
    let first_error = match (plan_with(&required, None), plan_with(&all, None)) {
        (Ok(p), Ok(q)) => {
            return Ok(Validation {
                nodes: g.nodes.len(),
                launches: p.launches_every_step().max(q.launches_every_step()),
                notes: Vec::new(),
            });
        }
        (Err(e), _) | (_, Err(e)) => e,
    };
    let mut notes = Vec::new();
    let mut launches = 0;
    let mut planned = 0;
    for out in &g.outputs {
        let only = Some(vec![out.name.clone()]);
        match plan_with(&required, only.clone()) {
            Ok(p) => {
                planned += 1;
                launches = launches.max(p.launches_every_step());
                match plan_with(&all, only) {
                    Ok(q) => launches = launches.max(q.launches_every_step()),
                    Err(e_all) => notes.push(format!(
                        "output `{}` plans without the optional inputs only (with the defaults):\n{e_all}",
                        out.name
                    )),
                }
            }
            Err(e) => notes.push(format!(
                "output `{}` does not plan with the default params:\n{e}",
                out.name
            )),
        }
    }
    if planned == 0 {
        return Err(first_error);
    }
    Ok(Validation {
        nodes: g.nodes.len(),
        launches,
        notes,
    })
}
