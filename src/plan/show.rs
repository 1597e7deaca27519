//! Plans as text (`mesoflow inspect`) and as Graphviz DOT (`mesoflow inspect --dot`).

use std::fmt::Write;

use super::{BufferRole, Launch, Plan, Storage, TransformFold, ValueId, Via};
use crate::graph::{Graph, NodeId, Source};

/// Bytes for people.
pub fn human_bytes(b: u64) -> String {
    const K: f64 = 1024.0;
    let x = b as f64;
    if x < K {
        format!("{b} B")
    } else if x < K * K {
        format!("{:.1} KiB", x / K)
    } else if x < K * K * K {
        format!("{:.1} MiB", x / K / K)
    } else {
        format!("{:.2} GiB", x / K / K / K)
    }
}

fn place(plan: &Plan, v: ValueId) -> String {
    match plan.values[v].storage {
        Storage::Input(i) => format!("input {i}"),
        Storage::State { state, next } => {
            format!(
                "state {} {}",
                plan.states[state].name,
                if next { "next" } else { "current" }
            )
        }
        Storage::Buffer(b) => format!("buf {b}"),
        Storage::Register => "register".into(),
        Storage::Pending(_) => "unassigned".into(),
    }
}

fn value(plan: &Plan, v: ValueId) -> String {
    let val = &plan.values[v];
    format!("{} {} [{}]", val.name, val.ty, place(plan, v))
}

fn launch_lines(out: &mut String, g: &Graph, plan: &Plan, launches: &[Launch]) {
    launch_lines_indented(out, g, plan, launches, "");
}

fn launch_lines_indented(
    out: &mut String,
    g: &Graph,
    plan: &Plan,
    launches: &[Launch],
    indent: &str,
) {
    for (i, l) in launches.iter().enumerate() {
        let mut text = String::new();
        launch_text(&mut text, g, plan, i, l);
        for line in text.lines() {
            writeln!(out, "{indent}{line}").unwrap();
        }
    }
}

/// A node's or a transform's launch: its heading (with `head` after the node), notes,
/// reads and writes.
#[allow(clippy::too_many_arguments)]
fn node_text(
    out: &mut String,
    g: &Graph,
    plan: &Plan,
    i: usize,
    node: NodeId,
    head: &str,
    inputs: &[Option<ValueId>],
    outputs: &[ValueId],
    scratch: &[ValueId],
    notes: &[String],
) {
    let n = &g.nodes[node];
    writeln!(out, "  {:>3}. {} ({}){head}", i + 1, n.id, n.kind).unwrap();
    for note in notes {
        writeln!(out, "         note   {note}").unwrap();
    }
    for a in plan
        .in_place
        .iter()
        .filter(|a| a.node == node && a.via == Via::Node)
    {
        writeln!(
            out,
            "         note   in place: {} is written into the buffer of {} ({}), no copy",
            plan.values[a.output].name,
            plan.values[a.input].name,
            place(plan, a.input)
        )
        .unwrap();
    }
    for v in inputs.iter().flatten() {
        writeln!(out, "         reads  {}", value(plan, *v)).unwrap();
    }
    for v in outputs.iter().chain(scratch) {
        writeln!(out, "         writes {}", value(plan, *v)).unwrap();
    }
}

