//! The `repeat` loop carrying S1's convergence loops: the flip rounds carrying the mesh
//! (reading the positions from outside) and the overlap rounds carrying the positions
//! (reading the mesh), against their f64 rounds iterated on the host; a fixed count; the
//! iteration cap as an error.

use std::collections::BTreeMap;

use mesoflow::exec::Profile;
use mesoflow::gpu::GpuContext;
use mesoflow::nodes::disks::flip::flip_round;
use mesoflow::nodes::disks::mesh::{MESH_WORDS, check_torus_mesh, periodic_delaunay};
use mesoflow::nodes::disks::overlap::vertex_fans;
use mesoflow::nodes::disks::wrap;
use mesoflow::plan::{Launch, Via};
use mesoflow::value::{HostArray, ValueType};

use crate::util::disks::{
    LoopRun, disk_graph_inputs, disk_positions, run_with_loops, run_with_loops_planned,
    run_with_loops_profiled,
};
use crate::util::{
    self, Rng, flat_particles, gpu, indices, input_decl, run_node_and_reference, u32s,
};

const L: [f64; 2] = [18.0, 16.0];

fn run(
    gpu: &GpuContext,
    json: &str,
    inputs: &BTreeMap<String, HostArray>,
    steps: u64,
) -> Result<LoopRun, String> {
    let dir = util::tmpdir("disk_loops");
    let g = util::load(&util::write_graph(&dir, "g.json", json));
    let out = run_with_loops(gpu, &g, inputs, steps);
    let _ = std::fs::remove_dir_all(&dir);
    out
}

/// The flip loop: `repeat` carrying the mesh through `edge_flip_round` (one Lawson round
/// per evaluation).
fn flip_graph(n: usize, repeat_params: &str) -> String {
    flip_graph_of_rounds(n, repeat_params, 1)
}

/// The same with `rounds` Lawson rounds per evaluation.
fn flip_graph_of_rounds(n: usize, repeat_params: &str, rounds: u32) -> String {
    let x = input_decl(&ValueType::Particles { n: n as u32, k: 2 });
    let mesh = input_decl(&ValueType::Indices {
        n: (2 * MESH_WORDS * n) as u32,
    });
    format!(
        r#"{{"mesoflow": 1, "inputs": {{"positions": {x}, "mesh": {mesh}}},
  "nodes": [
    {{"id": "flips", "kind": "repeat", "params": {repeat_params}, "inputs": {{"initial": "inputs.mesh", "next": "round.mesh", "count": "round.flips"}}}},
    {{"id": "round", "kind": "edge_flip_round", "params": {{"box": [{}, {}], "rounds": {rounds}}}, "inputs": {{"positions": "inputs.positions", "mesh": "flips.current"}}}}
  ],
  "outputs": {{"mesh": {{"from": "flips.out"}}, "iterations": {{"from": "flips.iterations"}}, "flips": {{"from": "flips.total"}}}}
}}"#,
        L[0], L[1]
    )
}

/// 300 disks, their Delaunay mesh, then moved (as in disks::flip): positions and mesh.
fn moved_disks(seed: u64) -> (Vec<f64>, Vec<u32>) {
    let mut rng = Rng::new(seed);
    let x0 = disk_positions(&mut rng, 300, L, 0.7);
    let mesh = periodic_delaunay(&x0, L).unwrap();
    let x = x0
        .iter()
        .enumerate()
        .map(|(i, v)| wrap(v + rng.uniform(-0.2, 0.2), L[i % 2]) as f32 as f64)
        .collect();
    (x, mesh)
}

/// The ids of the nodes the plan runs in the body of the graph's loop.
fn loop_body(gpu: &GpuContext, json: &str, inputs: &BTreeMap<String, HostArray>) -> Vec<String> {
    let dir = util::tmpdir("disk_loop_body");
    let g = util::load(&util::write_graph(&dir, "g.json", json));
    let _ = std::fs::remove_dir_all(&dir);
    let types = inputs.iter().map(|(k, v)| (k.clone(), v.ty)).collect();
    let plan = util::plan_graph(&gpu.caps, &g, types, None, true);
    let mut ids = Vec::new();
    for launch in &plan.step {
        if let Launch::Loop { body, .. } = launch {
            for b in body {
                if let Launch::Node { node, .. } = b {
                    ids.push(g.nodes[*node].id.clone());
                }
            }
        }
    }
    ids
}

/// The f64 rounds until one flips nothing (or `fixed` rounds): the mesh, the rounds run
/// and the flips made.
fn host_flips(x: &[f64], mesh: &[u32], fixed: usize) -> (Vec<u32>, u32, u32) {
    let (mut m, mut rounds, mut total) = (mesh.to_vec(), 0, 0);
    loop {
        let (next, flips) = flip_round(&m, x, L, 1e-5);
        m = next;
        rounds += 1;
        total += flips;
        if (fixed == 0 && flips == 0) || rounds as usize == fixed {
            return (m, rounds, total);
        }
    }
}

