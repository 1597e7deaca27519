//! The `repeat` node with a `fixed` count: a loop within a step, against f64 recurrences (the
//! body reading the loop's value and values from outside it, state carried across
//! steps), several values carried as columns, and its mistakes named. A loop until its
//! count is 0 runs its body exactly as many times as it reports, the iterations the
//! executor sends past the stop gated off, whatever the profile, and the same with its
//! body writing the carried value in place (`PortSpec::in_place_of`); a body node in
//! place of a value read after it is not given its buffer; a step its `halt` stops keeps
//! nothing, in place or not, the loop starting from the state or in its next buffer.

use std::collections::BTreeMap;

use mesoflow::exec::{Profile, Program, RunOptions};
use mesoflow::graph;
use mesoflow::plan::{Plan, Via};
use mesoflow::value::{HostArray, ValueType};

use crate::util::disks::run_with_loops_profiled;
use crate::util::probe::{Launches, probe_registry};
use crate::util::{
    compile_cached, f32s, gpu, load_or_plan_error, load_with_registry, particles, plan_graph,
    run_graph, tmpdir, types_of, u32s, write_graph,
};

/// x_(k+1) = alpha x_k + b, `count` times a step, the result kept as state; the body
/// also outputs what the loop left after one step's iterations (`once`).
fn affine_loop(count: &str) -> String {
    format!(
        r#"{{"mesoflow": 1,
 "params": {{"count": {{"default": {count}}}}},
 "inputs": {{"x": {{"type": "particles", "rows": 6, "cols": 2}}, "b": {{"type": "particles", "rows": 6, "cols": 2}}}},
 "state": {{"s": {{"init": "inputs.x", "next": "loop.out"}}}},
 "nodes": [
   {{"id": "loop", "kind": "repeat", "params": {{"fixed": "$count"}}, "inputs": {{"initial": "state.s", "next": "body.out"}}}},
   {{"id": "body", "kind": "axpy", "params": {{"alpha": -0.75}}, "inputs": {{"x": "loop.current", "y": "inputs.b"}}}}
 ],
 "outputs": {{"s": "state.s"}}}}"#
    )
}

#[test]
fn repeat_runs_its_body_count_times_a_step() {
    let Some(gpu) = gpu() else { return };
    let dir = tmpdir("repeat_affine");
    let x0: Vec<[f64; 2]> = (0..6).map(|i| [i as f64 - 2.5, 0.25 * i as f64]).collect();
    let b: Vec<[f64; 2]> = (0..6).map(|i| [1.0, -0.5 + 0.1 * i as f64]).collect();
    let inputs: BTreeMap<_, _> = [
        ("x".to_string(), particles(&x0)),
        ("b".to_string(), particles(&b)),
    ]
    .into();
    for (count, steps) in [(1u64, 1u64), (7, 1), (5, 3)] {
        let path = write_graph(
            &dir,
            &format!("loop{count}.json"),
            &affine_loop(&count.to_string()),
        );
        let g = crate::util::load_for(&path, steps, 0);
        let out = run_graph(&gpu, &g, &inputs, Some(&["s"]), steps, true);
        let got = f32s(&out["s"]);
        // The f64 recurrence: |alpha| < 1, so f32 rounding stays at its own size.
        let mut want = x0.clone();
        for _ in 0..count * steps {
            for (w, bi) in want.iter_mut().zip(&b) {
                for d in 0..2 {
                    w[d] = -0.75 * w[d] + bi[d];
                }
            }
        }
        for (i, w) in want.iter().flatten().enumerate() {
            assert!(
                (got[i] as f64 - w).abs() < 1e-6 * (1.0 + w.abs()),
                "count {count}, {steps} steps: [{i}] {} vs {w}",
                got[i]
            );
        }
    }
}

