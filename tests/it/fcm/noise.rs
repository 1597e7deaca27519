//! Fluctuations: fcm.json's noise added to the velocities, its covariance against the
//! mobility (fluctuation-dissipation), the Fourier noise's Hermitian symmetry and fresh
//! draws; Brownian diffusion in bd_fcm.json and the colloids demo against Hasimoto.

use std::collections::BTreeMap;
use std::f64::consts::PI;

use mesoflow::expr::ParamValue;
use mesoflow::graph::{self, LoadOptions};
use mesoflow::value::{HostArray, ValueType};

use crate::util::mobility::{
    axis_mobilities, eval, hasimoto, mobility_plan, noise_statistics, random_positions,
};
use crate::util::{
    Rng, compile_cached, gpu, load_with, particles, registry, root, run_cached, vectors,
};

#[test]
fn fluctuating_velocities_add_the_same_noise() {
    let Some(gpu) = gpu() else { return };
    let l = 12.0;
    let sets = [("box", "[12, 12, 12]"), ("noise_scale", "0.7")];
    let outputs = ["velocities", "noise", "fluctuating_velocities"];
    let mut rng = Rng::new(19);
    let x = random_positions(&mut rng, 20, [l; 3]);
    let f: Vec<[f64; 3]> = (0..20)
        .map(|_| [0, 1, 2].map(|_| rng.uniform(-1.0, 1.0)))
        .collect();
    let run = |seed: u64| {
        let g = load_with("fcm.json", &sets, 1, seed);
        let plan = mobility_plan(&gpu, &g, 20, false, &outputs);
        let mut fcm = compile_cached(&gpu, &g, &plan);
        eval(&mut fcm, &x, &f, None)
    };
    let a = run(5);
    let b = run(5);
    let c = run(6);
    let biggest = a["noise"]
        .iter()
        .flatten()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(biggest > 0.0);
    for i in 0..20 {
        for k in 0..3 {
            let combined = a["velocities"][i][k] + 0.7 * a["noise"][i][k];
            assert!(
                (a["fluctuating_velocities"][i][k] - combined).abs() <= 1e-5 * biggest,
                "particle {i} axis {k}: {} vs {combined}",
                a["fluctuating_velocities"][i][k]
            );
            // The same seed draws the same noise; another seed other noise.
            assert_eq!(a["noise"][i][k], b["noise"][i][k]);
        }
    }
    let differs = (0..20).filter(|&i| a["noise"][i] != c["noise"][i]).count();
    assert_eq!(differs, 20, "seed 6 repeated seed 5's noise");
}

/// Fluctuation-dissipation: over many steps (fresh draws each) the noise M^(1/2) W has
/// covariance M, for a single particle's variance and between two close particles.
#[test]
fn noise_covariance_is_the_mobility() {
    let Some(gpu) = gpu() else { return };
    let sets = r#"{"box": [8, 8, 8], "tolerance": 0.01}"#;
    let x = vec![[0.3, -1.1, 2.0], [1.6, -0.6, 2.4]];
    // M from the deterministic path of the same graph.
    let g = load_with(
        "fcm.json",
        &[("box", "[8, 8, 8]"), ("tolerance", "0.01")],
        1,
        0,
    );
    let plan = mobility_plan(&gpu, &g, 2, false, &["velocities"]);
    let mut fcm = compile_cached(&gpu, &g, &plan);
    let m = axis_mobilities(&mut fcm, &x);
    drop(fcm);
    let steps = 12_000u64;
    let (sq, pair) = noise_statistics(&gpu, "fcm.json", sets, &x, steps, 11);
    let s = steps as f64;
    // A variance estimated from s normal samples has relative standard deviation sqrt(2/s)
    // (1.3 % here); 5 of them is the bound.
    let bound = 5.0 * (2.0 / s).sqrt();
    for a in 0..3 {
        for i in 0..2 {
            let var = sq[i][a] / s;
            let want = m[i][i][a];
            eprintln!("particle {i} axis {a}: variance / M = {}", var / want);
            assert!(
                (var / want - 1.0).abs() <= bound,
                "particle {i} axis {a}: variance {var} vs M {want}"
            );
        }
        // var(n0 + n1) = M00 + M11 + 2 M01: the covariance between the particles.
        let var = pair[a] / s;
        let want = m[0][0][a] + m[1][1][a] + m[0][1][a] + m[1][0][a];
        eprintln!("axis {a}: variance of the sum / M = {}", var / want);
        assert!(
            (var / want - 1.0).abs() <= bound,
            "axis {a}: variance of the sum {var} vs {want}"
        );
    }
}

