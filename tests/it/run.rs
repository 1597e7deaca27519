//! Graphs run end to end on the GPU: closed forms, fusion equivalence, in-place outputs
//! against copies, states across steps (one kept unchanged), launches only outputs read
//! run on a run's last step only, subgraphs, the shipped examples.

use std::collections::BTreeMap;

use mesoflow::exec::{Profile, Program, RunOptions};
use mesoflow::gpu::KernelCache;
use mesoflow::graph;
use mesoflow::plan::PlanOptions;
use mesoflow::value::{HostArray, ValueType};

use crate::util::probe::{countdown_registry, load_probe_graph};
use crate::util::{
    Rng, compile_cached, f32s, gpu, load, load_with_registry, named, particles, plan_graph, root,
    run_graph, run_program, tmpdir, types_of, write_graph,
};

#[test]
fn relax_example_matches_its_closed_form() {
    let Some(gpu) = gpu() else { return };
    let g = load(&root().join("graphs/examples/relax.json"));
    let ty = ValueType::Particles { n: 1000, k: 3 };
    let x0 = Rng::new(1).array(ty, -1.0, 1.0);
    for steps in [1, 2, 7, 100] {
        let out = run_graph(
            &gpu,
            &g,
            &named(&[("positions", x0.clone())]),
            Some(&["positions"]),
            steps,
            true,
        );
        let x = f32s(&out["positions"]);
        // x_n = (1 - k dt)^n x_0 with k = 1, dt = 0.01; f32 rounding grows like n * eps.
        let factor = 0.99f64.powi(steps as i32);
        for (a, b) in x.iter().zip(f32s(&x0)) {
            let want = factor * b as f64;
            assert!(
                (*a as f64 - want).abs() <= 1e-6 * (1.0 + steps as f64) * b.abs() as f64 + 1e-7,
                "{steps} steps: {a} vs {want}"
            );
        }
    }
}

#[test]
fn fused_and_unfused_runs_agree() {
    let Some(gpu) = gpu() else { return };
    let g = load(&root().join("graphs/fixtures/pointwise_all.json"));
    let mut rng = Rng::new(5);
    let p = ValueType::Particles { n: 37, k: 3 };
    let data = named(&[
        ("x", rng.array(p, 0.5, 2.0)),
        ("y", rng.array(p, 0.5, 2.0)),
        ("s", rng.array(ValueType::Scalar, 0.5, 2.0)),
    ]);
    let fused = run_graph(&gpu, &g, &data, None, 1, true);
    let unfused = run_graph(&gpu, &g, &data, None, 1, false);
    for (name, a) in &fused {
        let (x, y) = (f32s(a), f32s(&unfused[name]));
        let scale = y.iter().fold(0f32, |m, v| m.max(v.abs()));
        for (i, (u, v)) in x.iter().zip(&y).enumerate() {
            // Same f32 operations either way; allow a few ulps for FMA contraction.
            assert!(
                (u - v).abs() <= 4.0 * f32::EPSILON * scale,
                "{name}[{i}]: fused {u} vs unfused {v}"
            );
        }
    }
}

#[test]
fn subgraphs_expand_with_their_own_params() {
    let Some(gpu) = gpu() else { return };
    let g = load(&root().join("graphs/fixtures/subgraph_parent.json"));
    assert!(
        g.nodes.iter().any(|n| n.id == "stiff/f"),
        "subgraph nodes carry prefixed ids"
    );
    let x = Rng::new(3).array(ValueType::Particles { n: 50, k: 3 }, -1.0, 1.0);
    let out = run_graph(&gpu, &g, &named(&[("x", x.clone())]), None, 1, true);
    for ((soft, both), x) in f32s(&out["soft"])
        .iter()
        .zip(f32s(&out["both"]))
        .zip(f32s(&x))
    {
        assert!((soft + 0.5 * x).abs() < 1e-6);
        assert!((both + 2.5 * x).abs() < 1e-6, "both = -2 x + soft = -2.5 x");
    }
}