/// Two values carried together as columns: a harmonic oscillator by velocity Verlet,
/// (x, v) -> (x', v'), 10 substeps a step, against the same f64 recurrence.
#[test]
fn repeat_carries_several_values_as_columns() {
    let Some(gpu) = gpu() else { return };
    let dir = tmpdir("repeat_columns");
    let json = r#"{"mesoflow": 1,
 "inputs": {"xv": {"type": "particles", "rows": 4, "cols": 2}},
 "state": {"s": {"init": "inputs.xv", "next": "loop.out"}},
 "nodes": [
   {"id": "loop", "kind": "repeat", "params": {"fixed": 10}, "inputs": {"initial": "state.s", "next": "pack.out"}},
   {"id": "x", "kind": "columns", "params": {"first": 0, "count": 1}, "inputs": {"x": "loop.current"}},
   {"id": "v", "kind": "columns", "params": {"first": 1, "count": 1}, "inputs": {"x": "loop.current"}},
   {"id": "half", "kind": "axpy", "params": {"alpha": -0.05}, "inputs": {"x": "x.out", "y": "v.out"}},
   {"id": "drift", "kind": "axpy", "params": {"alpha": 0.1}, "inputs": {"x": "half.out", "y": "x.out"}},
   {"id": "kick", "kind": "axpy", "params": {"alpha": -0.05}, "inputs": {"x": "drift.out", "y": "half.out"}},
   {"id": "pack", "kind": "concat", "params": {"cols": 2}, "inputs": {"a": "drift.out", "b": "kick.out"}}
 ],
 "outputs": {"s": "state.s"}}"#;
    let path = write_graph(&dir, "verlet.json", json);
    let steps = 4;
    let g = crate::util::load_for(&path, steps, 0);
    let xv0: Vec<[f64; 2]> = (0..4)
        .map(|i| [1.0 - 0.5 * i as f64, 0.3 * i as f64])
        .collect();
    let inputs: BTreeMap<_, _> = [("xv".to_string(), particles(&xv0))].into();
    let got = f32s(&run_graph(&gpu, &g, &inputs, Some(&["s"]), steps, true)["s"]);
    for (i, p) in xv0.iter().enumerate() {
        let (mut x, mut v) = (p[0], p[1]);
        for _ in 0..10 * steps {
            v -= 0.05 * x;
            x += 0.1 * v;
            v -= 0.05 * x;
        }
        assert!(
            (got[2 * i] as f64 - x).abs() < 1e-5,
            "x[{i}] {} vs {x}",
            got[2 * i]
        );
        assert!(
            (got[2 * i + 1] as f64 - v).abs() < 1e-5,
            "v[{i}] {} vs {v}",
            got[2 * i + 1]
        );
    }
}

#[test]
fn repeat_mistakes_are_named() {
    let dir = tmpdir("repeat_mistakes");
    let cases = [
        (affine_loop("0"), "port `count`: is not connected"),
        (affine_loop("2.5"), "fixed"),
        (
            affine_loop("3").replace(
                r#""inputs": {"x": "loop.current", "y": "inputs.b"}"#,
                r#""inputs": {"x": "first.out", "y": "first.out"}}, {"id": "first", "kind": "columns", "params": {"first": 0, "count": 1}, "inputs": {"x": "loop.current"}"#,
            ),
            "port `next`",
        ),
    ];
    for (i, (json, want)) in cases.iter().enumerate() {
        let path = write_graph(&dir, &format!("bad{i}.json"), json);
        let err = load_or_plan_error(&path, BTreeMap::new())
            .unwrap_or_else(|| panic!("case {i} loaded and planned"));
        assert!(err.contains(want), "case {i}: {err}");
        assert!(
            err.contains("loop"),
            "case {i} does not name the node: {err}"
        );
    }
}

