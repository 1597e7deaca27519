//! The whole graph (graphs/mpcd.json): its initial state, a given initial state,
//! measurement and averages against f64 references, total momentum and energy over 10^4
//! steps, and messages for bad input.

use std::collections::BTreeMap;

use mesoflow::expr::ParamValue;
use mesoflow::graph::{self, LoadOptions};
use mesoflow::nodes::mpcd::value_of;
use mesoflow::plan::{self, PlanOptions};
use mesoflow::value::{HostArray, ValueType};

use crate::util::mpcd::{random_particles, run_loaded, run_mpcd};
use crate::util::{Rng, gpu, particles, reference, registry, root, rows, tmpdir, write_graph};

#[test]
fn total_momentum_drifts_less_than_1e_6_over_10_4_steps() {
    if gpu().is_none() {
        return;
    }
    let sets = [("box", "[8, 8, 4]"), ("density", "10")];
    let steps = 10_000;
    // The initial state of the graph: its mpcd_init node alone (same params and seed).
    let start = {
        let gpu = gpu().expect("GPU");
        crate::util::run_node(
            &gpu,
            "mpcd_init",
            r#"{"box": [8, 8, 4], "density": 10, "seed": 4, "stream": 0}"#,
            &BTreeMap::new(),
        )
    };
    let end = run_mpcd(&sets, steps, 4, &["velocities", "momentum", "temperature"]);
    let total = |a: &HostArray| {
        let mut p = [0.0; 3];
        for r in rows(a, 3) {
            for k in 0..3 {
                p[k] += r[k];
            }
        }
        p
    };
    let energy = |a: &HostArray| a.data.to_f64().iter().map(|x| x * x).sum::<f64>();
    let (p0, p1) = (total(&start["velocities"]), total(&end["velocities"]));
    let n = start["velocities"].ty.words() as f64 / 3.0;
    // Relative to N m v_th (m = kT = 1): each collision rounds every new velocity to f32
    // (a random walk of ~1e-7 sqrt(steps / N) per particle: 2e-7 for these 2560 particles,
    // 3e-7 to 7e-7 measured with 640); an order-dependent or biased cell sum would drift
    // linearly, by ~1e-4 here.
    for k in 0..3 {
        let drift = (p1[k] - p0[k]).abs() / n;
        eprintln!(
            "momentum axis {k}: {} -> {} over {steps} steps of {n} particles: {drift:e} per particle",
            p0[k], p1[k]
        );
        assert!(
            drift < 1e-6,
            "axis {k}: momentum {} -> {} over {steps} steps ({drift:e} per particle)",
            p0[k],
            p1[k]
        );
    }
    // Zero total momentum at the start (the mean is removed in f32: ~1e-7 per particle).
    assert!(p0.iter().all(|p| p.abs() / n < 1e-6), "{p0:?}");
    // The averaged output agrees with the conserved value.
    let avg = end["momentum"].data.to_f64();
    for k in 0..3 {
        assert!(
            (avg[k] - p0[k]).abs() / n < 1e-6,
            "mean momentum {avg:?} vs {p0:?}"
        );
    }
    // SRD conserves energy too: the 3D rotation is two reflections, each norm-preserving
    // up to unbiased f32 rounding, so the energy random-walks (~4e-7 expected, 8e-7
    // measured with 640 particles); Rodrigues' formula with an f32 axis drifted by 4e-4.
    let (e0, e1) = (energy(&start["velocities"]), energy(&end["velocities"]));
    eprintln!("energy {e0} -> {e1}: relative {:e}", e1 / e0 - 1.0);
    assert!((e1 / e0 - 1.0).abs() < 1e-5, "energy {e0} -> {e1}");
}

