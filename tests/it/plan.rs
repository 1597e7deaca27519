//! The planner without a GPU: pruning, fusion groups, memory reuse, errors.

use std::collections::BTreeMap;

use mesoflow::gpu::DeviceCaps;
use mesoflow::plan::{self, BufferRole, Launch, Plan, PlanOptions, Storage, Via};
use mesoflow::value::ValueType;

use crate::util::probe::load_probe_graph;
use crate::util::{load, plan_graph, root, tmpdir, write_graph};

fn plan_file(
    path: &std::path::Path,
    outputs: Option<&[&str]>,
    fuse: bool,
) -> (mesoflow::graph::Graph, Plan) {
    let g = load(path);
    let inputs = g.declared_input_types();
    let p = plan_graph(&DeviceCaps::baseline(), &g, inputs, outputs, fuse);
    (g, p)
}

fn node_ids(g: &mesoflow::graph::Graph, p: &Plan) -> Vec<String> {
    p.launches()
        .flat_map(|(_, l)| l.nodes())
        .map(|n| g.nodes[n].id.clone())
        .collect()
}

#[test]
fn only_what_requested_outputs_need_runs() {
    let path = root().join("graphs/fixtures/branches.json");
    let (g, p) = plan_file(&path, Some(&["a"]), false);
    assert_eq!(node_ids(&g, &p), vec!["a1", "a2"]);
    let pruned: Vec<&str> = p.pruned.iter().map(|&n| g.nodes[n].id.as_str()).collect();
    assert_eq!(pruned, vec!["b1", "b2"]);
    let (g, p) = plan_file(&path, Some(&["b"]), false);
    assert_eq!(node_ids(&g, &p), vec!["b1", "b2"]);
    let (_, p) = plan_file(&path, None, false);
    assert!(p.pruned.is_empty());
}

#[test]
fn unknown_output_is_a_plan_error() {
    let g = load(&root().join("graphs/fixtures/branches.json"));
    let opts = PlanOptions {
        outputs: Some(vec!["c".into()]),
        inputs: g.declared_input_types(),
        fuse: true,
        in_place: true,
    };
    let e = plan::plan(&g, &opts, &DeviceCaps::baseline())
        .unwrap_err()
        .to_string();
    assert!(e.contains("unknown output `c` (outputs: a, b)"), "{e}");
}

#[test]
fn a_chain_fuses_into_one_kernel_and_keeps_intermediates_in_registers() {
    let dir = tmpdir("plan-chain");
    let path = write_graph(&dir, "chain.json", &crate::util::chain_graph(5));
    let (_, fused) = plan_file(&path, None, true);
    assert_eq!(fused.step.len(), 1);
    let Launch::Fused(k) = &fused.step[0] else {
        panic!("expected a fused launch")
    };
    assert_eq!(k.nodes.len(), 5);
    assert_eq!(k.outputs.len(), 1, "only the chain's end is stored");
    let registers = fused
        .values
        .iter()
        .filter(|v| v.storage == Storage::Register)
        .count();
    assert_eq!(registers, 4);
    let (_, unfused) = plan_file(&path, None, false);
    assert_eq!(unfused.step.len(), 5);
}

#[test]
fn pooled_buffers_are_reused_along_a_chain() {
    let dir = tmpdir("plan-reuse");
    let path = write_graph(&dir, "chain.json", &crate::util::chain_graph(6));
    let (_, p) = plan_file(&path, None, false);
    // Five intermediate values, at most two alive at once: two pooled buffers.
    let pool: Vec<_> = p
        .buffers
        .iter()
        .filter(|b| b.role == BufferRole::Pool)
        .collect();
    assert_eq!(pool.len(), 2, "{:?}", p.buffers);
    assert_eq!(p.memory.pool_without_reuse, 5 * pool[0].bytes);
    // No launch reads and writes the same buffer (no node here writes in place).
    assert!(p.in_place.is_empty());
    assert_shares_only_in_place(&p);
}

/// Every launch, loop bodies' included, reads and writes one buffer only where the plan
/// put an output in place of that input (`Plan::in_place`).
fn assert_shares_only_in_place(p: &Plan) {
    fn check(p: &Plan, launches: &[Launch]) {
        for l in launches {
            // A loop reads values made before it, which live through it: its own
            // launches are checked one by one.
            if let Launch::Loop { body, .. } = l {
                check(p, body);
                continue;
            }
            for r in l.reads() {
                for w in l.writes() {
                    if let (Storage::Buffer(a), Storage::Buffer(b)) =
                        (p.values[r].storage, p.values[w].storage)
                        && a == b
                    {
                        assert!(
                            p.in_place.iter().any(|x| x.input == r && x.output == w),
                            "a launch reads {} and writes {} in buffer {a}, not in place",
                            p.values[r].name,
                            p.values[w].name
                        );
                    }
                }
            }
        }
    }
    check(p, &p.prologue);
    check(p, &p.step);
}

/// The plan's in-place outputs as (node id, input value, output value).
fn in_place_names(g: &mesoflow::graph::Graph, p: &Plan) -> Vec<(String, String, String)> {
    p.in_place
        .iter()
        .map(|a| {
            (
                g.nodes[a.node].id.clone(),
                p.values[a.input].name.clone(),
                p.values[a.output].name.clone(),
            )
        })
        .collect()
}

/// The storage of the plan's value named `name` (of the step: the prologue's come first).
fn storage_of(p: &Plan, name: &str) -> Storage {
    p.values
        .iter()
        .rev()
        .find(|v| v.name == name)
        .unwrap_or_else(|| panic!("no value {name}"))
        .storage
}