/// The plan's in-place outputs of a graph as (node id, input name, output name).
fn in_place_of(g: &graph::Graph, p: &Plan) -> Vec<(String, String, String)> {
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

/// A loop until its count is 0 around the `countdown` probe, and around
/// `countdown_in_place`, which the plan lets write `next` into `current`'s buffer (the
/// loop then copies nothing per iteration): the same results, and the body runs exactly
/// the iterations reported, whatever the profile (an iteration past the stop would
/// subtract 1 more in place).
#[test]
fn repeat_runs_its_body_only_for_the_iterations_it_reports() {
    let Some(gpu) = gpu() else { return };
    let launches = Launches::default();
    let reg = probe_registry(&launches);
    let dir = tmpdir("repeat_gated");
    let steps = 3;
    for kind in ["countdown", "countdown_in_place"] {
        let json = r#"{"mesoflow": 1,
 "inputs": {"x": {"type": "particles", "rows": 1, "cols": 1}},
 "nodes": [
   {"id": "loop", "kind": "repeat", "inputs": {"initial": "inputs.x", "next": "tick.out", "count": "tick.count"}},
   {"id": "tick", "kind": "KIND", "inputs": {"x": "loop.current"}}
 ],
 "outputs": {"out": "loop.out", "iterations": "loop.iterations", "total": "loop.total", "first": "loop.first"}}"#
            .replace("KIND", kind);
        let path = write_graph(&dir, &format!("{kind}.json"), &json);
        let g = load_with_registry(&path, &reg);
        let types = [("x".to_string(), ValueType::Particles { n: 1, k: 1 })].into();
        let p = plan_graph(&gpu.caps, &g, types, None, true);
        // The loop ends where its value lies (the requested output's buffer).
        let finish = ("loop".into(), "loop.current".into(), "loop.out".into());
        let want: Vec<_> = match kind {
            "countdown" => vec![finish],
            _ => vec![
                ("tick".into(), "loop.current".into(), "tick.out".into()),
                finish,
            ],
        };
        assert_eq!(in_place_of(&g, &p), want, "{kind}");
        for x in [1.0, 4.0] {
            let inputs: BTreeMap<_, _> = [("x".to_string(), particles(&[[x]]))].into();
            // From x, the counts are 1 until x - k reaches 0: x iterations, the last
            // counting 0, and out = 0 exactly (small integers in f32).
            let k = x as u32;
            for profile in [
                Profile::Off,
                Profile::Launches,
                Profile::Dispatches,
                Profile::Steps,
            ] {
                let case = format!("{kind}, x {x}, {profile:?}");
                launches.clear();
                let (out, iterations) = run_with_loops_profiled(&gpu, &g, &inputs, steps, profile)
                    .unwrap_or_else(|e| panic!("{e}"));
                assert_eq!(f32s(&out["out"]), [0.0], "{case}");
                assert_eq!(u32s(&out["iterations"]), [k], "{case}");
                assert_eq!(u32s(&out["total"]), [k - 1], "{case}");
                // The first iteration's count: 0 only where it was also the last.
                assert_eq!(u32s(&out["first"]), [u32::from(k > 1)], "{case}");
                assert_eq!(
                    iterations,
                    [("loop".to_string(), vec![k; steps as usize])],
                    "{case}"
                );
                let ran = launches.total(&gpu);
                assert_eq!(
                    ran,
                    k * steps as u32,
                    "{case}: the body ran {ran} times for {k} iterations a step over {steps} steps"
                );
            }
        }
    }
}