fn launch_text(out: &mut String, g: &Graph, plan: &Plan, i: usize, l: &Launch) {
    {
        match l {
            Launch::Loop {
                node,
                inputs,
                outputs,
                scratch,
                notes,
                body,
                refills,
                ..
            } => {
                let n = &g.nodes[*node];
                writeln!(out, "  {:>3}. {} ({}), a loop:", i + 1, n.id, n.kind).unwrap();
                for note in notes {
                    writeln!(out, "         note   {note}").unwrap();
                }
                // A refilled output its refill's input shares a buffer with: the body
                // wrote the value in place, the loop copies nothing per iteration.
                for &(o, r) in refills {
                    if let Some(v) = inputs[r]
                        && plan.values[v].storage == plan.values[outputs[o]].storage
                    {
                        writeln!(
                            out,
                            "         note   {} shares the buffer of {} ({}): no copy per iteration",
                            plan.values[v].name,
                            plan.values[outputs[o]].name,
                            place(plan, v)
                        )
                        .unwrap();
                    }
                }
                // The loop starts where its initial value lies, ends where its carried
                // value lies.
                for a in plan.in_place.iter().filter(|a| a.node == *node) {
                    let (i, o) = (&plan.values[a.input].name, &plan.values[a.output].name);
                    let at = place(plan, a.output);
                    match a.via {
                        Via::Start => writeln!(
                            out,
                            "         note   in place: {o} starts in the buffer of {i} ({at}), no copy at the start"
                        ),
                        Via::Finish => writeln!(
                            out,
                            "         note   in place: {o} is {i} where it lies ({at}), no copy at the finish"
                        ),
                        Via::Node => Ok(()),
                    }
                    .unwrap();
                }
                for v in inputs.iter().flatten() {
                    writeln!(out, "         reads  {}", value(plan, *v)).unwrap();
                }
                for v in outputs.iter().chain(scratch) {
                    writeln!(out, "         writes {}", value(plan, *v)).unwrap();
                }
                writeln!(out, "         each iteration:").unwrap();
                launch_lines_indented(out, g, plan, body, "         ");
            }
            Launch::Node {
                node,
                inputs,
                outputs,
                scratch,
                notes,
                ..
            } => node_text(out, g, plan, i, *node, "", inputs, outputs, scratch, notes),
            Launch::Transform {
                node,
                inputs,
                outputs,
                scratch,
                notes,
                fold,
                ..
            } => {
                let mut head = String::new();
                match fold {
                    TransformFold::Hosts(f) => {
                        let s = &g.nodes[f.node];
                        write!(head, " + {} ({}), folded", s.id, s.kind).unwrap();
                        if let Some(c) = f.inverse {
                            let c = &g.nodes[c];
                            write!(head, " + first pass of {} ({})", c.id, c.kind).unwrap();
                        }
                    }
                    TransformFold::FirstPassElsewhere => head.push_str(", from its second pass"),
                    TransformFold::Alone => {}
                }
                node_text(
                    out, g, plan, i, *node, &head, inputs, outputs, scratch, notes,
                );
                if let TransformFold::Hosts(f) = fold {
                    writeln!(out, "         writes {}", value(plan, f.output)).unwrap();
                }
            }
            Launch::Fused(k) => {
                let names: Vec<String> = k
                    .nodes
                    .iter()
                    .map(|&n| format!("{} ({})", g.nodes[n].id, g.nodes[n].kind))
                    .collect();
                let label = if k.nodes.len() > 1 {
                    format!("fused x{}", k.nodes.len())
                } else {
                    "pointwise".into()
                };
                writeln!(
                    out,
                    "  {:>3}. [{label}, {} elements] {}",
                    i + 1,
                    k.len,
                    names.join(" -> ")
                )
                .unwrap();
                for v in &k.inputs {
                    writeln!(out, "         reads  {}", value(plan, *v)).unwrap();
                }
                for v in &k.outputs {
                    writeln!(out, "         writes {}", value(plan, *v)).unwrap();
                }
            }
            Launch::Copy { src, dst } => {
                writeln!(
                    out,
                    "  {:>3}. copy {} -> {}",
                    i + 1,
                    value(plan, *src),
                    place(plan, *dst)
                )
                .unwrap();
            }
        }
    }
}