/// The storage of a state's buffer in a step: its current or its next value.
fn state_storage(p: &Plan, name: &str, next: bool) -> Storage {
    Storage::State {
        state: p.states.iter().position(|s| s.name == name).unwrap(),
        next,
    }
}

fn names(list: &[(&str, &str, &str)]) -> Vec<(String, String, String)> {
    list.iter()
        .map(|(n, i, o)| (n.to_string(), i.to_string(), o.to_string()))
        .collect()
}

/// bd_delaunay.json and abp_delaunay.json: in both flip loops `edge_flip_round` writes the
/// mesh into the buffer of the loop's `current` (read by nothing after it), so neither it
/// nor `repeat` copies the mesh per iteration; every loop ends where its value lies (its
/// `current` read by nothing after it), and the overlap and settle loops start where
/// theirs lies (the move's positions, the flip loop's mesh, each read last by the loop):
/// the mesh lives in the state's next buffer from the flip loop's start to the step's end,
/// copied once a step (the flip loop starts from the state, which a halted step must keep
/// as it was); `inspect` says so. Without in place (`PlanOptions::in_place` off) every
/// value has a buffer of its own and the pool holds two meshes more.
#[test]
fn the_flip_loops_write_the_mesh_in_place() {
    for (name, moved) in [
        ("bd_delaunay.json", "move.out"),
        ("abp_delaunay.json", "propel.out"),
    ] {
        let g = load(&root().join("graphs").join(name));
        let plan_with = |in_place: bool| {
            let opts = PlanOptions {
                outputs: None,
                inputs: g.declared_input_types(),
                fuse: true,
                in_place,
            };
            plan::plan(&g, &opts, &DeviceCaps::baseline()).unwrap_or_else(|e| panic!("{e}"))
        };
        let p = plan_with(true);
        assert_eq!(
            in_place_names(&g, &p),
            names(&[
                ("flip", "flips.current", "flip.mesh"),
                ("flips", "flips.current", "flips.out"),
                ("overlaps", moved, "overlaps.current"),
                ("overlaps", "overlaps.current", "overlaps.out"),
                ("settle", "flips.out", "settle.current"),
                ("reflip", "settle.current", "reflip.mesh"),
                ("settle", "settle.current", "settle.out"),
            ]),
            "{name}"
        );
        let vias: Vec<Via> = p.in_place.iter().map(|a| a.via).collect();
        assert_eq!(
            vias,
            [
                Via::Node,
                Via::Finish,
                Via::Start,
                Via::Finish,
                Via::Start,
                Via::Node,
                Via::Finish
            ],
            "{name}"
        );
        assert_shares_only_in_place(&p);
        // Each loop's `next` (input 1) is its `current` (output 1): `repeat` skips its copy.
        let mut loops = 0;
        for l in &p.step {
            if let Launch::Loop {
                inputs, outputs, ..
            } = l
                && inputs[1].is_some_and(|n| p.values[n].name.ends_with(".mesh"))
            {
                assert_eq!(
                    p.values[inputs[1].unwrap()].storage,
                    p.values[outputs[1]].storage,
                    "{name}"
                );
                loops += 1;
            }
        }
        assert_eq!(loops, 2, "{name}");
        // Every mesh of the loops in the state's next buffer, the positions too from the
        // move on; the state's current buffers only read.
        let mesh = state_storage(&p, "mesh", true);
        let x = state_storage(&p, "x", true);
        for v in [
            "flips.current",
            "flip.mesh",
            "flips.out",
            "settle.current",
            "reflip.mesh",
            "settle.out",
        ] {
            assert_eq!(storage_of(&p, v), mesh, "{name}: {v}");
        }
        for v in [moved, "overlaps.current", "overlaps.out"] {
            assert_eq!(storage_of(&p, v), x, "{name}: {v}");
        }
        let text = plan::to_text(&g, &p);
        for want in [
            "note   in place: flip.mesh is written into the buffer of flips.current",
            "note   flip.mesh shares the buffer of flips.current",
            "note   reflip.mesh shares the buffer of settle.current",
            "note   in place: flips.out is flips.current where it lies (state mesh next), no copy at the finish",
            "note   in place: settle.current starts in the buffer of flips.out (state mesh next), no copy at the start",
            "note   in place: settle.out is settle.current where it lies (state mesh next), no copy at the finish",
        ] {
            assert!(text.contains(want), "{name}: no `{want}` in\n{text}");
        }
        assert!(!text.contains("flips.current starts"), "{name}: {text}");
        let copied = plan_with(false);
        assert!(copied.in_place.is_empty(), "{name}");
        assert_shares_only_in_place(&copied);
        let mesh = p.values[p.in_place[0].output].ty.bytes();
        assert!(
            copied.memory.pool >= p.memory.pool + 2 * mesh,
            "{name}: pool {} in place, {} copied",
            p.memory.pool,
            copied.memory.pool
        );
        assert!(!plan::to_text(&g, &copied).contains("in place"), "{name}");
    }
}