/// In place through a loop body: two in-place nodes in a row (the second in place of
/// the first's output, made in the body; `next` ends in `current`'s buffer), and a body
/// that reads `current` after the node that could take its buffer (which then does not:
/// only the second node, in place of the first's output, does). Both against their
/// recurrences, until the count is 0 and for a fixed count, two steps with state.
#[test]
fn repeat_bodies_write_in_place_only_where_nothing_reads_after() {
    let Some(gpu) = gpu() else { return };
    let launches = Launches::default();
    let reg = probe_registry(&launches);
    let dir = tmpdir("repeat_in_place");
    let json = |loop_params: &str, second_y: &str| {
        format!(
            r#"{{"mesoflow": 1,
 "inputs": {{"x": {{"type": "particles", "rows": 3, "cols": 1}}}},
 "state": {{"s": {{"init": "inputs.x", "next": "loop.out"}}}},
 "nodes": [
   {{"id": "loop", "kind": "repeat", "params": {loop_params}, "inputs": {{"initial": "state.s", "next": "b.out", "count": "b.count"}}}},
   {{"id": "a", "kind": "countdown_in_place", "inputs": {{"x": "loop.current"}}}},
   {{"id": "b", "kind": "countdown_in_place", "inputs": {{"x": "a.out"{second_y}}}}}
 ],
 "outputs": {{"s": "state.s", "iterations": "loop.iterations"}}}}"#
        )
    };
    let x0 = [[12.0], [7.0], [3.0]];
    let inputs: BTreeMap<_, _> = [("x".to_string(), particles(&x0))].into();
    let types: BTreeMap<_, _> = [("x".to_string(), ValueType::Particles { n: 3, k: 1 })].into();
    let steps = 2;
    // x -> x - 2 until x[0] reaches 0: 12 -> 10 ... -> 0 in 6 iterations (2 steps: 6
    // iterations, then the loop starts from 0 and runs 1 iteration more, to -2).
    let chain = json("{}", "");
    // x -> (x - 1) - 1 + x = 2x - 2, three times a step.
    let reread = json(r#"{"fixed": 3}"#, r#", "y": "loop.current""#);
    for (name, json, want_in_place) in [
        (
            "chain",
            &chain,
            vec![
                ("a", "loop.current", "a.out"),
                ("b", "a.out", "b.out"),
                ("loop", "loop.current", "loop.out"),
            ],
        ),
        (
            "reread",
            &reread,
            vec![
                ("b", "a.out", "b.out"),
                ("loop", "loop.current", "loop.out"),
            ],
        ),
    ] {
        let path = write_graph(&dir, &format!("{name}.json"), json);
        let g = load_with_registry(&path, &reg);
        let p = plan_graph(&gpu.caps, &g, types.clone(), None, true);
        let want_in_place: Vec<_> = want_in_place
            .iter()
            .map(|(n, i, o)| (n.to_string(), i.to_string(), o.to_string()))
            .collect();
        assert_eq!(in_place_of(&g, &p), want_in_place, "{name}");
        let (out, loops) = run_with_loops_profiled(&gpu, &g, &inputs, steps, Profile::Off)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let mut want: Vec<f32> = x0.iter().map(|r| r[0] as f32).collect();
        let mut counts = Vec::new();
        for _ in 0..steps {
            let mut k = 0;
            loop {
                k += 1;
                if name == "chain" {
                    want.iter_mut().for_each(|v| *v -= 2.0);
                    if want[0] <= 0.0 {
                        break;
                    }
                } else {
                    want.iter_mut().for_each(|v| *v = 2.0 * *v - 2.0);
                    if k == 3 {
                        break;
                    }
                }
            }
            counts.push(k);
        }
        assert_eq!(f32s(&out["s"]), want, "{name}");
        assert_eq!(u32s(&out["iterations"]), [counts[1]], "{name}");
        assert_eq!(loops.len(), usize::from(name == "chain"), "{name}");
        if let Some((_, per_step)) = loops.first() {
            assert_eq!(per_step, &counts, "{name}");
        }
    }
}