/// The plan as text: order, fused groups, buffers, memory.
pub fn to_text(g: &Graph, plan: &Plan) -> String {
    let mut out = String::new();
    writeln!(out, "graph   {}", g.file.display()).unwrap();
    if !g.doc.is_empty() {
        writeln!(out, "        {}", g.doc).unwrap();
    }
    writeln!(out, "device  {}", plan.caps.summary()).unwrap();
    if !g.params.is_empty() {
        writeln!(out, "params").unwrap();
        for p in &g.params {
            writeln!(out, "  {} = {}", p.name, p.value).unwrap();
        }
    }
    writeln!(out, "inputs").unwrap();
    for (i, t) in &plan.inputs {
        writeln!(out, "  {} {t}", g.inputs[*i].name).unwrap();
    }
    for (i, d) in g.inputs.iter().enumerate() {
        if !plan.inputs.iter().any(|(j, _)| *j == i) {
            writeln!(out, "  {} (not given)", d.name).unwrap();
        }
    }
    if !plan.states.is_empty() {
        writeln!(out, "states").unwrap();
        for s in &plan.states {
            writeln!(out, "  {} {}", s.name, s.ty).unwrap();
        }
    }
    writeln!(out, "prologue (once, before the first step)").unwrap();
    launch_lines(&mut out, g, plan, &plan.prologue);
    writeln!(out, "step (every time step)").unwrap();
    for (i, l) in plan.step.iter().enumerate() {
        let mut text = String::new();
        launch_text(&mut text, g, plan, i, l);
        for (k, line) in text.lines().enumerate() {
            writeln!(out, "{line}").unwrap();
            if k == 0 && plan.last_step_only.contains(&i) {
                writeln!(
                    out,
                    "         note   on the last step of a run only: only outputs read it"
                )
                .unwrap();
            }
        }
    }
    writeln!(out, "outputs (after the last step)").unwrap();
    for (name, v) in &plan.outputs {
        writeln!(out, "  {name} <- {}", value(plan, *v)).unwrap();
    }
    if !plan.pruned.is_empty() {
        let ids: Vec<&str> = plan
            .pruned
            .iter()
            .map(|&n| g.nodes[n].id.as_str())
            .collect();
        writeln!(
            out,
            "not run (no requested output needs them)\n  {}",
            ids.join(", ")
        )
        .unwrap();
    }
    if !plan.forwarded.is_empty() {
        let ids: Vec<&str> = plan
            .forwarded
            .iter()
            .map(|&n| g.nodes[n].id.as_str())
            .collect();
        writeln!(
            out,
            "read through (their output is an input unchanged, e.g. a sum whose optional term is absent)\n  {}",
            ids.join(", ")
        )
        .unwrap();
    }
    writeln!(out, "buffers").unwrap();
    for (i, b) in plan.buffers.iter().enumerate() {
        let role = match b.role {
            BufferRole::Pool => "pool",
            BufferRole::Output => "output",
            BufferRole::Persistent => "persistent",
        };
        writeln!(
            out,
            "  buf {i:<3} {:>10}  {role:<10} {}",
            human_bytes(b.bytes),
            b.holds.join(", ")
        )
        .unwrap();
    }
    let m = &plan.memory;
    writeln!(
        out,
        "memory  {} in all: inputs {}, states {} (two buffers each), pool {} ({} without reuse), outputs {}, persistent {}",
        human_bytes(m.total()),
        human_bytes(m.inputs),
        human_bytes(m.states),
        human_bytes(m.pool),
        human_bytes(m.pool_without_reuse),
        human_bytes(m.outputs),
        human_bytes(m.persistent)
    )
    .unwrap();
    let every = plan.launches_every_step();
    let last = plan.last_step_only.len();
    let last_note = if last == 0 {
        String::new()
    } else {
        format!(" (and {last} on the last step of a run only)")
    };
    writeln!(out, "        {every} launches per step{last_note}; node tables and constants are allocated when the plan is compiled").unwrap();
    out
}

fn q(s: &str) -> String {
    format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""))
}