/// With the test kinds `countdown` and `countdown_in_place` (out in place of x): the last
/// reader of a pooled value takes its buffer and an earlier reader does not; a graph
/// input, a requested output and, in a loop body, a value from outside the loop (read
/// again the next iteration) or one the body reads after the node keep buffers of their
/// own.
#[test]
fn in_place_outputs_take_only_buffers_no_one_reads_after() {
    let dir = tmpdir("plan-in-place");
    let g = load_probe_graph(
        &dir,
        "g.json",
        r#"{"mesoflow": 1,
 "inputs": {"x": {"type": "particles", "rows": 4, "cols": 1}},
 "nodes": [
   {"id": "a", "kind": "countdown", "inputs": {"x": "inputs.x"}},
   {"id": "b", "kind": "countdown_in_place", "inputs": {"x": "a.out"}},
   {"id": "c", "kind": "countdown_in_place", "inputs": {"x": "a.out", "y": "b.out"}},
   {"id": "d", "kind": "countdown_in_place", "inputs": {"x": "c.out"}},
   {"id": "e", "kind": "countdown_in_place", "inputs": {"x": "inputs.x"}},
   {"id": "loop", "kind": "repeat", "params": {"fixed": 2}, "inputs": {"initial": "d.out", "next": "h.out"}},
   {"id": "g", "kind": "countdown", "inputs": {"x": "inputs.x"}},
   {"id": "h", "kind": "countdown_in_place", "inputs": {"x": "g.out", "y": "loop.current"}},
   {"id": "k", "kind": "countdown_in_place", "inputs": {"x": "loop.out"}}
 ],
 "outputs": {"e": "e.out", "k": "k.out", "d": "d.count"}}"#,
    );
    let inputs: BTreeMap<_, _> = [("x".to_string(), ValueType::Particles { n: 4, k: 1 })].into();
    let p = plan_graph(&DeviceCaps::baseline(), &g, inputs, None, true);
    // b reads a.out before c does: only c takes it; d (the last reader of c.out) takes c's
    // buffer; e reads a graph input, k writes a requested output, h a value made before
    // the loop. The loop (d.out's last reader) starts in d.out's buffer and ends in it.
    assert_eq!(
        in_place_names(&g, &p),
        names(&[
            ("c", "a.out", "c.out"),
            ("d", "c.out", "d.out"),
            ("loop", "d.out", "loop.current"),
            ("loop", "loop.current", "loop.out")
        ])
    );
    assert_shares_only_in_place(&p);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Loops start where their initial value lies only where it is a pooled value the loop