/// A halted step keeps nothing, its body's value written in place or not, the loop
/// starting from the state or from a value made from it (`pre`, which the loop starts in:
/// with the loop's values, in the state's next buffer, as the mesh of bd_delaunay.json's
/// settle loop): the loop's first iteration runs before its tally sees the `halt`
/// (overwriting `current`, the state's next buffer where the loop ends in it), the step
/// stops with the halt's error, and the next step, halt cleared, goes on from the state
/// before it, as if it had never run.
#[test]
fn a_halted_step_keeps_nothing_in_place_or_not() {
    let Some(gpu) = gpu() else { return };
    let launches = Launches::default();
    let reg = probe_registry(&launches);
    let dir = tmpdir("repeat_halt");
    let halt = |h: u32| {
        BTreeMap::from([(
            "h".to_string(),
            HostArray::u32(ValueType::Indices { n: 1 }, vec![h]),
        )])
    };
    for kind in ["countdown", "countdown_in_place"] {
        for pre in [false, true] {
            let case = format!("{kind}, pre {pre}");
            let json = r#"{"mesoflow": 1,
 "inputs": {"x": {"type": "particles", "rows": 1, "cols": 1}, "h": {"type": "indices", "rows": 1}},
 "state": {"s": {"init": "inputs.x", "next": "loop.out"}},
 "nodes": [
   {"id": "pre", "kind": "countdown", "inputs": {"x": "state.s"}},
   {"id": "loop", "kind": "repeat", "inputs": {"initial": "INITIAL", "next": "tick.out", "count": "tick.count", "halt": "inputs.h"}},
   {"id": "tick", "kind": "KIND", "inputs": {"x": "loop.current"}}
 ],
 "outputs": {"s": "state.s"}}"#
                .replace("KIND", kind)
                .replace("INITIAL", if pre { "pre.out" } else { "state.s" });
            let path = write_graph(&dir, &format!("{kind}_{pre}.json"), &json);
            let g = load_with_registry(&path, &reg);
            let mut inputs = halt(0);
            inputs.insert("x".into(), particles(&[[3.0]]));
            let p = plan_graph(&gpu.caps, &g, types_of(&inputs), None, true);
            // The loop ends in the state's next buffer; it starts in pre's, never in the
            // state's.
            let vias: Vec<Via> = p.in_place.iter().map(|a| a.via).collect();
            let mut want = Vec::new();
            if pre {
                want.push(Via::Start);
            }
            if kind == "countdown_in_place" {
                want.push(Via::Node);
            }
            want.push(Via::Finish);
            assert_eq!(vias, want, "{case}");
            let mut program = compile_cached(&gpu, &g, &p);
            program.upload(&inputs).unwrap();
            let one = RunOptions {
                steps: 1,
                profile: Profile::Off,
                progress: false,
            };
            let s = |program: &Program| {
                let out: BTreeMap<_, _> = program.read_outputs().unwrap().into_iter().collect();
                f32s(&out["s"])
            };
            // 3 -> 2 -> 1 -> 0 (pre: 3 -> 2, then 1 -> 0): the count 0 stops the loop.
            program.run_on(&one).unwrap();
            assert_eq!(s(&program), [0.0], "{case}");
            program.update_inputs(&halt(5)).unwrap();
            let e = program.run_on(&one).unwrap_err().to_string();
            assert!(e.contains("`halt` check is 5"), "{case}: {e}");
            // The state after the last step that ran, though the halted one wrote its next
            // buffer.
            assert_eq!(s(&program), [0.0], "{case}");
            program.update_inputs(&halt(0)).unwrap();
            // 0 -> -1 (pre: 0 -> -1 -> -2), the count 0 at once: from the state before
            // the halted step.
            program.run_on(&one).unwrap();
            assert_eq!(s(&program), [if pre { -2.0 } else { -1.0 }], "{case}");
            assert_eq!(program.steps_done(), 2, "{case}");
        }
    }
}

/// A run that halts after some good steps keeps them: the state is the last good step's,
/// and the steps counted are those that ran (the next run goes on from there, with their
/// step number and state buffer), under every way of running steps. The halt is the
/// `countdown` probe's count on the state,
/// nonzero once the state passes 1: from -1 the state runs -1, 0, 1, 2 and the fourth
/// step halts.
#[test]
fn a_run_halted_after_good_steps_keeps_them() {
    let Some(gpu) = gpu() else { return };
    let launches = Launches::default();
    let reg = probe_registry(&launches);
    let dir = tmpdir("repeat_halt_later");
    let json = r#"{"mesoflow": 1,
 "inputs": {"x": {"type": "particles", "rows": 1, "cols": 1}},
 "state": {"s": {"init": "inputs.x", "next": "inc.out"}},
 "nodes": [
   {"id": "inc", "kind": "affine", "params": {"offset": 1}, "inputs": {"x": "state.s"}},
   {"id": "check", "kind": "countdown", "inputs": {"x": "state.s"}},
   {"id": "loop", "kind": "repeat", "inputs": {"initial": "state.s", "next": "tick.out", "count": "tick.count", "halt": "check.count"}},
   {"id": "tick", "kind": "countdown", "inputs": {"x": "loop.current"}}
 ],
 "outputs": {"s": "state.s", "left": "loop.out"}}"#;
    let path = write_graph(&dir, "halt_later.json", json);
    let g = load_with_registry(&path, &reg);
    let inputs: BTreeMap<_, _> = [("x".to_string(), particles(&[[-1.0]]))].into();
    let p = plan_graph(&gpu.caps, &g, types_of(&inputs), None, true);
    for profile in [Profile::Off, Profile::Launches, Profile::Steps] {
        let mut program = compile_cached(&gpu, &g, &p);
        program.upload(&inputs).unwrap();
        let e = program
            .run_on(&RunOptions {
                steps: 10,
                profile,
                progress: false,
            })
            .unwrap_err()
            .to_string();
        assert!(e.contains("`halt` check is 1"), "{profile:?}: {e}");
        assert_eq!(program.steps_done(), 3, "{profile:?}");
        let out: BTreeMap<_, _> = program.read_outputs().unwrap().into_iter().collect();
        assert_eq!(f32s(&out["s"]), [2.0], "{profile:?}");
    }
}

