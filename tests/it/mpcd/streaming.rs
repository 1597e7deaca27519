//! Streaming: trajectories between plates and in a periodic box against an f64 event
//! schedule; mpcd_stream_bin bit for bit against streaming then binning; reordering the
//! particles by cell changes only their order; the fused graph runs like the unfused one.

use std::collections::BTreeMap;

use mesoflow::graph::Graph;
use mesoflow::value::HostArray;

use crate::util::mpcd::{random_particles, run_graph_file, run_loaded, run_mpcd};
use crate::util::{Rng, gpu, particles, reference, rows, tmpdir, u32s, write_graph};

/// Independent f64 reference for plates: the whole duration at once from the schedule of
/// wall crossings of the unforced wall-normal motion (crossing j at t0 + j L / |v_z|),
/// velocity flipped (all components for bounce-back, v_z for specular) at each crossing,
/// the force along x acting in between; then x and y wrapped.
fn plates_reference(
    x: &[f64],
    v: &[f64],
    l: [f64; 3],
    g: f64,
    t: f64,
    slip: bool,
) -> (Vec<f64>, Vec<f64>) {
    let h = l[2] / 2.0;
    let mut x = x.to_vec();
    let mut v = v.to_vec();
    let mut crossings = Vec::new();
    if v[2] != 0.0 {
        let first = if v[2] > 0.0 {
            (h - x[2]) / v[2]
        } else {
            (-h - x[2]) / v[2]
        };
        let period = l[2] / v[2].abs();
        let mut j = 0.0;
        while first + j * period < t {
            crossings.push(first + j * period);
            j += 1.0;
        }
    }
    let mut now = 0.0;
    for &tc in crossings.iter().chain(std::iter::once(&t)) {
        let dt = tc - now;
        for a in 0..3 {
            x[a] += v[a] * dt;
        }
        x[0] += 0.5 * g * dt * dt;
        v[0] += g * dt;
        now = tc;
        if tc < t {
            if slip {
                v[2] = -v[2];
            } else {
                v.iter_mut().for_each(|c| *c = -*c);
            }
        }
    }
    for a in 0..2 {
        x[a] -= l[a] * (x[a] / l[a] + 0.5).floor();
    }
    (x, v)
}

fn stream_graph(dir: &std::path::Path, n: usize, params: &str) -> Graph {
    let json = format!(
        r#"{{"mesoflow": 1,
  "inputs": {{"x": {{"type": "particles", "rows": {n}, "cols": 3}}, "v": {{"type": "particles", "rows": {n}, "cols": 3}}}},
  "state": {{"x": {{"init": "inputs.x", "next": "s.positions"}}, "v": {{"init": "inputs.v", "next": "s.velocities"}}}},
  "nodes": [{{"id": "s", "kind": "mpcd_stream", "params": {params}, "inputs": {{"positions": "state.x", "velocities": "state.v"}}}}],
  "outputs": {{"x": "state.x", "v": "state.v"}}}}"#
    );
    crate::util::load(&write_graph(dir, "stream.json", &json))
}