/// A subgraph may keep state: each use of it has its own, namespaced by the node that
/// uses it (`soft/x`, `stiff/x`) beside the parent's `x`. Both start from the same input;
/// each relaxes at its own rate, x0 (1 - k dt)^steps, and the parent's state doubles.
#[test]
fn stateful_subgraphs_keep_a_state_per_use() {
    let Some(gpu) = gpu() else { return };
    let g = load(&root().join("graphs/fixtures/stateful_parent.json"));
    let names: Vec<&str> = g.states.iter().map(|s| s.name.as_str()).collect();
    for want in ["x", "soft/x", "stiff/x"] {
        assert!(names.contains(&want), "state {want} in {names:?}");
    }
    let x = Rng::new(5).array(ValueType::Particles { n: 20, k: 3 }, -1.0, 1.0);
    for steps in [1u64, 4] {
        let out = run_graph(&gpu, &g, &named(&[("x", x.clone())]), None, steps, true);
        let n = steps as i32;
        for (((soft, stiff), own), x0) in f32s(&out["soft"])
            .iter()
            .zip(f32s(&out["stiff"]))
            .zip(f32s(&out["x"]))
            .zip(f32s(&x))
        {
            let x0 = x0 as f64;
            let want_soft = x0 * (1.0 - 0.5 * 0.1f64).powi(n);
            let want_stiff = x0 * (1.0 - 2.0 * 0.1f64).powi(n);
            assert!(
                (*soft as f64 - want_soft).abs() < 1e-6,
                "{steps} steps: soft {soft} against {want_soft}"
            );
            assert!(
                (stiff as f64 - want_stiff).abs() < 1e-6,
                "{steps} steps: stiff {stiff} against {want_stiff}"
            );
            assert!(
                (own as f64 - x0 * 2f64.powi(n)).abs() < 1e-5,
                "{steps} steps: own {own}"
            );
        }
    }
}

#[test]
fn states_carry_across_steps_including_copies_and_swaps() {
    let Some(gpu) = gpu() else { return };
    let dir = tmpdir("states");
    let path = write_graph(
        &dir,
        "states.json",
        r#"{"mesoflow": 1,
         "inputs": {"x": {"type": "particles", "rows": 3, "cols": 1}, "y": {"type": "particles", "rows": 3, "cols": 1}},
         "state": {
           "count": {"init": "inputs.x", "next": "inc.out"},
           "a": {"init": "inputs.x", "next": "state.b"},
           "b": {"init": "inputs.y", "next": "state.a"},
           "held": {"init": "inputs.x", "next": "inputs.y"}
         },
         "nodes": [{"id": "inc", "kind": "affine", "params": {"offset": 1}, "inputs": {"x": "state.count"}}],
         "outputs": {"count": "state.count", "a": "state.a", "b": "state.b", "held": "state.held", "inc": "inc.out"}}"#,
    );
    let g = load(&path);
    let t = ValueType::Particles { n: 3, k: 1 };
    let x = HostArray::f32(t, vec![1.0, 2.0, 3.0]);
    let y = HostArray::f32(t, vec![10.0, 20.0, 30.0]);
    for steps in [1u64, 2, 3, 8] {
        let out = run_graph(
            &gpu,
            &g,
            &named(&[("x", x.clone()), ("y", y.clone())]),
            None,
            steps,
            true,
        );
        let n = steps as f32;
        assert_eq!(
            f32s(&out["count"]),
            vec![1.0 + n, 2.0 + n, 3.0 + n],
            "{steps} steps"
        );
        assert_eq!(f32s(&out["inc"]), vec![1.0 + n, 2.0 + n, 3.0 + n]);
        let (a, b) = if steps % 2 == 1 { (&y, &x) } else { (&x, &y) };
        assert_eq!(
            f32s(&out["a"]),
            f32s(a),
            "{steps} steps: a and b swap every step"
        );
        assert_eq!(f32s(&out["b"]), f32s(b));
        assert_eq!(f32s(&out["held"]), f32s(&y));
    }
}

#[test]
fn every_example_runs() {
    let Some(gpu) = gpu() else { return };
    let dir = root().join("graphs/examples");
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap().flatten() {
        let path = e.path();
        if path.extension().is_none_or(|x| x != "json") {
            continue;
        }
        let g = load(&path);
        let types = g.declared_input_types();
        let mut rng = Rng::new(11);
        let data: BTreeMap<String, HostArray> = types
            .iter()
            .map(|(k, t)| (k.clone(), rng.array(*t, -1.0, 1.0)))
            .collect();
        let out = run_graph(&gpu, &g, &data, None, 3, true);
        assert_eq!(out.len(), g.outputs.len(), "{}", path.display());
        for (name, a) in &out {
            assert!(
                a.data.to_f64().iter().all(|v| v.is_finite()),
                "{}: output {name} is not finite",
                path.display()
            );
        }
        n += 1;
    }
    assert!(n >= 1);
}