/// Two loops in a step, the second's value made from the first's, run as one submission
/// a step (`StepChain`, the default) and with a host round trip per loop: the same
/// results and iterations under every way of running steps. The state s grows by 1 a
/// step, the first loop counts down from s (s iterations) and the second from 2 s + what
/// the first left (0): the first batch (2 + 1 iterations, then one more than the last
/// step's) cannot hold the first loop at the first step nor the second at any, so the
/// chained steps go on with further batches and submit the rest of the step again; the
/// probes count that every body ran exactly the iterations reported, none past a stop.
#[test]
fn chained_loops_run_as_the_host_decided_ones() {
    let Some(gpu) = gpu() else { return };
    let launches = Launches::default();
    let reg = probe_registry(&launches);
    let dir = tmpdir("repeat_chained");
    let json = r#"{"mesoflow": 1,
 "inputs": {"x": {"type": "particles", "rows": 1, "cols": 1}},
 "state": {"s": {"init": "inputs.x", "next": "up.out"}},
 "nodes": [
   {"id": "up", "kind": "affine", "params": {"offset": 1}, "inputs": {"x": "state.s"}},
   {"id": "a", "kind": "repeat", "inputs": {"initial": "state.s", "next": "ta.out", "count": "ta.count"}},
   {"id": "ta", "kind": "countdown", "inputs": {"x": "a.current"}},
   {"id": "twice", "kind": "axpy", "params": {"alpha": 2}, "inputs": {"x": "state.s", "y": "a.out"}},
   {"id": "b", "kind": "repeat", "inputs": {"initial": "twice.out", "next": "tb.out", "count": "tb.count"}},
   {"id": "tb", "kind": "countdown", "inputs": {"x": "b.current"}}
 ],
 "outputs": {"s": "state.s", "a_left": "a.out", "b_left": "b.out", "b_iterations": "b.iterations", "b_total": "b.total"}}"#;
    let path = write_graph(&dir, "two_loops.json", json);
    let g = load_with_registry(&path, &reg);
    let x0 = 4u32;
    let steps = 4u64;
    let inputs: BTreeMap<_, _> = [("x".to_string(), particles(&[[x0 as f64]]))].into();
    let p = plan_graph(&gpu.caps, &g, types_of(&inputs), None, true);
    let a_want: Vec<u32> = (0..steps as u32).map(|k| x0 + k).collect();
    let b_want: Vec<u32> = a_want.iter().map(|a| 2 * a).collect();
    for chain in [true, false] {
        for profile in [Profile::Off, Profile::Steps, Profile::Launches] {
            let case = format!("chained {chain}, {profile:?}");
            launches.clear();
            let mut program = compile_cached(&gpu, &g, &p);
            program.set_chain_loops(chain);
            let out = crate::util::try_run_program(&mut program, &inputs, steps, profile)
                .unwrap_or_else(|e| panic!("{case}: {e}"));
            assert_eq!(
                program.loop_iterations(),
                [
                    ("a".to_string(), a_want.clone()),
                    ("b".to_string(), b_want.clone())
                ],
                "{case}"
            );
            assert_eq!(f32s(&out["s"]), [(x0 + steps as u32) as f32], "{case}");
            assert_eq!(f32s(&out["a_left"]), [0.0], "{case}");
            assert_eq!(f32s(&out["b_left"]), [0.0], "{case}");
            let b_last = *b_want.last().unwrap();
            assert_eq!(u32s(&out["b_iterations"]), [b_last], "{case}");
            assert_eq!(u32s(&out["b_total"]), [b_last - 1], "{case}");
            let want: u32 = a_want.iter().chain(&b_want).sum();
            assert_eq!(launches.total(&gpu), want, "{case}: body launches");
        }
    }
}