#[test]
fn streaming_and_wall_trajectories_match_an_f64_event_schedule() {
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("mpcd-stream");
    let l = [4.0, 4.0, 4.0];
    let (dt, steps, force) = (0.25, 6u64, 0.4);
    // A handful of particles: one hitting the top plate in the first step, one the bottom,
    // one parallel to the plates crossing the periodic x and y faces, one fast enough to
    // cross the gap within a step (|v_z| dt = 5 > L_z), one starting on a plate, and one
    // almost at rest.
    let x0 = vec![
        vec![0.3, -0.2, 1.8],
        vec![-1.0, 1.5, -1.7],
        vec![1.9, -1.95, 0.5],
        vec![0.0, 0.0, 0.0],
        vec![1.0, 1.0, 2.0],
        vec![-0.5, 0.5, 0.25],
    ];
    let v0 = vec![
        vec![0.5, -0.3, 1.0],
        vec![-0.2, 0.7, -2.0],
        vec![1.3, -0.9, 0.0],
        vec![0.3, 0.1, 20.0],
        vec![-0.4, 0.2, 0.6],
        vec![0.01, -0.02, 0.03],
    ];
    let inputs: BTreeMap<String, HostArray> = [
        ("x".to_string(), particles(&x0)),
        ("v".to_string(), particles(&v0)),
    ]
    .into();
    for slip in [false, true] {
        let params = format!(
            r#"{{"box": [4, 4, 4], "walls": "plates", "wall_bc": "{}", "dt": {dt}, "force": {force}, "mass": 2}}"#,
            if slip { "slip" } else { "no_slip" }
        );
        let g = stream_graph(&dir, x0.len(), &params);
        let out = run_loaded(&g, &inputs, &["x", "v"], steps);
        let (xs, vs) = (rows(&out["x"], 3), rows(&out["v"], 3));
        for p in 0..x0.len() {
            let (xr, vr) =
                plates_reference(&x0[p], &v0[p], l, force / 2.0, dt * steps as f64, slip);
            for a in 0..3 {
                // f32 positions of size <= 2 after ~20 operations: a few 1e-6; the fast
                // particle's many crossings lose a little more.
                assert!(
                    (xs[p][a] - xr[a]).abs() < 2e-5,
                    "slip {slip} particle {p} x: {:?} vs {xr:?}",
                    xs[p]
                );
                assert!(
                    (vs[p][a] - vr[a]).abs() < 2e-5,
                    "slip {slip} particle {p} v: {:?} vs {vr:?}",
                    vs[p]
                );
            }
            assert!(xs[p][2].abs() <= 2.0 && xs[p][0].abs() <= 2.0 && xs[p][1].abs() <= 2.0);
        }
        // A hand-checked case: particle 0 meets the top plate at t = 0.2, within the first
        // step, and for no slip has v = -(0.5 + 0.2 g, -0.3, 1) afterwards.
        let one = run_loaded(&g, &inputs, &["x", "v"], 1);
        let v1 = rows(&one["v"], 3);
        let x1 = rows(&one["x"], 3);
        assert!((x1[0][2] - (2.0 - 0.05)).abs() < 1e-6, "{:?}", x1[0]);
        if !slip {
            assert!(
                (v1[0][0] - (-(0.5 + 0.2 * 0.2) + 0.2 * 0.05)).abs() < 1e-6,
                "{:?}",
                v1[0]
            );
            assert!((v1[0][2] + 1.0).abs() < 1e-6);
        } else {
            assert!((v1[0][0] - (0.5 + 0.2 * 0.25)).abs() < 1e-6, "{:?}", v1[0]);
            assert!((v1[0][2] + 1.0).abs() < 1e-6);
        }
    }
    // Periodic box with the sine force: z moves freely, so the force of step k is
    // g sin(2 pi (z0 + k v_z dt) / L) and x gains v_x dt + g dt^2 / 2 per step.
    let g = stream_graph(
        &dir,
        x0.len(),
        &format!(r#"{{"box": [4, 4, 4], "dt": {dt}, "force": {force}, "force_shape": "sine"}}"#),
    );
    let out = run_loaded(&g, &inputs, &["x", "v"], steps);
    let (xs, vs) = (rows(&out["x"], 3), rows(&out["v"], 3));
    for p in 0..x0.len() {
        let mut x = x0[p].clone();
        let mut vx = v0[p][0];
        for k in 0..steps {
            let z = x0[p][2] + k as f64 * v0[p][2] * dt;
            let gk = force * (2.0 * std::f64::consts::PI * z / 4.0).sin();
            x[0] += vx * dt + 0.5 * gk * dt * dt;
            vx += gk * dt;
        }
        x[1] += v0[p][1] * dt * steps as f64;
        x[2] += v0[p][2] * dt * steps as f64;
        for a in 0..3 {
            let wrapped = x[a] - 4.0 * (x[a] / 4.0 + 0.5).floor();
            // Unwrapped z of the fast particle reaches 30: f32 sine arguments lose ~1e-5.
            let d = (xs[p][a] - wrapped).abs();
            assert!(
                d.min(4.0 - d) < 5e-5,
                "sine particle {p}: {:?} vs {wrapped}",
                xs[p]
            );
        }
        assert!(
            (vs[p][0] - vx).abs() < 5e-5,
            "sine particle {p} v_x {} vs {vx}",
            vs[p][0]
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The bit patterns of an output's words, for comparisons that must be exact.
fn bits(a: &HostArray) -> Vec<u64> {
    a.data.to_f64().iter().map(|f| f.to_bits()).collect()
}

/// Reordering the particles by cell (sort_every) changes only the order of the state:
/// streaming is per particle, the cell sums are exact integers and the random draws are
/// per cell, so the set of (position, velocity) rows after any number of steps is the
/// same, bit for bit, with or without it (plates and a force included).
#[test]
fn sorting_particles_by_cell_changes_only_their_order() {
    if gpu().is_none() {
        return;
    }
    let sets = [
        ("box", "[6, 6, 6]"),
        ("density", "5"),
        ("walls", "\"plates\""),
        ("force", "0.05"),
        ("thermostat", "\"monte_carlo\""),
    ];
    let state = |sort: &str| {
        let mut s = sets.to_vec();
        s.push(("sort_every", sort));
        let out = run_mpcd(&s, 25, 3, &["positions", "velocities"]);
        let x = rows(&out["positions"], 3);
        let v = rows(&out["velocities"], 3);
        let mut r: Vec<Vec<u32>> = x
            .iter()
            .zip(&v)
            .map(|(a, b)| a.iter().chain(b).map(|&f| (f as f32).to_bits()).collect())
            .collect();
        r.sort();
        (r, x)
    };
    let (plain, plain_x) = state("0");
    let (sorted, sorted_x) = state("3");
    assert_eq!(plain.len(), 6 * 6 * 6 * 5);
    assert_eq!(plain, sorted, "the same particles");
    assert_ne!(plain_x, sorted_x, "in another order");
}

#[test]
fn stream_bin_is_stream_then_bin_bitwise() {
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("mpcd-stream-bin");
    let mut rng = Rng::new(41);
    // (box, walls, wall_bc, force shape, thermostat, atomics)
    let cases = [
        (
            vec![6.0, 5.0, 4.0],
            "none",
            "no_slip",
            "sine",
            "none",
            "auto",
        ),
        (
            vec![6.0, 5.0, 4.0],
            "plates",
            "slip",
            "constant",
            "rescale",
            "int32",
        ),
        (
            vec![8.0, 6.0],
            "plates",
            "no_slip",
            "constant",
            "monte_carlo",
            "auto",
        ),
    ];
    for (l, walls, wall_bc, shape, thermostat, atomics) in cases {
        let d = l.len();
        let n = 2500;
        let (x, mut v) = random_particles(&mut rng, n, &l);
        // Fast particles too: several wall crossings in one step.
        for row in v.iter_mut().take(50) {
            row.iter_mut().for_each(|c| *c *= 40.0);
        }
        let common = format!(r#""box": {l:?}, "cell": 1, "walls": "{walls}", "mass": 1.5"#);
        let stream = format!(
            r#"{common}, "wall_bc": "{wall_bc}", "dt": 0.1, "force": 0.3, "force_shape": "{shape}""#
        );
        let bin = format!(
            r#"{common}, "temperature": 1.2, "thermostat": "{thermostat}", "atomics": "{atomics}", "seed": 9, "stream": 2"#
        );
        let json = format!(
            r#"{{"mesoflow": 1,
  "inputs": {{"x": {{"type": "particles", "rows": {n}, "cols": {d}}}, "v": {{"type": "particles", "rows": {n}, "cols": {d}}}}},
  "nodes": [
    {{"id": "stream", "kind": "mpcd_stream", "params": {{{stream}}}, "inputs": {{"positions": "inputs.x", "velocities": "inputs.v"}}}},
    {{"id": "bin", "kind": "mpcd_bin", "params": {{{bin}}}, "inputs": {{"positions": "stream.positions", "velocities": "stream.velocities"}}}},
    {{"id": "both", "kind": "mpcd_stream_bin", "params": {{{stream}, "temperature": 1.2, "thermostat": "{thermostat}", "atomics": "{atomics}", "seed": 9, "stream": 2}}, "inputs": {{"positions": "inputs.x", "velocities": "inputs.v"}}}}
  ],
  "outputs": {{"x1": "stream.positions", "v1": "stream.velocities", "c1": "bin.cell", "s1": "bin.sums",
              "x2": "both.positions", "v2": "both.velocities", "c2": "both.cell", "s2": "both.sums"}}}}"#
        );
        let g = crate::util::load(&write_graph(&dir, "stream_bin.json", &json));
        let inputs: BTreeMap<String, HostArray> = [
            ("x".to_string(), particles(&x)),
            ("v".to_string(), particles(&v)),
        ]
        .into();
        let out = run_loaded(
            &g,
            &inputs,
            &["x1", "v1", "c1", "s1", "x2", "v2", "c2", "s2"],
            1,
        );
        for (a, b) in [("x1", "x2"), ("v1", "v2"), ("c1", "c2"), ("s1", "s2")] {
            assert_eq!(
                bits(&out[a]),
                bits(&out[b]),
                "{walls} {d}D {thermostat}: {a} and {b} differ"
            );
        }
        // And the node's f64 reference (the two references composed) near the GPU.
        let r = reference(
            "mpcd_stream_bin",
            &format!(
                r#"{{{stream}, "temperature": 1.2, "thermostat": "{thermostat}", "seed": 9, "stream": 2}}"#
            ),
            &[Some(&particles(&x)), Some(&particles(&v))],
        );
        let (e, i) = crate::util::rel_max_err(&out["x2"], &r[0]);
        assert!(e < 1e-5, "{walls} {d}D positions: {e} at {i}");
        let cells = u32s(&out["c2"]);
        let same = cells
            .iter()
            .zip(&r[2].data)
            .filter(|(a, b)| **a as f64 == **b)
            .count();
        assert!(same >= n - 5, "{same} of {n} cells as the reference");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_fused_graph_runs_bitwise_like_the_unfused_one() {
    if gpu().is_none() {
        return;
    }
    // Plates, a force and a thermostat: every branch of streaming and binning; observables
    // too (they read the fused node's outputs).
    let sets = [
        ("box", "[6, 5, 6]"),
        ("density", "5"),
        ("walls", "\"plates\""),
        ("force", "0.05"),
        ("thermostat", "\"rescale\""),
        ("temperature", "1.1"),
    ];
    let outputs = ["positions", "velocities", "velocity_profile", "temperature"];
    let fused = run_graph_file("mpcd.json", &sets, 12, 5, &outputs);
    let unfused = run_graph_file("fixtures/mpcd_unfused.json", &sets, 12, 5, &outputs);
    for name in outputs {
        let (a, b) = (bits(&fused[name]), bits(&unfused[name]));
        assert!(!a.is_empty(), "{name}");
        assert_eq!(a, b, "{name}: the fused and unfused graphs differ");
    }
}

#[test]
fn reordering_steps_give_the_stable_cell_order_of_the_same_particles() {
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("mpcd-sort-every");
    let mut rng = Rng::new(43);
    for (l, walls, atomics) in [
        (vec![6.0, 5.0, 4.0], "none", "auto"),
        (vec![8.0, 6.0], "plates", "int32"),
    ] {
        let d = l.len();
        let n = 3000;
        let (x, v) = random_particles(&mut rng, n, &l);
        let params = format!(
            r#""box": {l:?}, "cell": 1, "walls": "{walls}", "mass": 1, "temperature": 1, "dt": 0.1, "force": 0.2, "atomics": "{atomics}", "seed": 9, "stream": 2"#
        );
        let json = format!(
            r#"{{"mesoflow": 1,
  "inputs": {{"x": {{"type": "particles", "rows": {n}, "cols": {d}}}, "v": {{"type": "particles", "rows": {n}, "cols": {d}}}}},
  "nodes": [
    {{"id": "plain", "kind": "mpcd_stream_bin", "params": {{{params}}}, "inputs": {{"positions": "inputs.x", "velocities": "inputs.v"}}}},
    {{"id": "sorted", "kind": "mpcd_stream_bin", "params": {{{params}, "sort_every": 2}}, "inputs": {{"positions": "inputs.x", "velocities": "inputs.v"}}}}
  ],
  "outputs": {{"x1": "plain.positions", "v1": "plain.velocities", "c1": "plain.cell", "s1": "plain.sums",
              "x2": "sorted.positions", "v2": "sorted.velocities", "c2": "sorted.cell", "s2": "sorted.sums"}}}}"#
        );
        let g = crate::util::load(&write_graph(&dir, "sort_every.json", &json));
        let inputs: BTreeMap<String, HostArray> = [
            ("x".to_string(), particles(&x)),
            ("v".to_string(), particles(&v)),
        ]
        .into();
        let names = ["x1", "v1", "c1", "s1", "x2", "v2", "c2", "s2"];
        // Step 0 reorders: row i of the sorted node is row perm[i] of the plain one, perm
        // the stable order of the cells; the sums are the same integers.
        let out = run_loaded(&g, &inputs, &names, 1);
        let c1 = u32s(&out["c1"]);
        let mut perm: Vec<usize> = (0..n).collect();
        perm.sort_by_key(|&i| c1[i]);
        let (x1, v1, x2, v2) = (
            bits(&out["x1"]),
            bits(&out["v1"]),
            bits(&out["x2"]),
            bits(&out["v2"]),
        );
        let c2 = u32s(&out["c2"]);
        assert!(
            c2.windows(2).all(|w| w[0] <= w[1]),
            "{walls} {d}D: cells in order"
        );
        for (i, &q) in perm.iter().enumerate() {
            assert_eq!(c2[i], c1[q], "row {i}");
            assert_eq!(
                x2[i * d..(i + 1) * d],
                x1[q * d..(q + 1) * d],
                "row {i} position"
            );
            assert_eq!(
                v2[i * d..(i + 1) * d],
                v1[q * d..(q + 1) * d],
                "row {i} velocity"
            );
        }
        assert_eq!(bits(&out["s1"]), bits(&out["s2"]), "{walls} {d}D sums");
        // Step 1 does not reorder: the same rows as the plain node.
        let out = run_loaded(&g, &inputs, &names, 2);
        for (a, b) in [("x1", "x2"), ("v1", "v2"), ("c1", "c2"), ("s1", "s2")] {
            assert_eq!(bits(&out[a]), bits(&out[b]), "{walls} {d}D step 1: {a} {b}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