/// Until no edge flips: the mesh, the rounds (the last flipping nothing) and the flips
/// equal the f64 rounds iterated on the host; two steps, each from the given mesh; the
/// same whether the loop runs in a step or is timed alone (profiles), whatever the
/// executor ran ahead of its decisions.
#[test]
fn repeat_carries_the_mesh_through_the_flip_rounds() {
    let Some(gpu) = gpu() else { return };
    let (x, mesh) = moved_disks(31);
    let (want, rounds, total) = host_flips(&x, &mesh, 0);
    assert!(rounds >= 3 && total > 10, "{rounds} rounds, {total} flips");
    let dir = util::tmpdir("disk_loops_profiled");
    let g = util::load(&util::write_graph(&dir, "g.json", &flip_graph(300, "{}")));
    for profile in [Profile::Off, Profile::Launches] {
        let (out, loops) =
            run_with_loops_profiled(&gpu, &g, &disk_graph_inputs(&x, &mesh, []), 2, profile)
                .unwrap();
        assert_eq!(u32s(&out["mesh"]), want, "{profile:?}");
        assert_eq!(u32s(&out["iterations"]), vec![rounds], "{profile:?}");
        assert_eq!(u32s(&out["flips"]), vec![total], "{profile:?}");
        assert_eq!(
            loops,
            vec![("flips".to_string(), vec![rounds, rounds])],
            "{profile:?}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
    let stats = check_torus_mesh(&want, &x, L).unwrap();
    assert_eq!(stats.inverted, 0);
}

/// The flip loop with the mesh written in place (the plan gives `edge_flip_round`'s
/// output the buffer of the loop's `current`: no copies) and copied (in place refused,
/// `PlanOptions::in_place` off): the mesh, the flips and the iterations bit for bit the
/// same, and the f64 rounds', for one Lawson round per evaluation and four, stopping on
/// either word of the count, two steps each from the given mesh, unprofiled and timed
/// alone.
#[test]
fn the_flip_loop_is_the_same_in_place_or_copied() {
    let Some(gpu) = gpu() else { return };
    let (x, mesh) = moved_disks(31);
    let (want, rounds, total) = host_flips(&x, &mesh, 0);
    let dir = util::tmpdir("disk_loops_in_place");
    for (r, stop_word) in [(1, 0), (4, 1)] {
        let params = format!(r#"{{"stop_word": {stop_word}}}"#);
        let json = flip_graph_of_rounds(300, &params, r);
        let g = util::load(&util::write_graph(&dir, "g.json", &json));
        let types = disk_graph_inputs(&x, &mesh, [])
            .iter()
            .map(|(k, v)| (k.clone(), v.ty))
            .collect();
        let p = util::plan_graph(&gpu.caps, &g, types, None, true);
        // The flip writes in place, the loop ends where the mesh lies (the output's
        // buffer); it starts from a graph input, which it copies.
        let vias: Vec<Via> = p.in_place.iter().map(|a| a.via).collect();
        assert_eq!(vias, [Via::Node, Via::Finish], "the flip writes in place");
        let iterations = if stop_word == 0 {
            (rounds - 1).div_ceil(r) + 1
        } else {
            rounds.div_ceil(r)
        };
        for profile in [Profile::Off, Profile::Launches] {
            let runs: Vec<LoopRun> = [true, false]
                .map(|in_place| {
                    run_with_loops_planned(
                        &gpu,
                        &g,
                        &disk_graph_inputs(&x, &mesh, []),
                        2,
                        profile,
                        in_place,
                    )
                    .unwrap()
                })
                .into();
            let case = format!("{r} rounds, stop_word {stop_word}, {profile:?}");
            for (name, a) in &runs[0].0 {
                assert_eq!(a.data, runs[1].0[name].data, "{case}: {name}");
            }
            assert_eq!(runs[0].1, runs[1].1, "{case}: iterations");
            let (out, loops) = &runs[0];
            assert_eq!(u32s(&out["mesh"]), want, "{case}");
            assert_eq!(u32s(&out["iterations"]), vec![iterations], "{case}");
            assert_eq!(u32s(&out["flips"]), vec![total], "{case}");
            assert_eq!(
                loops,
                &vec![("flips".to_string(), vec![iterations; 2])],
                "{case}"
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Stopping on the flips of an evaluation's last round (`stop_word` 1): with r Lawson
/// rounds per evaluation, a cascade of R single rounds (the last flipping nothing) ends
/// after ceil(R / r) evaluations, where stopping on all the evaluation's flips (word 0)
/// takes ceil((R - 1) / r) + 1, one more whenever r divides R - 1; the mesh and the flips
/// counted are the same either way.
#[test]
fn repeat_stops_on_the_last_rounds_flips() {
    let Some(gpu) = gpu() else { return };
    let (x, mesh) = moved_disks(31);
    let (want, rounds, total) = host_flips(&x, &mesh, 0);
    for r in [1u32, 2, 3] {
        for (stop_word, iterations) in [(0, (rounds - 1).div_ceil(r) + 1), (1, rounds.div_ceil(r))]
        {
            let params = format!(r#"{{"stop_word": {stop_word}}}"#);
            let (out, _) = run(
                &gpu,
                &flip_graph_of_rounds(300, &params, r),
                &disk_graph_inputs(&x, &mesh, []),
                1,
            )
            .unwrap();
            let case = format!("{r} rounds, stop_word {stop_word}");
            assert_eq!(u32s(&out["mesh"]), want, "{case}");
            assert_eq!(u32s(&out["iterations"]), vec![iterations], "{case}");
            assert_eq!(u32s(&out["flips"]), vec![total], "{case}");
        }
    }
    // The flips are two words: there is no word 2.
    let e = run(
        &gpu,
        &flip_graph(300, r#"{"stop_word": 2}"#),
        &disk_graph_inputs(&x, &mesh, []),
        1,
    )
    .unwrap_err();
    assert!(e.contains("stop_word 2"), "{e}");
}

/// A fixed count runs exactly that many rounds; and a cap below the rounds needed is an
/// error, although the executor submits iterations ahead of the host's decision.
#[test]
fn repeat_runs_a_fixed_count_and_refuses_past_its_cap() {
    let Some(gpu) = gpu() else { return };
    let (x, mesh) = moved_disks(37);
    let (want, rounds, total) = host_flips(&x, &mesh, 2);
    assert_eq!(rounds, 2);
    let (out, _) = run(
        &gpu,
        &flip_graph(300, r#"{"fixed": 2}"#),
        &disk_graph_inputs(&x, &mesh, []),
        1,
    )
    .unwrap();
    assert_eq!(u32s(&out["mesh"]), want);
    assert_eq!(u32s(&out["iterations"]), vec![2]);
    assert_eq!(u32s(&out["flips"]), vec![total]);
    let e = run(
        &gpu,
        &flip_graph(300, r#"{"max_iterations": 2}"#),
        &disk_graph_inputs(&x, &mesh, []),
        1,
    )
    .unwrap_err();
    assert!(
        e.contains("after 2 iterations") && e.contains("flips"),
        "{e}"
    );
}

/// The overlap loop: `repeat` carrying the positions through `overlap_correction_round`
/// on a fixed mesh (its fans made by `vertex_fans` before the loop, which the plan keeps
/// out of the loop body) until no pair along an edge overlaps, bit for bit the same as
/// the node's rounds run one by one from the host (each of which `disks::overlap` checks
/// against the f64 round), with the same count of rounds and overlaps.
#[test]
fn repeat_carries_the_positions_through_the_overlap_rounds() {
    if gpu().is_none() {
        return;
    }
    let l = [24.0, 22.0];
    let mut rng = Rng::new(41);
    let n = 300;
    let x0 = disk_positions(&mut rng, n, l, 0.72);
    let mesh = periodic_delaunay(&x0, l).unwrap();
    let x: Vec<f64> = x0.iter().map(|&v| v as f32 as f64).collect();
    let params = r#"{"sigma": 1, "box": [24, 22]}"#;
    let table = vertex_fans(&mesh, n, 10);
    let fans = indices(&table);
    let (mut want, mut rounds, mut total) = (x.clone(), 0u32, 0u32);
    loop {
        let (out, _) = run_node_and_reference(
            "overlap_correction_round",
            params,
            &[
                ("positions", flat_particles(&want, 2)),
                ("mesh", indices(&mesh)),
                ("fans", fans.clone()),
            ],
        );
        want = out["positions"].data.to_f64();
        let count = u32s(&out["overlaps"])[0];
        rounds += 1;
        total += count;
        if count == 0 {
            break;
        }
        assert!(rounds < 100, "no convergence");
    }
    assert!(rounds >= 4, "{rounds} rounds");
    let json = format!(
        r#"{{"mesoflow": 1, "inputs": {{"positions": {}, "mesh": {}}},
  "nodes": [
    {{"id": "overlaps", "kind": "repeat", "inputs": {{"initial": "inputs.positions", "next": "round.positions", "count": "round.overlaps"}}}},
    {{"id": "fans", "kind": "vertex_fans", "inputs": {{"mesh": "inputs.mesh"}}}},
    {{"id": "round", "kind": "overlap_correction_round", "params": {params}, "inputs": {{"positions": "overlaps.current", "mesh": "inputs.mesh", "fans": "fans.fans"}}}}
  ],
  "outputs": {{"positions": {{"from": "overlaps.out"}}, "iterations": {{"from": "overlaps.iterations"}}, "overlaps": {{"from": "overlaps.total"}}}}
}}"#,
        input_decl(&ValueType::Particles { n: n as u32, k: 2 }),
        input_decl(&ValueType::Indices {
            n: mesh.len() as u32
        }),
    );
    // The rounds above took the shared GPU in turn; the loop takes it now.
    let gpu = gpu().expect("checked above");
    assert_eq!(
        loop_body(&gpu, &json, &disk_graph_inputs(&x, &mesh, [])),
        ["round"]
    );
    let (out, _) = run(&gpu, &json, &disk_graph_inputs(&x, &mesh, []), 1).unwrap();
    assert_eq!(u32s(&out["iterations"]), vec![rounds]);
    assert_eq!(u32s(&out["overlaps"]), vec![total]);
    assert_eq!(out["positions"].data.to_f64(), want);
}
