//! Fusion of element-wise (pointwise) nodes into generated kernels.
//!
//! Pointwise nodes of one phase with the same element count are grouped greedily in
//! topological order. A node joins the group of one of its producers unless another of
//! its inputs depends on that group through a node outside it (joining would then make a
//! cycle between the group and that node). A group becomes one kernel: each element is
//! loaded once, the members' bodies run in registers, and only values used outside the
//! group are stored. Without fusion every pointwise node is a group of one, through the
//! same code generator, so fused and unfused runs differ only in f32 rounding of stores
//! (none: registers hold the same f32 values).

use std::cmp::Reverse;
use std::collections::{BTreeMap, BTreeSet, BinaryHeap, HashMap};
use std::fmt::Write;

use super::infer::Inferred;
use super::{PlanValue, ValueId};
use crate::gpu::WG_1D;
use crate::graph::{Graph, NodeId, Source};
use crate::ids::IdVec;
use crate::node::Lowering;
use crate::value::ValueType;

/// Binding budget of a fused kernel: WebGPU guarantees 8 storage buffers per stage.
const MAX_BINDINGS: usize = 8;

/// The most members one fused kernel has. Shader compilers take time superlinear in a
/// kernel's straight-line length (a chain of 2,000 element-wise nodes, fused whole, took
/// minutes to build), so longer groups are cut into consecutive runs of this many; each
/// cut costs one store and one load per element, nothing on results (values are f32 in
/// registers and in buffers alike).
pub const MAX_FUSED_NODES: usize = 64;

pub struct FuseCtx<'a> {
    pub g: &'a Graph,
    pub types: &'a IdVec<NodeId, Inferred>,
    pub order: &'a [NodeId],
    pub fuse: bool,
    /// Whether a node output is needed after the phase (an output, a state's next value).
    pub escapes: &'a dyn Fn(Source) -> bool,
}

/// A unit of the schedule.
#[derive(Clone, Debug)]
pub enum Unit {
    Single(NodeId),
    /// Pointwise members in order, each with whether its output must be stored.
    Group(Vec<(NodeId, bool)>),
    /// A transform that applies a spectral node in its last pass (see `fold.rs`),
    /// and with `inverse` also the first pass of the inverse transform after it.
    Folded {
        transform: NodeId,
        spectral: NodeId,
        inverse: Option<NodeId>,
    },
    /// An inverse transform whose first pass a [`Unit::Folded`] ran.
    AfterFold(NodeId),
}

/// A generated element-wise kernel.
#[derive(Clone, Debug)]
pub struct FusedKernel {
    pub nodes: Vec<NodeId>,
    /// Complete WGSL. Params are not in it, so equal structures share one pipeline.
    pub source: String,
    /// Bindings in order: params, the clock when `uses_clock`, `inputs`, `outputs`.
    pub inputs: Vec<ValueId>,
    pub outputs: Vec<ValueId>,
    pub params: Vec<f32>,
    /// Elements per member.
    pub len: u64,
    /// Binding 1 is the engine clock (a member reads the step).
    pub uses_clock: bool,
}

fn out_type(ctx: &FuseCtx, n: NodeId) -> Option<ValueType> {
    ctx.types[n].outputs()?.first().copied()
}

/// Values element-wise kernels run over as flat f32 words: spectra too (only real-linear
/// kinds accept them, and those act on real and imaginary parts alike).
fn real_array(t: &ValueType) -> bool {
    matches!(
        t,
        ValueType::Particles { .. }
            | ValueType::RealGrid { .. }
            | ValueType::Scalar
            | ValueType::ComplexGrid { .. }
            | ValueType::HalfComplexGrid { .. }
    )
}

fn is_pointwise(ctx: &FuseCtx, n: NodeId) -> bool {
    let inst = &ctx.g.nodes[n];
    matches!(inst.node().lowering(), Lowering::Pointwise(_))
        && inst.output_ports.len() == 1
        && out_type(ctx, n).is_some_and(|t| real_array(&t))
}