#[test]
fn identical_kernels_share_one_pipeline() {
    let Some(gpu) = gpu() else { return };
    use mesoflow::exec::Program;
    use mesoflow::gpu::KernelCache;
    let dir = tmpdir("pipeline-cache");
    let g = load(&write_graph(
        &dir,
        "chain.json",
        &crate::util::chain_graph(20),
    ));
    let ty = ValueType::Particles { n: 64, k: 1 };
    let p = plan_graph(&gpu.caps, &g, [("x".to_string(), ty)].into(), None, false);
    let mut cache = KernelCache::default();
    let program = Program::compile(&gpu, &g, &p, &mut cache).unwrap();
    // Twenty unfused scale nodes: one pointwise pipeline, plus the clock tick and the copy.
    assert!(
        program.kernels_built <= 3,
        "{} pipelines built",
        program.kernels_built
    );
    assert_eq!(program.dispatches_per_step(), 21);
    // A second program over the same cache builds nothing new.
    let again = Program::compile(&gpu, &g, &p, &mut cache).unwrap();
    assert_eq!(again.kernels_built, 0);
}

#[test]
fn whole_steps_are_timed_end_to_end_and_compute_what_unprofiled_runs_do() {
    let Some(gpu) = gpu() else { return };
    use mesoflow::exec::{Profile, Program, RunOptions};
    use mesoflow::gpu::KernelCache;
    use mesoflow::plan::{self, PlanOptions};
    let dir = tmpdir("step-timing");
    let g = load(&write_graph(
        &dir,
        "chain.json",
        &crate::util::chain_graph(8),
    ));
    let ty = ValueType::Particles { n: 300, k: 1 };
    let x = HostArray::f32(ty, (0..300).map(|i| i as f32).collect());
    let opts = PlanOptions {
        outputs: None,
        inputs: [("x".to_string(), ty)].into_iter().collect(),
        fuse: false,
        in_place: true,
    };
    let p = plan::plan(&g, &opts, &gpu.caps).unwrap();
    let mut cache = KernelCache::default();
    let mut program = Program::compile(&gpu, &g, &p, &mut cache).unwrap();
    program.upload(&crate::util::named(&[("x", x)])).unwrap();
    let mut outputs = Vec::new();
    for profile in [Profile::Off, Profile::Steps] {
        let stats = program
            .run(&RunOptions {
                steps: 3,
                profile,
                progress: false,
            })
            .unwrap();
        if profile == Profile::Steps {
            assert_eq!(stats.step_samples.len(), 3);
            assert!(stats.step_samples.iter().all(|d| !d.is_zero()), "{stats:?}");
            assert_eq!(stats.timed_by_gpu, gpu.caps.timestamps);
            assert!(stats.profile.is_empty());
        } else {
            assert!(stats.step_samples.is_empty());
        }
        outputs.push(program.read_outputs().unwrap());
    }
    assert_eq!(outputs[0], outputs[1]);
}

/// The error of compiling, on this device, a one-node `sum` graph over an input of `n`
/// rows of `k` planned for a device without size limits: the executor checks every
/// buffer against the device's limits before allocating (once the device itself refused
/// the bind group, under an internal buffer label).
fn refused_past_the_device_limits(
    gpu: &mesoflow::gpu::GpuContext,
    name: &str,
    n: u32,
    k: u32,
) -> String {
    use mesoflow::exec::Program;
    use mesoflow::gpu::KernelCache;
    use mesoflow::plan::{self, PlanOptions};
    let dir = tmpdir(name);
    let g = load(&write_graph(
        &dir,
        "sum.json",
        &format!(
            r#"{{"mesoflow": 1,
            "inputs": {{"x": {{"type": "particles", "cols": {k}}}}},
            "nodes": [{{"id": "total", "kind": "sum", "inputs": {{"x": "inputs.x"}}}}],
            "outputs": {{"total": "total.out"}}}}"#
        ),
    ));
    let opts = PlanOptions {
        outputs: None,
        inputs: [("x".to_string(), ValueType::Particles { n, k })].into(),
        fuse: true,
        in_place: true,
    };
    let caps = mesoflow::gpu::DeviceCaps {
        max_binding: u64::MAX,
        max_buffer: u64::MAX,
        ..gpu.caps.clone()
    };
    let p = plan::plan(&g, &opts, &caps).unwrap();
    let e = match Program::compile(gpu, &g, &p, &mut KernelCache::default()) {
        Ok(_) => panic!("a buffer past the device's limits compiled"),
        Err(e) => e.to_string(),
    };
    eprintln!("refused as: {e}");
    e
}