/// reads last, through `initial` only: not a value read after the loop (l1), a state
/// (l2: a step the `halt` check stops keeps its state), a graph input (l3) or a value
/// the body reads too (l4); c.out, read by l5 only, is where l5 starts. Every loop ends
/// where its value lies, `current` read by nothing after it: in a pooled buffer, in the
/// state's next buffer (l2, whose `out` is the state's next value) or in a requested
/// output's (l5, with c.out and its body's values). Off, nothing shares.
#[test]
fn loops_start_and_end_where_their_values_lie_only_where_nothing_reads_after() {
    let dir = tmpdir("plan-loop-in-place");
    let g = load_probe_graph(
        &dir,
        "g.json",
        r#"{"mesoflow": 1,
 "inputs": {"x": {"type": "particles", "rows": 4, "cols": 1}},
 "state": {"s": {"init": "inputs.x", "next": "l2.out"}},
 "nodes": [
   {"id": "a", "kind": "countdown", "inputs": {"x": "state.s"}},
   {"id": "l1", "kind": "repeat", "params": {"fixed": 2}, "inputs": {"initial": "a.out", "next": "t1.out"}},
   {"id": "t1", "kind": "countdown", "inputs": {"x": "l1.current"}},
   {"id": "r", "kind": "countdown", "inputs": {"x": "a.out", "y": "l1.out"}},
   {"id": "l2", "kind": "repeat", "params": {"fixed": 2}, "inputs": {"initial": "state.s", "next": "t2.out"}},
   {"id": "t2", "kind": "countdown", "inputs": {"x": "l2.current", "y": "r.out"}},
   {"id": "l3", "kind": "repeat", "params": {"fixed": 2}, "inputs": {"initial": "inputs.x", "next": "t3.out"}},
   {"id": "t3", "kind": "countdown", "inputs": {"x": "l3.current"}},
   {"id": "b", "kind": "countdown", "inputs": {"x": "l3.out"}},
   {"id": "l4", "kind": "repeat", "params": {"fixed": 2}, "inputs": {"initial": "b.out", "next": "t4.out"}},
   {"id": "t4", "kind": "countdown", "inputs": {"x": "l4.current", "y": "b.out"}},
   {"id": "c", "kind": "countdown", "inputs": {"x": "l4.out"}},
   {"id": "l5", "kind": "repeat", "params": {"fixed": 2}, "inputs": {"initial": "c.out", "next": "t5.out"}},
   {"id": "t5", "kind": "countdown_in_place", "inputs": {"x": "l5.current"}}
 ],
 "outputs": {"s": "state.s", "l5": "l5.out"}}"#,
    );
    let inputs: BTreeMap<_, _> = [("x".to_string(), ValueType::Particles { n: 4, k: 1 })].into();
    let p = plan_graph(&DeviceCaps::baseline(), &g, inputs.clone(), None, true);
    let mut got: Vec<(String, String, String, Via)> = p
        .in_place
        .iter()
        .map(|a| {
            (
                g.nodes[a.node].id.clone(),
                p.values[a.input].name.clone(),
                p.values[a.output].name.clone(),
                a.via,
            )
        })
        .collect();
    got.sort_by(|a, b| (&a.0, &a.1).cmp(&(&b.0, &b.1)));
    let want: Vec<(String, String, String, Via)> = [
        ("l1", "l1.current", "l1.out", Via::Finish),
        ("l2", "l2.current", "l2.out", Via::Finish),
        ("l3", "l3.current", "l3.out", Via::Finish),
        ("l4", "l4.current", "l4.out", Via::Finish),
        ("l5", "c.out", "l5.current", Via::Start),
        ("l5", "l5.current", "l5.out", Via::Finish),
        ("t5", "l5.current", "t5.out", Via::Node),
    ]
    .iter()
    .map(|(n, i, o, v)| (n.to_string(), i.to_string(), o.to_string(), *v))
    .collect();
    assert_eq!(got, want);
    assert_shares_only_in_place(&p);
    // l2 runs in the state's next buffer; the state's current is read only.
    let next = state_storage(&p, "s", true);
    for v in ["l2.current", "t2.out", "l2.out"] {
        assert_eq!(storage_of(&p, v) == next, v != "t2.out", "{v}");
    }
    // l5 and the values it starts from live in the output's buffer.
    let Storage::Buffer(out) = storage_of(&p, "l5.out") else {
        panic!("l5.out has no buffer")
    };
    assert_eq!(p.buffers[out].role, BufferRole::Output);
    for v in ["c.out", "l5.current", "t5.out"] {
        assert_eq!(storage_of(&p, v), Storage::Buffer(out), "{v}");
    }
    for v in ["a.out", "l1.current", "b.out", "l4.current", "l3.current"] {
        assert_ne!(storage_of(&p, v), Storage::Buffer(out), "{v}");
        assert_ne!(storage_of(&p, v), next, "{v}");
    }
    let text = plan::to_text(&g, &p);
    for want in [
        "note   in place: l5.current starts in the buffer of c.out",
        "note   in place: l2.out is l2.current where it lies (state s next), no copy at the finish",
        "l5.current (in place)",
    ] {
        assert!(text.contains(want), "no `{want}` in\n{text}");
    }
    let copied = plan_graph_in_place(&g, inputs, false);
    assert!(copied.in_place.is_empty());
    assert_shares_only_in_place(&copied);
    assert!(!plan::to_text(&g, &copied).contains("in place"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A plan with or without in-place outputs, on the baseline capabilities.
fn plan_graph_in_place(
    g: &mesoflow::graph::Graph,
    inputs: BTreeMap<String, ValueType>,
    in_place: bool,
) -> Plan {
    let opts = PlanOptions {
        outputs: None,
        inputs,
        fuse: true,
        in_place,
    };
    plan::plan(g, &opts, &DeviceCaps::baseline()).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn fusion_respects_paths_through_other_launches() {
    // b = scale(a); m = multiply(a, c) where c is a broadcast scalar computed from
    // nothing in the group; a diamond a -> (b, c) -> d fuses whole.
    let dir = tmpdir("plan-diamond");
    let path = write_graph(
        &dir,
        "diamond.json",
        r#"{"mesoflow": 1, "inputs": {"x": {"type": "particles", "rows": 10, "cols": 3}},
         "nodes": [
           {"id": "a", "kind": "scale", "params": {"factor": 2}, "inputs": {"x": "inputs.x"}},
           {"id": "b", "kind": "scale", "params": {"factor": 3}, "inputs": {"x": "a.out"}},
           {"id": "c", "kind": "affine", "params": {"offset": 1}, "inputs": {"x": "a.out"}},
           {"id": "d", "kind": "multiply", "inputs": {"a": "b.out", "b": "c.out"}}
         ],
         "outputs": {"d": "d.out", "a": "a.out"}}"#,
    );
    let (g, p) = plan_file(&path, None, true);
    assert_eq!(p.step.len(), 1);
    let Launch::Fused(k) = &p.step[0] else {
        panic!()
    };
    let ids: Vec<&str> = k.nodes.iter().map(|&n| g.nodes[n].id.as_str()).collect();
    assert_eq!(ids, vec!["a", "b", "c", "d"]);
    assert_eq!(k.outputs.len(), 2, "a (an output) and d are stored");
}

#[test]
fn absent_optional_inputs_drop_the_nodes_that_need_them() {
    let dir = tmpdir("plan-absent");
    let path = write_graph(
        &dir,
        "opt.json",
        r#"{"mesoflow": 1,
         "inputs": {"x": {"type": "particles", "cols": 3}, "extra": {"type": "particles", "cols": 3, "optional": true}},
         "nodes": [
           {"id": "e", "kind": "scale", "params": {"factor": 2}, "inputs": {"x": "inputs.extra"}},
           {"id": "sum", "kind": "add", "inputs": {"a": "inputs.x", "b": "e.out"}}
         ],
         "outputs": {"sum": "sum.out", "e": "e.out"}}"#,
    );
    let g = load(&path);
    let x = ValueType::Particles { n: 4, k: 3 };
    let only_x: BTreeMap<String, ValueType> = [("x".to_string(), x)].into_iter().collect();
    let p = plan::plan(
        &g,
        &PlanOptions {
            outputs: Some(vec!["sum".into()]),
            inputs: only_x.clone(),
            fuse: true,
            in_place: true,
        },
        &DeviceCaps::baseline(),
    )
    .unwrap();
    // The scale of the absent input drops out, and the sum without its optional term
    // is read through: the output is the input itself, no work at all.
    assert!(node_ids(&g, &p).is_empty(), "{:?}", node_ids(&g, &p));
    let forwarded: Vec<&str> = p
        .forwarded
        .iter()
        .map(|&n| g.nodes[n].id.as_str())
        .collect();
    assert_eq!(forwarded, vec!["sum"]);
    assert!(!p.pruned.iter().any(|&n| g.nodes[n].id == "sum"));
    let text = mesoflow::plan::to_text(&g, &p);
    assert!(
        text.contains("read through") && text.contains("sum <- inputs.x"),
        "{text}"
    );
    let e = plan::plan(
        &g,
        &PlanOptions {
            outputs: None,
            inputs: only_x,
            fuse: true,
            in_place: true,
        },
        &DeviceCaps::baseline(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("output `e` cannot be computed") && e.contains("extra"),
        "{e}"
    );
}

#[test]
fn inputs_sharing_a_size_must_agree() {
    let g = load(&root().join("graphs/fixtures/pointwise_all.json"));
    let mut inputs = g.declared_input_types();
    inputs.insert("y".into(), ValueType::Particles { n: 36, k: 3 });
    let e = plan::plan(
        &g,
        &PlanOptions {
            outputs: None,
            inputs,
            fuse: true,
            in_place: true,
        },
        &DeviceCaps::baseline(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("input `y` has 36 rows but input `x` has 37; both are declared with rows `n`"),
        "{e}"
    );
}

#[test]
fn values_larger_than_a_binding_are_plan_errors() {
    let g = load(&root().join("graphs/fixtures/branches.json"));
    let inputs = [(
        "x".to_string(),
        ValueType::Particles {
            n: 20_000_000,
            k: 3,
        },
    )]
    .into_iter()
    .collect();
    let caps = DeviceCaps {
        max_binding: 128 << 20,
        ..DeviceCaps::baseline()
    };
    let e = plan::plan(
        &g,
        &PlanOptions {
            outputs: None,
            inputs,
            fuse: true,
            in_place: true,
        },
        &caps,
    )
    .unwrap_err()
    .to_string();
    // The input itself is refused, by name, before any node meets it.
    assert!(
        e.contains("input `x` is particles(20000000x3), 240000000 bytes")
            && e.contains("more than this device binds in one buffer (134217728 bytes"),
        "{e}"
    );
    // A node output past the limit is refused at its port.
    let dir = tmpdir("plan-output-limit");
    let g = load(&write_graph(
        &dir,
        "big.json",
        r#"{"mesoflow": 1,
            "nodes": [{"id": "c", "kind": "constant", "params": {"value": 1, "rows": 40000000}}],
            "outputs": {"c": "c.out"}}"#,
    ));
    let e = plan::plan(
        &g,
        &PlanOptions {
            outputs: None,
            inputs: BTreeMap::new(),
            fuse: true,
            in_place: true,
        },
        &caps,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("node `c`, port `out`: output particles(40000000x1) takes 160000000 bytes"),
        "{e}"
    );
}

#[test]
fn states_swap_buffers_and_outputs_read_the_final_state() {
    let (_, p) = plan_file(&root().join("graphs/examples/relax.json"), None, true);
    assert_eq!(p.states.len(), 1);
    // The step writes the next state in place (no copy) and the output is the final state.
    assert!(p.step.iter().all(|l| !matches!(l, Launch::Copy { .. })));
    let (_, v) = p.outputs.iter().find(|(n, _)| n == "positions").unwrap();
    assert_eq!(
        p.values[*v].storage,
        Storage::State {
            state: 0,
            next: true
        }
    );
    let text = plan::to_text(&load(&root().join("graphs/examples/relax.json")), &p);
    assert!(text.contains("fused x2"), "{text}");
    let dot = plan::to_dot(&load(&root().join("graphs/examples/relax.json")), &p);
    assert!(
        dot.starts_with("digraph") && dot.contains("cluster_"),
        "{dot}"
    );
}

/// A graph reducing an input of any length to one number per column.
const REDUCE_INPUT: &str = r#"{"mesoflow": 1,
    "inputs": {"x": {"type": "particles", "cols": 3}},
    "nodes": [{"id": "total", "kind": "sum", "inputs": {"x": "inputs.x"}}],
    "outputs": {"total": "total.out"}}"#;

#[test]
fn an_input_larger_than_the_device_binds_is_refused_by_name() {
    let dir = tmpdir("plan-input-limit");
    let g = load(&write_graph(&dir, "sum.json", REDUCE_INPUT));
    let caps = DeviceCaps {
        max_binding: 1024,
        ..DeviceCaps::baseline()
    };
    let plan_for = |n: u32| {
        let opts = PlanOptions {
            outputs: None,
            inputs: [("x".to_string(), ValueType::Particles { n, k: 3 })].into(),
            fuse: true,
            in_place: true,
        };
        plan::plan(&g, &opts, &caps)
    };
    // 85 rows of 3 floats: 1020 bytes, bound whole; 86 rows: 1032.
    assert!(plan_for(85).is_ok());
    let e = plan_for(86).unwrap_err().to_string();
    assert!(
        e.contains("input `x`") && e.contains("1032 bytes") && e.contains("1024"),
        "{e}"
    );
}

/// The problems planning `outputs` of a loaded graph with these inputs reports, or none.
fn plan_problems(
    g: &mesoflow::graph::Graph,
    inputs: BTreeMap<String, ValueType>,
    outputs: &[&str],
) -> Option<String> {
    let caps = DeviceCaps {
        max_binding: u64::MAX,
        max_buffer: u64::MAX,
        ..DeviceCaps::baseline()
    };
    let opts = PlanOptions {
        outputs: Some(outputs.iter().map(|s| s.to_string()).collect()),
        inputs,
        fuse: true,
        in_place: true,
    };
    plan::plan(g, &opts, &caps).err().map(|e| e.to_string())
}

/// A node's param values are checked where the node runs: a graph with a node whose op
/// its kind refuses loads, plans every output that does not need that node, and names
/// node and param when an output does. Before, loading refused the file.
#[test]
fn param_values_are_checked_only_where_the_node_runs() {
    let dir = tmpdir("plan-unused-params");
    let path = write_graph(
        &dir,
        "unused.json",
        r#"{"mesoflow": 1,
          "inputs": {"x": {"type": "particles", "cols": 3}},
          "nodes": [
            {"id": "s", "kind": "scale", "params": {"factor": 2}, "inputs": {"x": "inputs.x"}},
            {"id": "r", "kind": "column_reduce", "params": {"op": "average"}, "inputs": {"x": "s.out"}}
          ],
          "outputs": {"y": "s.out", "z": "r.out"}}"#,
    );
    let g = load(&path);
    assert_eq!(plan_problems(&g, g.declared_input_types(), &["y"]), None);
    let e = plan_problems(&g, g.declared_input_types(), &["y", "z"]).expect("z needs r");
    assert!(
        e.contains("node `r`: param `op`: bad value") && e.contains("average"),
        "{e}"
    );
    assert!(!e.contains("node `s`"), "{e}");
    // `validate` agrees: the file is valid, with a note on `z`.
    let v = mesoflow::plan::validate_file(crate::util::registry(), &path).unwrap();
    assert!(
        v.notes.len() == 1 && v.notes[0].contains("output `z`") && v.notes[0].contains("`op`"),
        "{v}"
    );
}