/// Free Brownian particles in bd_fcm.json: the mean squared displacement per axis grows as
/// 2 kT M_self t (M_self is Hasimoto's, whatever the other particles do).
#[test]
fn free_particles_diffuse_with_the_self_mobility() {
    let Some(gpu) = gpu() else { return };
    let (l, n, dt, kt) = (16.0, 64usize, 0.05, 1.5);
    let steps = 240u64;
    let g = graph::load(
        &root().join("graphs/bd_fcm.json"),
        registry(),
        &LoadOptions {
            overrides: [
                ("box", ParamValue::Numbers(vec![l; 3])),
                ("tolerance", ParamValue::Number(1e-2)),
                ("dt", ParamValue::Number(dt)),
                ("temperature", ParamValue::Number(kt)),
                ("save_every", ParamValue::Number(1.0)),
            ]
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect(),
            steps,
            seed: 4,
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let mut rng = Rng::new(23);
    let x0 = random_positions(&mut rng, n, [l; 3]);
    let inputs: BTreeMap<String, HostArray> = [("positions".to_string(), particles(&x0))].into();
    let (out, _) = run_cached(&gpu, &g, &inputs, None, steps, true);
    assert_eq!(
        out["trajectory"].ty,
        ValueType::Frames {
            frames: steps as u32,
            n: n as u32,
            k: 3
        }
    );
    let traj = out["trajectory"].data.to_f64();
    let frame = |t: usize, i: usize, a: usize| -> f64 {
        if t == 0 {
            x0[i][a]
        } else {
            traj[((t - 1) * n + i) * 3 + a]
        }
    };
    // The last frame is the final state.
    let last = vectors(&out["positions"]);
    assert_eq!(last[5][1], frame(steps as usize, 5, 1));
    let mobility = hasimoto(1.0, l) / (6.0 * PI);
    for lag in [1usize, 8, 40] {
        let mut sum = 0.0;
        let mut count = 0.0;
        for t in 0..=(steps as usize - lag) {
            for i in 0..n {
                for a in 0..3 {
                    let d = frame(t + lag, i, a) - frame(t, i, a);
                    sum += d * d;
                    count += 1.0;
                }
            }
        }
        let msd = sum / count;
        let want = 2.0 * kt * mobility * dt * lag as f64;
        // Independent samples: n * 3 per window of `lag` steps (hydrodynamic correlations
        // between particles are weak at this density); 5 standard deviations.
        let independent = (n * 3) as f64 * (steps as f64 / lag as f64);
        let bound = 5.0 * (2.0 / independent).sqrt();
        eprintln!("MSD lag {lag}: {msd:e} vs 2 kT M t = {want:e} (bound {bound:e})");
        assert!(
            (msd / want - 1.0).abs() <= bound,
            "lag {lag}: MSD {msd} vs {want}"
        );
    }
}

/// The README's main job (graphs/examples/colloids.json) measures the self-diffusion
/// coefficient from its own initial positions (kept in state: random nodes draw afresh
/// every step) and reports kT times Hasimoto's self-mobility as theory.
#[test]
fn colloids_demo_measures_the_self_diffusion() {
    let Some(gpu) = gpu() else { return };
    let (n, side, steps) = (1000usize, 24.0, 200u64);
    let g = graph::load(
        &root().join("graphs/examples/colloids.json"),
        registry(),
        &LoadOptions {
            overrides: [
                ("n", ParamValue::Number(n as f64)),
                ("side", ParamValue::Number(side)),
                ("tolerance", ParamValue::Number(1e-2)),
            ]
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect(),
            steps,
            seed: 3,
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let out = crate::util::run_graph(&gpu, &g, &BTreeMap::new(), None, steps, true);
    let theory = out["theory"].data.to_f64()[0];
    let want = hasimoto(1.0, side) / (6.0 * PI);
    assert!((theory - want).abs() <= 1e-6 * want, "{theory} vs {want}");
    // Relative standard errors per axis: independent particles plus the Oseen correlation
    // of pairs (graphs/examples/colloids.json's doc); steps are independent samples for
    // the per-step estimate. 5 standard deviations.
    let var = 2.0 / n as f64 + 13.2 / (side * side);
    for (name, bound) in [
        ("diffusion", 5.0 * (var / steps as f64).sqrt()),
        ("diffusion_msd", 5.0 * var.sqrt()),
    ] {
        let d = out[name].data.to_f64();
        eprintln!("colloids: {name} = {d:?}, theory {theory:e}, bound {bound:e} per axis");
        for (a, &da) in d.iter().enumerate() {
            assert!(
                (da / theory - 1.0).abs() <= bound,
                "{name} axis {a}: {da:e} vs {theory:e}"
            );
        }
    }
}

/// The noise spectrum is the half spectrum of a real field (its inverse transform and
/// forward transform give it back), and each step draws anew (step 1 against the f64
/// reference at step 1).
#[test]
fn fourier_noise_is_hermitian_and_fresh_every_step() {
    let Some(gpu) = gpu() else { return };
    let params =
        r#"{"box": [2, 1.5, 1], "grid": [8, 6, 5], "viscosity": 0.8, "noise": 0.3, "seed": 9}"#;
    let json = format!(
        r#"{{"mesoflow": 1, "nodes": [
            {{"id": "n", "kind": "stokes_noise", "params": {params}}},
            {{"id": "i", "kind": "irfft", "inputs": {{"x": "n.out"}}}},
            {{"id": "f", "kind": "rfft", "inputs": {{"x": "i.out"}}}}],
          "outputs": {{"noise": "n.out", "back": "f.out"}}}}"#
    );
    let dir = crate::util::tmpdir("fcm-noise");
    let g = crate::util::load(&crate::util::write_graph(&dir, "g.json", &json));
    let out = crate::util::run_graph(&gpu, &g, &BTreeMap::new(), None, 2, true);
    let noise = out["noise"].data.to_f64();
    let back = out["back"].data.to_f64();
    let norm = noise.iter().map(|x| x * x).sum::<f64>().sqrt();
    let diff = noise
        .iter()
        .zip(&back)
        .map(|(a, b)| (a - b) * (a - b))
        .sum::<f64>()
        .sqrt();
    assert!(diff <= 1e-5 * norm, "not Hermitian: {diff:e} of {norm:e}");
    // After 2 steps the output holds step 1's draw.
    let kind = registry().get("stokes_noise").unwrap();
    let raw: BTreeMap<String, serde_json::Value> = serde_json::from_str(params).unwrap();
    let raw = raw
        .into_iter()
        .map(|(k, v)| (k, ParamValue::from_json(&v).unwrap()))
        .collect();
    let node = kind
        .build(&mesoflow::node::check_params(kind.params(), &raw).unwrap())
        .unwrap();
    let ty = out["noise"].ty;
    let mut want = vec![mesoflow::value::RefArray::new(
        ty,
        vec![0.0; ty.words() as usize],
    )];
    node.cpu_reference(&[], &mut want, mesoflow::node::RefCtx { step: 1 });
    let (e, at) = crate::util::rel_max_err(&out["noise"], &want[0]);
    assert!(e <= 2e-6, "step 1: {e:e} at {at}");
    let mut step0 = want.clone();
    node.cpu_reference(&[], &mut step0, mesoflow::node::RefCtx { step: 0 });
    let (e, _) = crate::util::rel_max_err(&out["noise"], &step0[0]);
    assert!(e > 0.1, "step 1 repeated step 0's draw");
}