#[test]
fn a_binding_past_the_device_limit_is_refused_by_name_before_anything_is_built() {
    let Some(gpu) = gpu() else { return };
    // The input's binding is past what the device allows.
    let n = u32::try_from(gpu.caps.max_binding / 4 + 4).unwrap();
    let e = refused_past_the_device_limits(&gpu, "refused-launch", n, 1);
    assert!(
        e.contains("input `x`") && e.contains("max_storage_buffer_binding_size"),
        "{e}"
    );
    assert!(e.contains("nothing was allocated"), "{e}");
    assert!(!e.contains("label") && !e.contains("partial"), "{e}");
}

#[test]
fn a_buffer_past_the_device_limit_is_refused_by_name_before_anything_is_allocated() {
    let Some(gpu) = gpu() else { return };
    // 64 GiB of input: no device creates the buffer.
    let e = refused_past_the_device_limits(&gpu, "unheld-buffers", u32::MAX, 4);
    assert!(
        e.contains("input `x`") && e.contains("max_buffer_size"),
        "{e}"
    );
    assert!(e.contains("nothing was allocated"), "{e}");
    assert!(!e.contains("label"), "{e}");
}

/// `read_finite_outputs` refuses outputs holding NaN or infinity from finite inputs,
/// naming each with its counts and first index; `read_outputs` still gives the values;
/// an input holding NaN turns the check off (its NaN may flow to the outputs).
#[test]
fn non_finite_outputs_from_finite_inputs_are_an_error_of_the_checked_read() {
    use mesoflow::exec::{ExecError, Profile, Program, RunOptions};
    use mesoflow::gpu::KernelCache;
    let Some(gpu) = gpu() else { return };
    let g = load(&root().join("graphs/fixtures/divide_by_zero.json"));
    let ty = ValueType::Particles { n: 2, k: 3 };
    let p = plan_graph(
        &gpu.caps,
        &g,
        [("x".to_string(), ty)].into_iter().collect(),
        None,
        true,
    );
    let mut cache = KernelCache::default();
    let mut program = Program::compile(&gpu, &g, &p, &mut cache).unwrap();
    let once = RunOptions {
        steps: 1,
        profile: Profile::Off,
        progress: false,
    };
    let x = HostArray::f32(ty, vec![1.0, -2.0, 3.0, 0.0, 5.0, 6.0]);
    program.upload(&named(&[("x", x)])).unwrap();
    program.run(&once).unwrap();
    assert_eq!(program.non_finite_input(), None);
    match program.read_finite_outputs() {
        Err(e @ ExecError::NonFinite(_)) => {
            let ExecError::NonFinite(found) = &e else {
                unreachable!()
            };
            assert_eq!(found.len(), 1, "{e}");
            let (name, f) = &found[0];
            assert_eq!(name, "ratio");
            assert_eq!((f.nan, f.infinite, f.first, f.len), (1, 5, 0, 6), "{e}");
            assert!(f.first_value.is_infinite());
            assert!(e.to_string().contains("output `ratio` has 1 NaN and 5 infinite of 6 values, the first at index 0 (inf)"), "{e}");
        }
        other => panic!("expected NonFinite, got {other:?}"),
    }
    let raw: BTreeMap<String, HostArray> = program.read_outputs().unwrap().into_iter().collect();
    assert_eq!(f32s(&raw["doubled"]), vec![2.0, -4.0, 6.0, 0.0, 10.0, 12.0]);
    assert!(f32s(&raw["ratio"])[3].is_nan());
    // A NaN given as input: not judged.
    let x = HostArray::f32(ty, vec![f32::NAN, 1.0, 1.0, 1.0, 1.0, 1.0]);
    program.upload(&named(&[("x", x)])).unwrap();
    program.run(&once).unwrap();
    assert_eq!(program.non_finite_input(), Some("x"));
    assert!(program.read_finite_outputs().is_ok());
}