/// The issue's cases: PSE in a box of 4 at 1e-4, whose fcm.json torque path (never run:
/// PSE gives no torques) gets a torque support of 96 cells, past the spreading's 32, loads
/// and plans; fcm.json at L = 64 plans its velocities with its declared inputs (the
/// optional torques absent, as in a run), and with 4 particles given, the absent optional
/// torques do not take the size's default of 1000 rows.
#[test]
fn nodes_the_plan_does_not_run_never_reject_it() {
    let g = crate::util::load_with(
        "pse.json",
        &[("box", "[4, 4, 4]"), ("tolerance", "1e-4")],
        1,
        0,
    );
    assert_eq!(
        plan_problems(&g, g.declared_input_types(), &["velocities"]),
        None
    );
    let g = crate::util::load_with("fcm.json", &[("box", "[64, 64, 64]")], 1, 0);
    assert!(!g.declared_input_types().contains_key("torques"));
    assert_eq!(
        plan_problems(&g, g.declared_input_types(), &["velocities", "noise"]),
        None
    );
    // The torque path where torques are given: its guard names the nodes.
    let e = plan_problems(&g, g.declared_input_types_with_optional(), &["velocities"])
        .expect("torques need rotation");
    assert!(e.contains("spread_torques"), "{e}");
    let four = ValueType::Particles { n: 4, k: 3 };
    let given: BTreeMap<String, ValueType> = [("positions".to_string(), four)].into();
    let assumed = g.assumed_input_types(&given, &[]);
    assert_eq!(assumed.get("forces"), Some(&four));
    assert!(!assumed.contains_key("torques"));
    assert_eq!(plan_problems(&g, assumed, &["velocities"]), None);
    let with = g.assumed_input_types(&given, &["torques"]);
    assert_eq!(with.get("torques"), Some(&four));
}