/// Groups the phase's nodes and orders the units.
pub fn group(ctx: &FuseCtx) -> Vec<Unit> {
    let in_phase: BTreeSet<NodeId> = ctx.order.iter().copied().collect();
    let pos: HashMap<NodeId, usize> = ctx.order.iter().enumerate().map(|(i, &n)| (n, i)).collect();
    let mut group_of: HashMap<NodeId, usize> = HashMap::new();
    let mut groups: Vec<Vec<NodeId>> = Vec::new();
    // deps[n]: groups n depends on, transitively.
    let mut deps: HashMap<NodeId, BTreeSet<usize>> = HashMap::new();

    for &n in ctx.order {
        let inst = &ctx.g.nodes[n];
        let producers: Vec<NodeId> = inst
            .inputs
            .iter()
            .filter_map(|s| match s {
                Source::Node { node, .. } if in_phase.contains(node) => Some(*node),
                _ => None,
            })
            .collect();
        let mut d = BTreeSet::new();
        for &u in &producers {
            d.extend(deps.get(&u).into_iter().flatten().copied());
            if let Some(&gu) = group_of.get(&u) {
                d.insert(gu);
            }
        }
        if is_pointwise(ctx, n) {
            let len = out_type(ctx, n).map(|t| t.words()).unwrap_or(0);
            let mut chosen = None;
            if ctx.fuse {
                for &u in &producers {
                    let Some(&gu) = group_of.get(&u) else {
                        continue;
                    };
                    if out_type(ctx, u).map(|t| t.words()) != Some(len) {
                        continue;
                    }
                    // No other input may reach this group from outside it.
                    let blocked = producers.iter().any(|&w| {
                        group_of.get(&w) != Some(&gu)
                            && deps.get(&w).is_some_and(|dw| dw.contains(&gu))
                    });
                    if !blocked {
                        chosen = Some(gu);
                        break;
                    }
                }
            }
            let gid = match chosen {
                Some(gu) => {
                    groups[gu].push(n);
                    gu
                }
                None => {
                    groups.push(vec![n]);
                    groups.len() - 1
                }
            };
            group_of.insert(n, gid);
        }
        deps.insert(n, d);
    }

    // Escaping outputs: used outside the group or after the phase.
    let mut consumers: HashMap<NodeId, Vec<NodeId>> = HashMap::new();
    for &n in ctx.order {
        for s in &ctx.g.nodes[n].inputs {
            if let Source::Node { node, .. } = s {
                consumers.entry(*node).or_default().push(n);
            }
        }
    }
    let groups = split_for_bindings(ctx, groups, &consumers);
    let mut group_of: HashMap<NodeId, usize> = HashMap::new();
    for (gid, members) in groups.iter().enumerate() {
        for &m in members {
            group_of.insert(m, gid);
        }
    }
    let escapes = |n: NodeId, gid: usize| -> bool {
        (ctx.escapes)(Source::Node { node: n, port: 0 })
            || consumers
                .get(&n)
                .into_iter()
                .flatten()
                .any(|c| group_of.get(c) != Some(&gid))
    };

    // Units, ordered topologically on the quotient graph (first-declared first).
    let mut unit_of: HashMap<NodeId, usize> = HashMap::new();
    let mut units: Vec<Unit> = Vec::new();
    let mut unit_pos: Vec<usize> = Vec::new();
    let mut group_unit: HashMap<usize, usize> = HashMap::new();
    for &n in ctx.order {
        match group_of.get(&n) {
            Some(&gid) => {
                let u = *group_unit.entry(gid).or_insert_with(|| {
                    let members = groups[gid].iter().map(|&m| (m, escapes(m, gid))).collect();
                    units.push(Unit::Group(members));
                    unit_pos.push(pos[&n]);
                    units.len() - 1
                });
                unit_of.insert(n, u);
            }
            None => {
                units.push(Unit::Single(n));
                unit_pos.push(pos[&n]);
                unit_of.insert(n, units.len() - 1);
            }
        }
    }
    let mut indeg = vec![0usize; units.len()];
    let mut succ: Vec<BTreeSet<usize>> = vec![BTreeSet::new(); units.len()];
    for &n in ctx.order {
        let un = unit_of[&n];
        for s in &ctx.g.nodes[n].inputs {
            if let Source::Node { node, .. } = s
                && let Some(&up) = unit_of.get(node)
                && up != un
                && succ[up].insert(un)
            {
                indeg[un] += 1;
            }
        }
    }
    let mut ready: BinaryHeap<Reverse<(usize, usize)>> = (0..units.len())
        .filter(|&u| indeg[u] == 0)
        .map(|u| Reverse((unit_pos[u], u)))
        .collect();
    let mut ordered = Vec::new();
    while let Some(Reverse((_, u))) = ready.pop() {
        ordered.push(u);
        for &v in &succ[u] {
            indeg[v] -= 1;
            if indeg[v] == 0 {
                ready.push(Reverse((unit_pos[v], v)));
            }
        }
    }
    assert_eq!(
        ordered.len(),
        units.len(),
        "fusion produced a cyclic schedule"
    );
    let mut slots: Vec<Option<Unit>> = units.into_iter().map(Some).collect();
    ordered
        .into_iter()
        .map(|u| slots[u].take().expect("each unit once"))
        .collect()
}