#[test]
fn graph_params_pick_a_subgraph_and_bind_its_params() {
    let Some(gpu) = gpu() else { return };
    let g = load(&root().join("graphs/fixtures/graph_params.json"));
    let x = Rng::new(6).array(ValueType::Particles { n: 12, k: 3 }, -1.0, 1.0);
    let o = Rng::new(7).array(ValueType::Particles { n: 12, k: 3 }, -1.0, 1.0);
    for steps in [1u64, 3] {
        let inputs = named(&[("x", x.clone()), ("o", o.clone())]);
        let out = run_graph(&gpu, &g, &inputs, None, steps, true);
        for (i, (x0, o)) in f32s(&x).iter().zip(f32s(&o)).enumerate() {
            let (mut plain, mut bound, mut forwarded) = (*x0 as f64, *x0 as f64, *x0 as f64);
            let mut offset = *x0 as f64;
            for _ in 0..steps {
                plain += 0.1 * (-plain);
                bound += 0.1 * (-2.0 * bound + 0.5);
                forwarded += 0.1 * (-0.25 * forwarded);
                offset += 0.1 * (o as f64 - offset);
            }
            for (name, want) in [
                ("plain", plain),
                ("bound", bound),
                ("forwarded", forwarded),
                ("with_input", offset),
                ("forwarded_input", offset),
            ] {
                let got = f32s(&out[name])[i] as f64;
                assert!(
                    (got - want).abs() < 1e-6,
                    "{steps} steps, {name}[{i}]: {got} against {want}"
                );
            }
        }
    }
}

#[test]
fn graph_param_mistakes_are_named() {
    let dir = tmpdir("graph_param_mistakes");
    let lib = root().join("graphs/fixtures/lib");
    for f in ["relax_with.json", "trap_force.json", "linear_pull.json"] {
        std::fs::create_dir_all(dir.join("lib")).unwrap();
        std::fs::copy(lib.join(f), dir.join("lib").join(f)).unwrap();
    }
    let cases: [(&str, &str); 5] = [
        (
            r#"{"id": "r", "graph": "lib/relax_with.json", "params": {"pull": "lib/linear_pull.json", "pull.stiffness": 1, "pul.shift": 1}, "inputs": {"x0": "inputs.x"}}"#,
            "`pul.shift` binds param `shift` of graph param `pul`, but this graph has no graph param `pul` (its graph params: pull)",
        ),
        (
            r#"{"id": "r", "graph": "lib/relax_with.json", "params": {"pull": "lib/linear_pull.json", "pull.stifness": 1}, "inputs": {"x0": "inputs.x"}}"#,
            "unknown param `stifness` (did you mean `stiffness`?) (this graph's params: stiffness, shift); bound as `pull.stifness` in node `r` of",
        ),
        (
            r#"{"id": "r", "graph": "lib/relax_with.json", "params": {"pull": "lib/nowhere.json"}, "inputs": {"x0": "inputs.x"}}"#,
            "graph param `pull`: cannot read subgraph file",
        ),
        (
            r#"{"id": "r", "graph": "lib/relax_with.json", "params": {"pull": 3}, "inputs": {"x0": "inputs.x"}}"#,
            "bad value 3 for param `pull`",
        ),
        (
            r#"{"id": "r", "graph": "$k", "inputs": {"x0": "inputs.x"}}"#,
            "`graph`: `$k` is not a graph param of this file",
        ),
    ];
    for (i, (node, want)) in cases.iter().enumerate() {
        let text = format!(
            r#"{{"mesoflow": 1, "params": {{"k": {{"default": 1.0}}}}, "inputs": {{"x": {{"type": "particles", "cols": 3}}}},
               "nodes": [{node}], "outputs": {{"y": "r.positions"}}}}"#
        );
        let path = write_graph(&dir, &format!("case{i}.json"), &text);
        let err = match mesoflow::graph::load(&path, crate::util::registry(), &Default::default()) {
            Ok(_) => panic!("case {i} loaded"),
            Err(e) => e.to_string(),
        };
        assert!(err.contains(want), "case {i}: {err}");
    }
    // A param both set by the node and bound by the parent.
    write_graph(
        &dir.join("lib"),
        "clash.json",
        r#"{"mesoflow": 1, "params": {"pull": {"default": "linear_pull.json", "graph": true}},
            "inputs": {"x": {"type": "particles", "cols": 3}},
            "nodes": [{"id": "f", "graph": "$pull", "params": {"stiffness": 2}, "inputs": {"x": "inputs.x"}}],
            "outputs": {"force": "f.force"}}"#,
    );
    let top = write_graph(
        &dir,
        "clash_top.json",
        r#"{"mesoflow": 1, "inputs": {"x": {"type": "particles", "cols": 3}},
            "nodes": [{"id": "c", "graph": "lib/clash.json", "params": {"pull.stiffness": 3}, "inputs": {"x": "inputs.x"}}],
            "outputs": {"y": "c.force"}}"#,
    );
    let err = mesoflow::graph::load(&top, crate::util::registry(), &Default::default())
        .err()
        .expect("a clash")
        .to_string();
    assert!(
        err.contains("param `stiffness` is set here and bound by the parent as `pull.stiffness`"),
        "{err}"
    );
}