/// The plan as a Graphviz digraph: fused groups are clusters, edges carry types.
pub fn to_dot(g: &Graph, plan: &Plan) -> String {
    let mut out = String::from(
        "digraph mesoflow {\n  rankdir=LR;\n  node [shape=box, fontname=\"Helvetica\"];\n",
    );
    for (i, t) in &plan.inputs {
        writeln!(
            out,
            "  {} [shape=ellipse, label={}];",
            q(&format!("inputs.{}", g.inputs[*i].name)),
            q(&format!("{}\\n{t}", g.inputs[*i].name))
        )
        .unwrap();
    }
    for s in &plan.states {
        writeln!(
            out,
            "  {} [shape=diamond, label={}];",
            q(&format!("state.{}", s.name)),
            q(&format!("state {}\\n{}", s.name, s.ty))
        )
        .unwrap();
    }
    let mut scheduled = Vec::new();
    for (cluster, l) in plan.step.iter().enumerate() {
        match l {
            Launch::Fused(k) if k.nodes.len() > 1 => {
                writeln!(
                    out,
                    "  subgraph cluster_{cluster} {{ label=\"fused\"; style=dashed;"
                )
                .unwrap();
                for &n in &k.nodes {
                    writeln!(
                        out,
                        "    {} [label={}];",
                        q(&g.nodes[n].id),
                        q(&format!("{}\\n{}", g.nodes[n].id, g.nodes[n].kind))
                    )
                    .unwrap();
                    scheduled.push(n);
                }
                out.push_str("  }\n");
            }
            other => {
                for n in other.nodes() {
                    writeln!(
                        out,
                        "  {} [label={}];",
                        q(&g.nodes[n].id),
                        q(&format!("{}\\n{}", g.nodes[n].id, g.nodes[n].kind))
                    )
                    .unwrap();
                    scheduled.push(n);
                }
            }
        }
    }
    for l in &plan.prologue {
        for n in l.nodes() {
            if !scheduled.contains(&n) {
                writeln!(
                    out,
                    "  {} [label={}, style=rounded];",
                    q(&g.nodes[n].id),
                    q(&format!(
                        "{}\\n{} (prologue)",
                        g.nodes[n].id, g.nodes[n].kind
                    ))
                )
                .unwrap();
                scheduled.push(n);
            }
        }
    }
    let name = |s: Source| match s {
        Source::Node { node, .. } => Some(g.nodes[node].id.clone()),
        Source::Input(i) => Some(format!("inputs.{}", g.inputs[i].name)),
        Source::State(i) => Some(format!("state.{}", g.states[i].name)),
        Source::Absent => None,
    };
    for &n in &scheduled {
        let inst = &g.nodes[n];
        for (port, s) in inst.input_ports.iter().zip(&inst.inputs) {
            if let Some(from) = name(*s) {
                writeln!(
                    out,
                    "  {} -> {} [label={}];",
                    q(&from),
                    q(&inst.id),
                    q(port.name)
                )
                .unwrap();
            }
        }
    }
    for s in &plan.states {
        if let Some(def) = g.states.iter().find(|d| d.name == s.name)
            && let Some(from) = name(def.next)
        {
            writeln!(
                out,
                "  {} -> {} [style=dotted, label=\"next\"];",
                q(&from),
                q(&format!("state.{}", s.name))
            )
            .unwrap();
        }
    }
    for (oname, v) in &plan.outputs {
        writeln!(
            out,
            "  {} [shape=ellipse, style=bold, label={}];",
            q(&format!("outputs.{oname}")),
            q(oname)
        )
        .unwrap();
        let src = g
            .outputs
            .iter()
            .find(|o| &o.name == oname)
            .and_then(|o| name(o.source));
        if let Some(from) = src {
            writeln!(
                out,
                "  {} -> {} [label={}];",
                q(&from),
                q(&format!("outputs.{oname}")),
                q(&plan.values[*v].ty.to_string())
            )
            .unwrap();
        }
    }
    out.push_str("}\n");
    out
}