/// Cuts groups into consecutive runs whose kernels fit the binding budget and
/// [`MAX_FUSED_NODES`]. A run of a
/// convex group is convex (members are in topological order, and no outside node sits
/// between two members), so the cut needs no further checks.
fn split_for_bindings(
    ctx: &FuseCtx,
    groups: Vec<Vec<NodeId>>,
    consumers: &HashMap<NodeId, Vec<NodeId>>,
) -> Vec<Vec<NodeId>> {
    let bindings = |chunk: &[NodeId]| -> usize {
        let inside: BTreeSet<NodeId> = chunk.iter().copied().collect();
        let mut ext = BTreeSet::new();
        let mut outs = 0;
        for &m in chunk {
            for s in &ctx.g.nodes[m].inputs {
                match s {
                    Source::Absent => {}
                    Source::Node { node, .. } if inside.contains(node) => {}
                    s => {
                        ext.insert(*s);
                    }
                }
            }
            // Conservative while the run grows: a consumer not (yet) in the run counts as outside.
            let outside = consumers
                .get(&m)
                .into_iter()
                .flatten()
                .any(|c| !inside.contains(c));
            if outside || (ctx.escapes)(Source::Node { node: m, port: 0 }) {
                outs += 1;
            }
        }
        let clock = chunk.iter().any(
            |&m| matches!(ctx.g.nodes[m].node().lowering(), Lowering::Pointwise(b) if b.uses_step),
        );
        1 + usize::from(clock) + ext.len() + outs
    };
    let mut out = Vec::new();
    for members in groups {
        let mut run: Vec<NodeId> = Vec::new();
        for m in members {
            run.push(m);
            if run.len() > 1 && (run.len() > MAX_FUSED_NODES || bindings(&run) > MAX_BINDINGS) {
                run.pop();
                out.push(std::mem::take(&mut run));
                run.push(m);
            }
        }
        out.push(run);
    }
    out
}

/// How the component index of an element follows from the output type.
fn comp_expr(t: &ValueType) -> String {
    match *t {
        ValueType::Particles { k, .. } => format!("idx % {k}u"),
        ValueType::RealGrid { dims, .. } => format!(
            "idx / {}u",
            dims[0] as u64 * dims[1] as u64 * dims[2] as u64
        ),
        _ => "0u".into(),
    }
}