#[test]
fn initial_state_is_uniform_and_maxwell_boltzmann_with_zero_momentum() {
    if gpu().is_none() {
        return;
    }
    let params = r#"{"box": [12, 10, 8], "density": 5, "temperature": 2, "mass": 0.5, "seed": 3, "stream": 0}"#;
    let (out, r) = crate::util::run_node_and_reference("mpcd_init", params, &[]);
    let n = 12 * 10 * 8 * 5;
    assert_eq!(out["positions"].ty, ValueType::Particles { n, k: 3 });
    // Against the f64 reference (the same Philox draws): f32 uniform positions are exact
    // up to the final rounding; normals differ by the f32 log/sqrt/cos (~1e-6 of 4 sigma).
    for (port, r, tol) in [("positions", &r[0], 1e-6), ("velocities", &r[1], 2e-5)] {
        let g = out[port].data.to_f64();
        let worst = g
            .iter()
            .zip(&r.data)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(worst < tol, "{port}: {worst}");
    }
    let x = rows(&out["positions"], 3);
    let v = rows(&out["velocities"], 3);
    let l = [12.0, 10.0, 8.0];
    // Uniform: every axis inside the box with mean ~0 (sd L / sqrt(12 N) = 0.05 at most);
    // kT / m = 4 per component (relative sd sqrt(2 / N) = 2.5%), mean exactly removed.
    for a in 0..3 {
        assert!(x.iter().all(|p| p[a] >= -l[a] / 2.0 && p[a] < l[a] / 2.0));
        let mean: f64 = x.iter().map(|p| p[a]).sum::<f64>() / n as f64;
        assert!(mean.abs() < 0.2, "axis {a}: mean position {mean}");
        let vm: f64 = v.iter().map(|p| p[a]).sum::<f64>() / n as f64;
        assert!(vm.abs() < 1e-6, "axis {a}: mean velocity {vm}");
        let var: f64 = v.iter().map(|p| p[a] * p[a]).sum::<f64>() / n as f64;
        assert!(
            (var / 4.0 - 1.0).abs() < 0.1,
            "axis {a}: <v^2> {var} vs kT/m = 4"
        );
    }
}