/// The problems of `graphs/<name>` with these `--set` values (JSON literals), whether
/// loading finds them or planning every output with the declared inputs does.
fn load_or_plan_problems(name: &str, sets: &[(&str, &str)]) -> String {
    let opts = mesoflow::graph::LoadOptions {
        overrides: sets
            .iter()
            .map(|(k, v)| {
                let json: serde_json::Value = serde_json::from_str(v).unwrap();
                (
                    k.to_string(),
                    mesoflow::expr::ParamValue::from_json(&json).unwrap(),
                )
            })
            .collect(),
        ..Default::default()
    };
    let path = root().join("graphs").join(name);
    let g = match mesoflow::graph::load(&path, crate::util::registry(), &opts) {
        Ok(g) => g,
        Err(e) => return e.to_string(),
    };
    let opts = PlanOptions {
        outputs: None,
        inputs: g.declared_input_types(),
        fuse: true,
        in_place: true,
    };
    match plan::plan(&g, &opts, &DeviceCaps::baseline()) {
        Ok(_) => panic!("{name} with {sets:?} planned"),
        Err(e) => e.to_string(),
    }
}

/// Params past what f32 carries (issue 19) are refused where a node's f32 arithmetic
/// stops being meaningful, and the message names the graph param the user set, also
/// through subgraphs and expressions (before: NaN or infinite outputs with exit 0, or a
/// derived value alone: `param support: 4294967295 is outside [0, 32]`).
#[test]
fn extreme_params_are_refused_naming_the_param_the_user_set() {
    // (graph, --set values, what the report must say)
    type Case<'a> = (&'a str, &'a [(&'a str, &'a str)], &'a [&'a str]);
    let cases: &[Case] = &[
        (
            "examples/relax.json",
            &[("dt", "1e308")],
            &[
                "node `move`: param `alpha`: bad value: 1e308 is outside [-1e18, 1e18]",
                "(from graph param `dt` = 1e308)",
            ],
        ),
        (
            "examples/relax.json",
            &[("stiffness", "1e30")],
            &[
                "node `force`: param `factor`: bad value: -1e30 is outside [-1e18, 1e18]",
                "(computed from `stiffness` = 1e30 via `-stiffness`)",
            ],
        ),
        (
            "fcm.json",
            &[("box", "[8, 8, 8]"), ("viscosity", "1e-300")],
            &[
                "node `flow`: param `viscosity`: bad value: 1e-300 is outside [1e-18, 1e18]",
                "(from graph param `viscosity` = 1e-300)",
            ],
        ),
        (
            // Within the param's range, but the mobility the kernel forms is not.
            "fcm.json",
            &[("box", "[8, 8, 8]"), ("viscosity", "1e-18")],
            &[
                "node `flow`: the mobility at the longest wavelength",
                "is outside [1e-18, 1e18] in magnitude",
                "(from graph param `box` = [8, 8, 8], `viscosity` = 1e-18)",
            ],
        ),
        (
            "fcm.json",
            &[("box", "[8, 8, 8]"), ("width", "1e-30")],
            &[
                // The worst-placement support search finds no support first.
                "fcm_support: the grid [12, 12, 12] is too coarse for FCM's Gaussian (sigma = 1e-30)",
                "`width` = 1e-30 via `fcm_support(",
            ],
        ),
        (
            // With the support given, the window's own coefficient check names `width`.
            "fcm.json",
            &[("box", "[8, 8, 8]"), ("width", "1e-30"), ("support", "8")],
            &[
                "node `spread_forces`: the Gaussian's exponent factor h^2 / (2 `width`^2) (h the cell size) = ",
                "(from graph param `width` = 1e-30)",
            ],
        ),
        (
            "fcm.json",
            &[("box", "[8, 8, 8]"), ("radius", "1e30")],
            &[
                "fcm_grid: a box side of 8 is shorter than the spheres' diameter 2a = 2e30",
                "(computed from `box` = [8, 8, 8], `radius` = 1e30 via `fcm_grid(",
            ],
        ),
        (
            "fcm.json",
            &[("box", "[1e-30, 1e-30, 1e-30]")],
            &[
                "shorter than the spheres' diameter 2a = 2",
                "(computed from `box` = [1e-30, 1e-30, 1e-30] via `fcm_grid(",
            ],
        ),
        (
            "fcm.json",
            &[("box", "[8, 8, 8]"), ("radius", "5e-324")],
            &[
                "fcm_grid: a box length of 8 for radius 5e-324 needs inf cells",
                "(computed from `box` = [8, 8, 8], `radius` = 5e-324 via `fcm_grid(",
            ],
        ),
        (
            // Through pse.json's inlined fcm.json: the user's param, not fcm.json's.
            "pse.json",
            &[("box", "[8, 8, 8]"), ("viscosity", "1e-300")],
            &[
                "fcm.json: node `far/flow`: param `viscosity`: bad value: 1e-300",
                "(from graph param `viscosity` = 1e-300)",
            ],
        ),
        (
            "pse.json",
            &[("box", "[8, 8, 8]"), ("radius", "5e-324")],
            &[
                "pse_split: the RPY near field at split inf, radius 5e-324",
                "(computed from `box` = [8, 8, 8], `radius` = 5e-324 via `pse_split(",
            ],
        ),
        (
            "rpy_open.json",
            &[("viscosity", "1e-300")],
            &[
                "param `viscosity`: bad value: 1e-300",
                "(from graph param `viscosity` = 1e-300)",
            ],
        ),
        (
            "rpy_open.json",
            &[("viscosity", "1e-17"), ("radius", "1e-17")],
            &[
                "1/(6 pi `viscosity` `radius`) = ",
                "(from graph param `radius` = 1e-17, `viscosity` = 1e-17)",
            ],
        ),
        (
            "bd_fcm.json",
            &[("box", "[8, 8, 8]"), ("dt", "1e308")],
            &[
                "node `move`: param `alpha`: bad value: 1e308",
                "(from graph param `dt` = 1e308)",
            ],
        ),
    ];
    for (name, sets, wanted) in cases {
        let e = load_or_plan_problems(name, sets);
        for w in *wanted {
            assert!(e.contains(w), "{name} {sets:?}: expected `{w}` in:\n{e}");
        }
        assert!(
            !e.contains("0000000000"),
            "{name} {sets:?}: numbers in full:\n{e}"
        );
    }
}

/// A node whose `enabled` is false or 0 (literal or `$param`), and every node inside a
/// disabled subgraph node, is left out: its readers see an absent optional input, and an
/// output that needs it is not computed, with the node and the reason named.
#[test]
fn disabled_nodes_are_left_out_with_the_reason() {
    let dir = tmpdir("disabled");
    let graph = |extra: &str| {
        format!(
            r#"{{"mesoflow": 1,
  "params": {{"on": {{"default": 0}}}},
  "sizes": {{"n": {{"default": 8}}}},
  "inputs": {{"x": {{"type": "particles", "rows": "n", "cols": 3}}}},
  "nodes": [
    {{"id": "a", "kind": "scale", "params": {{"factor": 2}}, "inputs": {{"x": "inputs.x"}}}},
    {{"id": "b", "kind": "scale", "enabled": "$on", "params": {{"factor": 3}}, "inputs": {{"x": "inputs.x"}}}},
    {{"id": "c", "kind": "add", "inputs": {{"a": "a.out", "b": "b.out"}}}}{extra}
  ],
  "outputs": {{"sum": "c.out", "tripled": "b.out"}}
}}"#
        )
    };
    let path = write_graph(&dir, "g.json", &graph(""));
    let (g, p) = plan_file(&path, Some(&["sum"]), false);
    assert_eq!(
        node_ids(&g, &p),
        vec!["a".to_string()],
        "b left out, c read through"
    );
    let g = load(&path);
    let err = plan::plan(
        &g,
        &PlanOptions {
            outputs: Some(vec!["tripled".into()]),
            inputs: g.declared_input_types(),
            fuse: false,
            in_place: true,
        },
        &DeviceCaps::baseline(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("`tripled`") && err.contains("node `b`") && err.contains("`enabled` is 0"),
        "{err}"
    );
    // A true `enabled` keeps the node; a string is a load error naming it.
    let on = write_graph(
        &dir,
        "on.json",
        &graph("").replace(r#""default": 0"#, r#""default": true"#),
    );
    let (g, p) = plan_file(&on, Some(&["tripled"]), false);
    assert_eq!(node_ids(&g, &p), vec!["b".to_string()]);
    let bad = write_graph(
        &dir,
        "bad.json",
        &graph("").replace(r#""default": 0"#, r#""default": "yes""#),
    );
    let err = match mesoflow::graph::load(&bad, crate::util::registry(), &Default::default()) {
        Ok(_) => panic!("a string `enabled` loaded"),
        Err(e) => e.to_string(),
    };
    assert!(err.contains("`enabled` must be true or false"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A state whose next value is itself (`"next": "state.k"`: a value kept unchanged) costs
/// no copy in the steps: the prologue writes its initial value into both of its buffers.
#[test]
fn a_state_kept_unchanged_is_copied_once_into_both_buffers() {
    let (_, p) = plan_file(&root().join("graphs/fixtures/kept_state.json"), None, true);
    assert!(p.step.iter().all(|l| !matches!(l, Launch::Copy { .. })));
    let k = p.states.iter().position(|s| s.name == "k").unwrap();
    let written: Vec<Storage> = p
        .prologue
        .iter()
        .filter_map(|l| match l {
            Launch::Copy { dst, .. } => Some(p.values[*dst].storage),
            _ => None,
        })
        .collect();
    for next in [false, true] {
        assert!(
            written.contains(&Storage::State { state: k, next }),
            "{written:?}"
        );
    }
}

/// The ids of the nodes of the step launches the plan runs on a run's last step only.
fn last_step_only(g: &mesoflow::graph::Graph, p: &Plan) -> Vec<String> {
    p.last_step_only
        .iter()
        .flat_map(|&i| p.step[i].nodes())
        .map(|n| g.nodes[n].id.clone())
        .collect()
}

/// Launches whose values only outputs read run on a run's last step only
/// (`Plan::last_step_only`): a scatter of the next state and a node reading only it; the
/// move (it writes the state), a record (a persistent output, fed through the scatter it
/// then needs every step) and an element-wise output fused with the move run every step;
/// in a graph without state, everything runs every step.
#[test]
fn launches_only_outputs_read_run_on_the_last_step_only() {
    let dir = tmpdir("plan-last-step");
    let graph = |record: bool| {
        format!(
            r#"{{"mesoflow": 1,
 "inputs": {{"x": {{"type": "particles", "rows": 8, "cols": 2}}, "index": {{"type": "indices", "rows": 8}}}},
 "state": {{"s": {{"init": "inputs.x", "next": "move.out"}}}},
 "nodes": [
   {{"id": "move", "kind": "affine", "params": {{"offset": 1}}, "inputs": {{"x": "state.s"}}}},
   {{"id": "tripled", "kind": "scale", "params": {{"factor": 3}}, "inputs": {{"x": "move.out"}}}},
   {{"id": "back", "kind": "scatter", "inputs": {{"values": "move.out", "index": "inputs.index"}}}},
   {{"id": "twice", "kind": "scale", "params": {{"factor": 2}}, "inputs": {{"x": "back.out"}}}},
   {{"id": "rec", "kind": "record", "enabled": {record}, "params": {{"frames": 4}}, "inputs": {{"x": "back.out"}}}}
 ],
 "outputs": {{"s": "state.s", "tripled": "tripled.out", "twice": "twice.out", "frames": "rec.out"}}}}"#
        )
    };
    let path = write_graph(&dir, "last.json", &graph(false));
    let (g, p) = plan_file(&path, Some(&["s", "tripled", "twice"]), false);
    assert_eq!(last_step_only(&g, &p), ["tripled", "back", "twice"]);
    assert_eq!(p.launches_every_step(), 1);
    let text = plan::to_text(&g, &p);
    assert!(
        text.contains("on the last step of a run only: only outputs read it")
            && text.contains("1 launches per step (and 3 on the last step of a run only)"),
        "{text}"
    );
    // Fused with the move, the tripled output is written every step.
    let (g, p) = plan_file(&path, Some(&["s", "tripled", "twice"]), true);
    assert_eq!(last_step_only(&g, &p), ["back", "twice"]);
    // Only the state asked for: nothing is for outputs alone.
    let (_, p) = plan_file(&path, Some(&["s"]), false);
    assert!(p.last_step_only.is_empty());
    // A record keeps the scatter it reads in every step; the scale after it is still for
    // the output alone.
    let path = write_graph(&dir, "recorded.json", &graph(true));
    let (g, p) = plan_file(&path, None, false);
    assert_eq!(last_step_only(&g, &p), ["tripled", "twice"]);
    // A graph that carries nothing from a step to the next (a mobility timed over many
    // steps) runs everything every step, though only outputs read it.
    let (_, p) = plan_file(&root().join("graphs/fixtures/branches.json"), None, false);
    assert!(!p.step.is_empty() && p.last_step_only.is_empty());
}