/// Generates the kernel of a group. `member_outputs[i]` is the value of member i's
/// output (in registers unless it escapes); `get` finds the value of any other source
/// (`None`: absent).
pub fn generate(
    g: &Graph,
    members: &[(NodeId, bool)],
    member_outputs: &[ValueId],
    get: &dyn Fn(Source) -> Option<ValueId>,
    values: &IdVec<ValueId, PlanValue>,
) -> FusedKernel {
    let len = values[member_outputs[0]].ty.words();
    let local: HashMap<Source, usize> = members
        .iter()
        .enumerate()
        .map(|(j, &(n, _))| (Source::Node { node: n, port: 0 }, j))
        .collect();
    let mut inputs: Vec<ValueId> = Vec::new();
    let mut input_index: BTreeMap<ValueId, usize> = BTreeMap::new();
    let mut functions: Vec<(String, String)> = Vec::new(); // (signature key, code)
    let mut calls = String::new();
    let mut params = Vec::new();
    let mut outputs = Vec::new();
    let mut stores = String::new();
    let mut imports: Vec<String> = Vec::new();
    let mut uses_clock = false;

    for (j, &(n, escapes)) in members.iter().enumerate() {
        let inst = &g.nodes[n];
        let Lowering::Pointwise(body) = inst.node().lowering() else {
            unreachable!("members are pointwise")
        };
        let mut sig = String::new();
        for p in &inst.input_ports {
            write!(sig, "{}: f32, ", p.name).unwrap();
        }
        sig.push_str("idx: u32, comp: u32, step: u32");
        for i in &body.imports {
            if !imports.contains(i) {
                imports.push(i.clone());
            }
        }
        uses_clock |= body.uses_step;
        for k in 0..body.params.len() {
            write!(sig, ", p{k}: f32").unwrap();
        }
        let key = format!("{sig}|{}", body.body);
        let fid = match functions.iter().position(|(k, _)| *k == key) {
            Some(f) => f,
            None => {
                let code = format!(
                    "fn f{}({sig}) -> f32 {{\n    {}\n}}\n",
                    functions.len(),
                    body.body.trim()
                );
                functions.push((key, code));
                functions.len() - 1
            }
        };
        let mut args = Vec::new();
        for src in &inst.inputs {
            args.push(match local.get(src) {
                Some(&l) => format!("v{l}"),
                None => match get(*src) {
                    // An absent optional input reads as 0.
                    None => "0.0".to_string(),
                    Some(v) => {
                        let next = inputs.len();
                        let b = *input_index.entry(v).or_insert_with(|| {
                            inputs.push(v);
                            next
                        });
                        let words = values[v].ty.words();
                        if words == 1 && len != 1 {
                            format!("in{b}[0]")
                        } else if words < len {
                            // A one-column particle array broadcast over the columns
                            // (nodes/pointwise.rs `row_broadcast`).
                            format!("in{b}[idx / {}u]", len / words)
                        } else {
                            format!("in{b}[idx]")
                        }
                    }
                },
            });
        }
        args.push("idx".into());
        args.push(comp_expr(&values[member_outputs[j]].ty));
        args.push("step".into());
        for k in 0..body.params.len() {
            args.push(format!("prm[{}]", params.len() + k));
        }
        params.extend_from_slice(&body.params);
        writeln!(calls, "    let v{j} = f{fid}({});", args.join(", ")).unwrap();
        if escapes {
            writeln!(stores, "    out{}[idx] = v{j};", outputs.len()).unwrap();
            outputs.push(member_outputs[j]);
        }
    }

    let mut src =
        String::from("// Generated by mesoflow's fusion pass.\n#import common/index.wgsl\n");
    for i in &imports {
        writeln!(src, "#import {i}").unwrap();
    }
    writeln!(src, "\nconst LEN: u32 = {len}u;").unwrap();
    src.push_str("@group(0) @binding(0) var<storage, read> prm: array<f32>;\n");
    // Bindings: params, [clock], inputs, outputs.
    let first_input = if uses_clock { 2 } else { 1 };
    if uses_clock {
        src.push_str("@group(0) @binding(1) var<storage, read> clock: array<u32>;\n");
    }
    for b in 0..inputs.len() {
        writeln!(
            src,
            "@group(0) @binding({}) var<storage, read> in{b}: array<f32>;",
            first_input + b
        )
        .unwrap();
    }
    for b in 0..outputs.len() {
        writeln!(
            src,
            "@group(0) @binding({}) var<storage, read_write> out{b}: array<f32>;",
            first_input + inputs.len() + b
        )
        .unwrap();
    }
    src.push('\n');
    for (_, code) in &functions {
        src.push_str(code);
    }
    writeln!(
        src,
        "\n@compute @workgroup_size({WG_1D})\nfn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,\n        @builtin(local_invocation_index) lid: u32) {{\n    let idx = flat_index(wid, nwg, lid, {WG_1D}u);\n    if (idx >= LEN) {{ return; }}"
    )
    .unwrap();
    if uses_clock {
        src.push_str("    let step = clock[0];\n");
    } else {
        src.push_str("    let step = 0u;\n");
    }
    src.push_str(&calls);
    src.push_str(&stores);
    src.push_str("}\n");
    let source = crate::gpu::shaders::resolve(&src)
        .unwrap_or_else(|e| panic!("a pointwise kind imports a shader that is not embedded: {e}"));
    FusedKernel {
        nodes: members.iter().map(|m| m.0).collect(),
        source,
        inputs,
        outputs,
        params,
        len,
        uses_clock,
    }
}