/// A subgraph left out (`enabled` false) whose planner refuses the values it is given
/// (poisson.json in a box too small for any split) loads, its outputs absent; enabled,
/// the same refusal is the file's problem.
#[test]
fn a_disabled_subgraph_with_a_refused_planner_loads() {
    let dir = tmpdir("disabled_planner");
    for on in [false, true] {
        let text = format!(
            r#"{{"mesoflow": 1,
               "inputs": {{"x": {{"type": "particles", "rows": 4, "cols": 3}}, "q": {{"type": "particles", "rows": 4, "cols": 1}}}},
               "nodes": [
                 {{"id": "e", "graph": "poisson.json", "enabled": {on}, "params": {{"box": [6, 6, 6], "width": 1.0}},
                   "inputs": {{"positions": "inputs.x", "charges": "inputs.q"}}}},
                 {{"id": "f", "kind": "add", "inputs": {{"a": "inputs.x", "b": "e.forces"}}}}
               ],
               "outputs": {{"f": "f.out"}}}}"#
        );
        let path = write_graph(&dir, &format!("on_{on}.json"), &text);
        let loaded = mesoflow::graph::load(&path, crate::util::registry(), &Default::default());
        match (on, loaded) {
            (false, Ok(_)) => {}
            (true, Err(e)) => assert!(e.to_string().contains("no split plans Poisson"), "{e}"),
            (on, Ok(_)) => panic!("enabled {on}: loaded"),
            (on, Err(e)) => panic!("enabled {on}: {e}"),
        }
    }
}

/// `g` planned for `inputs` with in-place outputs on or off, and the ids of the nodes
/// whose outputs the plan put in place, in the plan's order.
fn plan_in_place(
    gpu: &mesoflow::gpu::GpuContext,
    g: &graph::Graph,
    inputs: &BTreeMap<String, HostArray>,
    in_place: bool,
) -> (mesoflow::plan::Plan, Vec<String>) {
    let opts = PlanOptions {
        outputs: None,
        inputs: types_of(inputs),
        fuse: true,
        in_place,
    };
    let p = mesoflow::plan::plan(g, &opts, &gpu.caps).unwrap_or_else(|e| panic!("{e}"));
    let aliased = p
        .in_place
        .iter()
        .map(|a| g.nodes[a.node].id.clone())
        .collect();
    (p, aliased)
}

/// Outputs in place of their inputs (the `countdown_in_place` probe): two nodes read one
/// pooled value, and only the second, the last to read it, writes into its buffer (the
/// first would change what the second reads); a graph input is never written. The
/// results are those of the plan that gives every output a buffer of its own.
#[test]
fn in_place_outputs_give_the_results_of_copies() {
    let Some(gpu) = gpu() else { return };
    let dir = tmpdir("run-in-place");
    let g = load_probe_graph(
        &dir,
        "g.json",
        r#"{"mesoflow": 1,
 "inputs": {"x": {"type": "particles", "rows": 5, "cols": 1}},
 "nodes": [
   {"id": "a", "kind": "countdown", "inputs": {"x": "inputs.x"}},
   {"id": "b", "kind": "countdown_in_place", "inputs": {"x": "a.out"}},
   {"id": "c", "kind": "countdown_in_place", "inputs": {"x": "a.out", "y": "b.out"}},
   {"id": "d", "kind": "countdown", "inputs": {"x": "c.out"}},
   {"id": "e", "kind": "countdown_in_place", "inputs": {"x": "inputs.x"}},
   {"id": "f", "kind": "countdown", "inputs": {"x": "e.out", "y": "inputs.x"}}
 ],
 "outputs": {"d": "d.out", "f": "f.out"}}"#,
    );
    let x: Vec<[f64; 1]> = (0..5).map(|i| [i as f64 - 1.5]).collect();
    let inputs: BTreeMap<_, _> = [("x".to_string(), particles(&x))].into();
    let mut results = Vec::new();
    for in_place in [true, false] {
        let (p, aliased) = plan_in_place(&gpu, &g, &inputs, in_place);
        assert_eq!(aliased, if in_place { vec!["c"] } else { vec![] });
        let mut program = compile_cached(&gpu, &g, &p);
        let out = run_program(&mut program, &inputs, 1);
        results.push((f32s(&out["d"]), f32s(&out["f"])));
    }
    // a = x - 1, b = x - 2, c = (a - 1) + b = 2x - 4, d = 2x - 5; e = x - 1, f = 2x - 2.
    let d: Vec<f32> = x.iter().map(|r| (2.0 * r[0] - 5.0) as f32).collect();
    let f: Vec<f32> = x.iter().map(|r| (2.0 * r[0] - 2.0) as f32).collect();
    assert_eq!(results[0], (d.clone(), f.clone()), "in place");
    assert_eq!(results[1], (d, f), "copied");
}

