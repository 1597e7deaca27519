//! The `repeat` node with a `fixed` count: a loop within a step, against f64 recurrences (the
//! body reading the loop's value and values from outside it, state carried across
//! steps), several values carried as columns, and its mistakes named. A loop until its
//! count is 0 runs its body exactly as many times as it reports, the iterations the
//! executor sends past the stop gated off, whatever the profile.

use std::collections::BTreeMap;

use mesoflow::exec::Profile;
use mesoflow::graph::{self, LoadOptions};

use crate::util::disks::run_with_loops_profiled;
use crate::util::probe::countdown_registry;
use crate::util::{f32s, gpu, load_or_plan_error, particles, run_graph, tmpdir, u32s, write_graph};

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

#[test]
fn repeat_runs_its_body_only_for_the_iterations_it_reports() {
    let Some(gpu) = gpu() else { return };
    let (reg, launches) = countdown_registry();
    let dir = tmpdir("repeat_gated");
    let json = r#"{"mesoflow": 1,
 "inputs": {"x": {"type": "particles", "rows": 1, "cols": 1}},
 "nodes": [
   {"id": "loop", "kind": "repeat", "inputs": {"initial": "inputs.x", "next": "tick.out", "count": "tick.count"}},
   {"id": "tick", "kind": "countdown", "inputs": {"x": "loop.current"}}
 ],
 "outputs": {"out": "loop.out", "iterations": "loop.iterations", "total": "loop.total"}}"#;
    let path = write_graph(&dir, "countdown.json", json);
    let g = graph::load(&path, &reg, &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    let steps = 3;
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
            launches.clear();
            let (out, iterations) = run_with_loops_profiled(&gpu, &g, &inputs, steps, profile)
                .unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(f32s(&out["out"]), [0.0], "x {x}, {profile:?}");
            assert_eq!(u32s(&out["iterations"]), [k], "x {x}, {profile:?}");
            assert_eq!(u32s(&out["total"]), [k - 1], "x {x}, {profile:?}");
            assert_eq!(
                iterations,
                [("loop".to_string(), vec![k; steps as usize])],
                "x {x}, {profile:?}"
            );
            let ran = launches.count(&gpu);
            assert_eq!(
                ran,
                k * steps as u32,
                "x {x}, {profile:?}: the body ran {ran} times for {k} iterations a step over {steps} steps"
            );
        }
    }
}