#[test]
fn measure_and_average_match_their_f64_references() {
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("mpcd-measure");
    let mut rng = Rng::new(11);
    let l = vec![6.0, 5.0, 4.0];
    let n = 1500;
    let (x, v) = random_particles(&mut rng, n, &l);
    let geometry = r#""box": [6, 5, 4], "walls": "plates", "temperature": 1.3, "mass": 2"#;
    let json = format!(
        r#"{{"mesoflow": 1,
  "inputs": {{"x": {{"type": "particles", "rows": {n}, "cols": 3}}, "v": {{"type": "particles", "rows": {n}, "cols": 3}}}},
  "nodes": [
    {{"id": "bin", "kind": "mpcd_bin", "params": {{{geometry}, "shift": false}}, "inputs": {{"positions": "inputs.x", "velocities": "inputs.v"}}}},
    {{"id": "measure", "kind": "mpcd_measure", "params": {{{geometry}, "bins": 7}}, "inputs": {{"positions": "inputs.x", "velocities": "inputs.v", "sums": "bin.sums", "cell": "bin.cell", "before": "inputs.v"}}}},
    {{"id": "average", "kind": "mpcd_average", "params": {{{geometry}, "bins": 7}}, "inputs": {{"sums": "measure.sums"}}}}
  ],
  "outputs": {{"sums": "bin.sums", "cell": "bin.cell", "acc": "measure.sums", "profile": "average.profile", "temperature": "average.temperature", "momentum": "average.momentum"}}}}"#
    );
    let g = crate::util::load(&write_graph(&dir, "measure.json", &json));
    let inputs: BTreeMap<String, HostArray> = [
        ("x".to_string(), particles(&x)),
        ("v".to_string(), particles(&v)),
    ]
    .into();
    // Three steps: the same inputs (and, unshifted, the same cells) sampled three times.
    let out = run_loaded(
        &g,
        &inputs,
        &["sums", "cell", "acc", "profile", "temperature", "momentum"],
        3,
    );
    let p = format!("{{{geometry}, \"bins\": 7}}");
    let mut acc =
        mesoflow::value::RefArray::new(out["acc"].ty, vec![0.0; out["acc"].ty.words() as usize]);
    {
        let k = registry().get("mpcd_measure").unwrap();
        let raw: BTreeMap<String, serde_json::Value> = serde_json::from_str(&p).unwrap();
        let raw = raw
            .into_iter()
            .map(|(n, v)| (n, ParamValue::from_json(&v).unwrap()))
            .collect();
        let node = k
            .build(&mesoflow::node::check_params(k.params(), &raw).unwrap())
            .unwrap();
        let ins = [
            Some(particles(&x).to_ref()),
            Some(particles(&v).to_ref()),
            Some(out["sums"].to_ref()),
            Some(out["cell"].to_ref()),
            Some(particles(&v).to_ref()),
        ];
        for step in 0..3 {
            node.cpu_reference(
                &ins,
                std::slice::from_mut(&mut acc),
                mesoflow::node::RefCtx { step },
            );
        }
    }
    let gacc = out["acc"].data.to_f64();
    // Integer words: samples and counts agree exactly; momentum and profile sums up to the
    // f32 product v * unit (above 2^24 units f32 rounds it: at most 1 unit per particle
    // and sample); the temperature sum is rounded per workgroup of cells (relative 1e-6).
    let pair = |w: &[f64], i: usize| value_of(w[i], w[i + 1]) as f64;
    assert_eq!(gacc[0], 3.0);
    for i in [1, 3, 5] {
        let (g, r) = (pair(&gacc, i), pair(&acc.data, i));
        assert!((g - r).abs() <= 3.0 * n as f64, "word {i}: {g} vs {r}");
    }
    assert!(
        (pair(&gacc, 7) / pair(&acc.data, 7) - 1.0).abs() < 1e-5,
        "temperature sum {} vs {}",
        pair(&gacc, 7),
        pair(&acc.data, 7)
    );
    assert_eq!(pair(&gacc, 9), pair(&acc.data, 9));
    for b in 0..7 {
        assert!(
            (pair(&gacc, 11 + 4 * b) - pair(&acc.data, 11 + 4 * b)).abs()
                <= pair(&acc.data, 13 + 4 * b),
            "bin {b}"
        );
        assert_eq!(
            pair(&gacc, 13 + 4 * b),
            pair(&acc.data, 13 + 4 * b),
            "bin {b} count"
        );
    }
    let r = reference("mpcd_average", &p, &[Some(&out["acc"])]);
    for (port, r) in ["profile", "temperature", "momentum"].iter().zip(&r) {
        let (e, i) = crate::util::rel_max_err(&out[*port], r);
        assert!(e < 1e-5, "{port}: {e} at {i}");
    }
    // And the averages against direct f64 sums of the inputs: momentum m sum v, profile.
    let vv = rows(&particles(&v), 3);
    let mom = out["momentum"].data.to_f64();
    for a in 0..3 {
        let direct: f64 = 2.0 * vv.iter().map(|p| p[a]).sum::<f64>();
        assert!(
            (mom[a] - direct).abs() < 1e-4 * n as f64 / 100.0,
            "momentum {a}: {} vs {direct}",
            mom[a]
        );
    }
    let xs = rows(&particles(&x), 3);
    let prof = out["profile"].data.to_f64();
    for (b, &got) in prof.iter().enumerate() {
        let sel: Vec<f64> = (0..n)
            .filter(|&p| (((xs[p][2] / 4.0 + 0.5) * 7.0).floor() as usize).min(6) == b)
            .map(|p| vv[p][0])
            .collect();
        let direct = sel.iter().sum::<f64>() / sel.len() as f64;
        assert!((got - direct).abs() < 1e-5, "bin {b}: {got} vs {direct}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_given_initial_state_is_used() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(17);
    let l = [4.0, 4.0, 4.0];
    let (x, v) = random_particles(&mut rng, 300, &l);
    let inputs: BTreeMap<String, HostArray> = [
        ("positions".to_string(), particles(&x)),
        ("velocities".to_string(), particles(&v)),
    ]
    .into();
    let g = graph::load(
        &root().join("graphs/mpcd.json"),
        registry(),
        &LoadOptions {
            overrides: [("box".to_string(), ParamValue::Numbers(l.to_vec()))].into(),
            steps: 1,
            seed: 0,
        },
    )
    .unwrap();
    let out = run_loaded(&g, &inputs, &["positions", "velocities"], 1);
    // One step: positions stream with the given velocities (dt = 0.1; collisions change
    // velocities only), and the velocities keep the given total momentum.
    let xs = rows(&out["positions"], 3);
    for p in 0..300 {
        for a in 0..3 {
            let want = x[p][a] as f32 as f64 + 0.1 * v[p][a] as f32 as f64;
            let want = want - 4.0 * (want / 4.0 + 0.5).floor();
            let diff = (xs[p][a] - want).abs();
            assert!(
                diff.min(4.0 - diff) < 1e-6,
                "particle {p}: {:?} vs {want}",
                xs[p]
            );
        }
    }
    let total = |r: &[Vec<f64>]| {
        (0..3)
            .map(|a| r.iter().map(|p| p[a]).sum::<f64>())
            .collect::<Vec<_>>()
    };
    let (p0, p1) = (
        total(&rows(&particles(&v), 3)),
        total(&rows(&out["velocities"], 3)),
    );
    for a in 0..3 {
        assert!((p0[a] - p1[a]).abs() < 1e-4, "{p0:?} vs {p1:?}");
    }
}

#[test]
fn bad_mpcd_input_gets_messages_naming_file_node_and_port() {
    let load = |sets: &[(&str, ParamValue)]| {
        crate::util::load_or_plan_error(
            &root().join("graphs/mpcd.json"),
            sets.iter()
                .map(|(k, v)| (k.to_string(), v.clone()))
                .collect(),
        )
        .unwrap_or_default()
    };
    let e = load(&[("box", ParamValue::Numbers(vec![10.5, 10.0, 10.0]))]);
    assert!(
        e.contains("mpcd.json")
            && e.contains("node `stream_bin`")
            && e.contains("not a whole number of cells"),
        "{e}"
    );
    // Plates take the biased rule (one more layer of cells), with L/a even too.
    let e = load(&[
        ("rule", ParamValue::Text("biased".into())),
        ("walls", ParamValue::Text("plates".into())),
    ]);
    assert!(e.is_empty(), "{e}");
    let e = load(&[
        ("rule", ParamValue::Text("biased".into())),
        ("walls", ParamValue::Text("plates".into())),
        ("box", ParamValue::Numbers(vec![16.0, 16.0, 15.0])),
    ]);
    assert!(
        e.contains("node `collide`") && e.contains("even number of cells") && e.contains("15"),
        "{e}"
    );
    let e = load(&[
        ("rule", ParamValue::Text("biased".into())),
        ("box", ParamValue::Numbers(vec![15.0, 16.0, 16.0])),
    ]);
    assert!(e.contains("even number of cells"), "{e}");
    let e = load(&[
        ("thermostat", ParamValue::Text("rescale".into())),
        ("temperature", ParamValue::Number(0.0)),
    ]);
    assert!(
        e.contains("node `collide`") && e.contains("temperature > 0"),
        "{e}"
    );
    // Cell sums of another grid: the collision names its port and the likely cause.
    let dir = tmpdir("mpcd-errors");
    let json = r#"{"mesoflow": 1,
  "inputs": {"x": {"type": "particles", "rows": 10, "cols": 3}, "v": {"type": "particles", "rows": 10, "cols": 3}},
  "nodes": [
    {"id": "bin", "kind": "mpcd_bin", "params": {"box": [4, 4, 4]}, "inputs": {"positions": "inputs.x", "velocities": "inputs.v"}},
    {"id": "collide", "kind": "mpcd_collide", "params": {"box": [4, 4, 6]}, "inputs": {"velocities": "inputs.v", "cell": "bin.cell", "sums": "bin.sums"}}
  ],
  "outputs": {"v": "collide.velocities"}}"#;
    let g = crate::util::load(&write_graph(&dir, "bad.json", json));
    let caps = mesoflow::gpu::DeviceCaps::baseline();
    let e = plan::plan(
        &g,
        &PlanOptions {
            outputs: None,
            inputs: g.declared_input_types(),
            fuse: true,
            in_place: true,
        },
        &caps,
    )
    .err()
    .map(|e| e.to_string())
    .unwrap_or_default();
    assert!(
        e.contains("bad.json")
            && e.contains("node `collide`")
            && e.contains("sums")
            && e.contains("same box"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