/// A state kept unchanged (`"next": "state.k"`, no copy in the steps) holds its initial
/// value through even and odd steps: y = x + 2 s x, k = 2 x.
#[test]
fn a_state_kept_unchanged_holds_its_value() {
    let Some(gpu) = gpu() else { return };
    let g = load(&root().join("graphs/fixtures/kept_state.json"));
    let x = Rng::new(8).array(ValueType::Particles { n: 8, k: 2 }, -1.0, 1.0);
    for steps in [1u64, 2, 5] {
        let out = run_graph(&gpu, &g, &named(&[("x", x.clone())]), None, steps, true);
        for ((y, k), x) in f32s(&out["y"]).iter().zip(f32s(&out["k"])).zip(f32s(&x)) {
            assert_eq!(k, 2.0 * x, "{steps} steps");
            let want = x as f64 * (1.0 + 2.0 * steps as f64);
            assert!(
                (*y as f64 - want).abs() < 1e-5,
                "{steps} steps: {y} vs {want}"
            );
        }
    }
}

/// A launch only outputs read (`Plan::last_step_only`: the probe on the next state, an
/// output) runs on the last step of each run only, and the output is the last step's:
/// under every profile, over `run_on` calls and `run_on_and_read` chunks; the same probe
/// feeding the state runs every step.
#[test]
fn launches_only_outputs_read_run_on_the_last_step_of_each_run() {
    let Some(gpu) = gpu() else { return };
    let (reg, launches) = countdown_registry();
    let dir = tmpdir("last_step_only");
    let graph = |next: &str| {
        format!(
            r#"{{"mesoflow": 1,
 "inputs": {{"x": {{"type": "particles", "rows": 1, "cols": 1}}}},
 "state": {{"s": {{"init": "inputs.x", "next": "{next}"}}}},
 "nodes": [
   {{"id": "move", "kind": "affine", "params": {{"offset": 2}}, "inputs": {{"x": "state.s"}}}},
   {{"id": "probe", "kind": "countdown", "inputs": {{"x": "move.out"}}}}
 ],
 "outputs": {{"y": "probe.out", "s": "state.s"}}}}"#
        )
    };
    let inputs: BTreeMap<_, _> = [("x".to_string(), particles(&[[10.0]]))].into();
    let run = |json: &str, runs: &[(u64, Profile, bool)]| -> (Vec<f32>, u32) {
        let g = load_with_registry(&write_graph(&dir, "g.json", json), &reg);
        let p = plan_graph(&gpu.caps, &g, types_of(&inputs), None, true);
        launches.clear();
        let mut cache = KernelCache::default();
        let mut program = Program::compile(&gpu, &g, &p, &mut cache).unwrap();
        program.upload(&inputs).unwrap();
        let mut ys = Vec::new();
        for &(steps, profile, and_read) in runs {
            let opts = RunOptions {
                steps,
                profile,
                progress: false,
            };
            let out: BTreeMap<String, HostArray> = if and_read {
                let (_, out) = program.run_on_and_read(&opts).unwrap();
                out.into_iter().collect()
            } else {
                program.run_on(&opts).unwrap();
                program.read_outputs().unwrap().into_iter().collect()
            };
            ys.push(f32s(&out["y"])[0]);
        }
        (ys, launches.total(&gpu))
    };
    let runs = [
        (5, Profile::Off, false),
        (2, Profile::Launches, false),
        (3, Profile::Steps, false),
        (1, Profile::Dispatches, false),
        (4, Profile::Off, true),
    ];
    // The probe reads the next state: after k steps in all, s = 10 + 2 k and y = s - 1.
    let (ys, ran) = run(&graph("move.out"), &runs);
    assert_eq!(ys, [19.0, 23.0, 29.0, 31.0, 39.0]);
    assert_eq!(
        ran,
        runs.len() as u32,
        "the probe ran {ran} times in {} runs",
        runs.len()
    );
    // The probe's output is the next state: it runs every step; s = 10 + k = y.
    let (ys, ran) = run(&graph("probe.out"), &runs);
    assert_eq!(ys, [15.0, 17.0, 20.0, 21.0, 25.0]);
    assert_eq!(ran, 15);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Loops that start and end where their values lie (`repeat`'s `current` in the buffer of
/// its initial value, its `out` in that of `current`), with the probe in place in a body
/// stopped by its count (gated batches) and a fixed loop after it, carrying a state: the
/// chain from the value made from the state to the state's next value in one buffer
/// (the state's next), or with the first loop's result requested (its buffer then holds
/// that loop's values, which the second copies from). Three steps, against the plan
/// that copies everything and against the recurrence, exactly (quarters in f32).
#[test]
fn loops_in_place_give_the_results_of_copies() {
    let Some(gpu) = gpu() else { return };
    let dir = tmpdir("run-loops-in-place");
    let x: Vec<[f64; 1]> = [4.5, 1.0, 2.25, -1.0, 0.25].map(|v| [v]).into();
    let inputs: BTreeMap<_, _> = [("x".to_string(), particles(&x))].into();
    let steps = 3;
    // a = s - 1; l1: v -= 1 until v[0] <= 0 (at least once); l2: v = v - 1 + x, 3 times.
    let mut s: Vec<f64> = x.iter().map(|r| r[0]).collect();
    let mut l1 = Vec::new();
    for _ in 0..steps {
        let mut v: Vec<f64> = s.iter().map(|s| s - 1.0).collect();
        loop {
            v.iter_mut().for_each(|v| *v -= 1.0);
            if v[0] <= 0.0 {
                break;
            }
        }
        l1 = v.clone();
        for _ in 0..3 {
            v.iter_mut().zip(&x).for_each(|(v, x)| *v = *v - 1.0 + x[0]);
        }
        s = v;
    }
    let f = |v: &[f64]| v.iter().map(|v| *v as f32).collect::<Vec<f32>>();
    for requested in [false, true] {
        let json = r#"{"mesoflow": 1,
 "inputs": {"x": {"type": "particles", "rows": 5, "cols": 1}},
 "state": {"s": {"init": "inputs.x", "next": "l2.out"}},
 "nodes": [
   {"id": "a", "kind": "countdown", "inputs": {"x": "state.s"}},
   {"id": "l1", "kind": "repeat", "inputs": {"initial": "a.out", "next": "t1.out", "count": "t1.count"}},
   {"id": "t1", "kind": "countdown_in_place", "inputs": {"x": "l1.current"}},
   {"id": "l2", "kind": "repeat", "params": {"fixed": 3}, "inputs": {"initial": "l1.out", "next": "t2.out"}},
   {"id": "t2", "kind": "countdown", "inputs": {"x": "l2.current", "y": "inputs.x"}}
 ],
 "outputs": {"s": "state.s"OUTPUTS}}"#
            .replace("OUTPUTS", if requested { r#", "l1": "l1.out""# } else { "" });
        let g = load_probe_graph(&dir, &format!("g{requested}.json"), &json);
        let mut results = Vec::new();
        for in_place in [true, false] {
            // l1 starts in a.out, t1 writes in place, l1 ends in its current; l2 starts in
            // l1.out unless it is requested, and ends in the state's next buffer.
            let (p, aliased) = plan_in_place(&gpu, &g, &inputs, in_place);
            let want = match (in_place, requested) {
                (false, _) => vec![],
                (true, false) => vec!["l1", "t1", "l1", "l2", "l2"],
                (true, true) => vec!["l1", "t1", "l1", "l2"],
            };
            assert_eq!(aliased, want, "requested {requested}");
            let mut program = compile_cached(&gpu, &g, &p);
            let out = run_program(&mut program, &inputs, steps);
            results.push(out);
        }
        let case = format!("requested {requested}");
        for (name, a) in &results[0] {
            assert_eq!(a.data, results[1][name].data, "{case}: {name}");
        }
        assert_eq!(f32s(&results[0]["s"]), f(&s), "{case}");
        if requested {
            assert_eq!(f32s(&results[0]["l1"]), f(&l1), "{case}");
        }
    }
}
