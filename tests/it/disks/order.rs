//! The disk graphs' internal order (bd_delaunay.json, abp_delaunay.json): the disks are
//! numbered once in a Morton order of their initial positions and everything comes back
//! in the user's numbering. The same run with the ids permuted gives the same disks
//! (noise off); the unwrapped positions follow the wrapped path; the scatter back runs on
//! a run's last step only; a broken given mesh is still refused as given.

use std::collections::{BTreeMap, BTreeSet};

use mesoflow::exec::{Profile, Program, RunOptions};
use mesoflow::gpu::{DeviceCaps, GpuContext, KernelCache};
use mesoflow::graph::Graph;
use mesoflow::nodes::disks::mesh::{MESH_WORDS, check_torus_mesh, periodic_delaunay};
use mesoflow::nodes::disks::minimum_image;
use mesoflow::plan::{Launch, Plan};
use mesoflow::value::{HostArray, ValueType};

use crate::util::disks::{disk_graph_inputs, lattice_disks, random_headings, run_with_loops};
use crate::util::{Rng, flat_particles, gpu, indices, load_with, plan_graph, types_of, u32s};

/// The undirected edges of a mesh, each as (lower id, higher id).
fn edges(mesh: &[u32]) -> BTreeSet<(u32, u32)> {
    mesh.chunks(MESH_WORDS)
        .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
        .map(|(a, b)| (a.min(b), a.max(b)))
        .collect()
}

/// The rows of a flat array of `k` columns taken in the order `perm` (row i of the
/// result is row perm[i]).
fn rows_by(x: &[f64], k: usize, perm: &[usize]) -> Vec<f64> {
    perm.iter()
        .flat_map(|&p| x[k * p..k * p + k].to_vec())
        .collect()
}

/// A random permutation of 0 .. n.
fn shuffled(rng: &mut Rng, n: usize) -> Vec<usize> {
    let mut p: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        p.swap(i, j);
    }
    p
}

/// The inputs of a run with the disks renumbered: new disk i is old disk perm[i] (its
/// rows taken in that order, the mesh's vertex ids renamed, its triangles kept).
fn renumbered(inputs: &BTreeMap<String, HostArray>, perm: &[usize]) -> BTreeMap<String, HostArray> {
    let mut rank = vec![0u32; perm.len()];
    for (i, &p) in perm.iter().enumerate() {
        rank[p] = i as u32;
    }
    inputs
        .iter()
        .map(|(name, a)| {
            let moved = match a.ty {
                ValueType::Particles { k, .. } => {
                    flat_particles(&rows_by(&a.data.to_f64(), k as usize, perm), k)
                }
                _ => {
                    let m: Vec<u32> = u32s(a)
                        .chunks(MESH_WORDS)
                        .flat_map(|t| {
                            [
                                rank[t[0] as usize],
                                rank[t[1] as usize],
                                rank[t[2] as usize],
                                t[3],
                                t[4],
                                t[5],
                            ]
                        })
                        .collect();
                    indices(&m)
                }
            };
            (name.clone(), moved)
        })
        .collect()
}

/// A graph file, its `--set` values and its inputs.
type Case<'a> = (
    &'a str,
    Vec<(&'a str, &'a str)>,
    &'a BTreeMap<String, HostArray>,
);

/// With the noise off (diffusion 0), a run of disks numbered at random and the same run
/// with the disks renumbered by a permutation (inputs permuted, mesh relabelled) give
/// the same disks, output for output, up to that permutation: positions, unwrapped
/// positions, forces and headings within f32 rounding (the internal orders differ
/// inside a Morton cell, and with them the order of some sums), the charges exactly,
/// and the same mesh edges, each output mesh a valid triangulation of its output
/// positions in its own numbering.
#[test]
fn renumbered_disks_give_the_same_run_up_to_the_permutation() {
    let Some(gpu) = gpu() else { return };
    let n = 256usize;
    let mut rng = Rng::new(83);
    let (x, l) = lattice_disks(&mut rng, n, 0.5, 1.0);
    let mesh = periodic_delaunay(&x, [l, l]).unwrap();
    let q: Vec<f64> = (0..n)
        .flat_map(|i| if i % 3 == 0 { [1.0, 1.0] } else { [-1.0, 2.0] })
        .collect();
    let theta = random_headings(&mut rng, n);
    let perm = shuffled(&mut rng, n);
    let steps = 6;
    let bd = disk_graph_inputs(&x, &mesh, [("charges", flat_particles(&q, 2))]);
    let abp = disk_graph_inputs(&x, &mesh, [("angles", flat_particles(&theta, 1))]);
    let cases: [Case; 3] = [
        (
            "bd_delaunay.json",
            vec![
                ("n", "256"),
                ("density", "0.5"),
                ("config", "\"custom\""),
                ("diffusion", "0"),
            ],
            &bd,
        ),
        (
            "bd_delaunay.json",
            vec![
                ("n", "256"),
                ("density", "0.5"),
                ("config", "\"custom\""),
                ("diffusion", "0"),
                ("range", "\"short\""),
            ],
            &bd,
        ),
        (
            "abp_delaunay.json",
            vec![
                ("n", "256"),
                ("density", "0.5"),
                ("diffusion", "0"),
                ("speed", "2"),
            ],
            &abp,
        ),
    ];
    for (file, sets, inputs) in cases {
        let g = load_with(file, &sets, steps, 7);
        let (a, _) = run_with_loops(&gpu, &g, inputs, steps).unwrap();
        let (b, _) = run_with_loops(&gpu, &g, &renumbered(inputs, &perm), steps).unwrap();
        let what = format!("{file} {sets:?}");
        for (name, k, tol) in [
            ("positions", 2, 1e-5),
            ("unwrapped", 2, 1e-5),
            ("forces", 2, 1e-5),
            ("charges", 2, 0.0),
            ("angles", 1, 0.0),
        ] {
            let Some(out) = a.get(name) else { continue };
            let want = rows_by(&out.data.to_f64(), k, &perm);
            let got = b[name].data.to_f64();
            let scale = want.iter().fold(1.0f64, |m, v| m.max(v.abs()));
            let err = got
                .iter()
                .zip(&want)
                .map(|(g, w)| (g - w).abs())
                .fold(0.0, f64::max);
            eprintln!("{what}: {name} differs by {err:e}");
            assert!(err <= tol * scale, "{what}: {name} differs by {err:e}");
        }
        let (xa, xb) = (a["positions"].data.to_f64(), b["positions"].data.to_f64());
        let (ma, mb) = (u32s(&a["mesh"]), u32s(&b["mesh"]));
        for (m, x) in [(&ma, &xa), (&mb, &xb)] {
            let stats = check_torus_mesh(m, x, [l, l]).unwrap_or_else(|e| panic!("{what}: {e}"));
            assert_eq!(stats.inverted, 0, "{what}");
        }
        let mapped: BTreeSet<(u32, u32)> = edges(&mb)
            .into_iter()
            .map(|(i, j)| {
                let (p, q) = (perm[i as usize] as u32, perm[j as usize] as u32);
                (p.min(q), p.max(q))
            })
            .collect();
        assert_eq!(mapped, edges(&ma), "{what}: the meshes' edges");
        // The disks moved (forces, self-propulsion), and a step came out in each.
        let moved = (0..n)
            .map(|i| {
                let d = [0, 1].map(|c| minimum_image(xa[2 * i + c] - x[2 * i + c], l));
                d[0].hypot(d[1])
            })
            .fold(0.0, f64::max);
        assert!(moved > 1e-3, "{what}: the largest move {moved}");
    }
}

/// Runs a loaded disk graph for `chunks` runs of `steps` steps each, reading the outputs
/// after each: per chunk, the unwrapped positions minus the wrapped ones are whole box
/// lengths, and the unwrapped positions follow the wrapped path (each chunk's minimum
/// image added on the host). Returns how many disks ended in another image of the box
/// than the one they started in (unwrapped minus wrapped not zero), and how many more
/// than half a box from where they started along some axis.
fn check_unwrapped(
    gpu: &GpuContext,
    g: &Graph,
    inputs: &BTreeMap<String, HostArray>,
    l: f64,
    chunks: usize,
    steps: u64,
) -> (usize, usize) {
    let p = plan_graph(
        &gpu.caps,
        g,
        types_of(inputs),
        Some(&["positions", "unwrapped"]),
        true,
    );
    let mut cache = KernelCache::default();
    let mut program = Program::compile(gpu, g, &p, &mut cache).unwrap();
    program.upload(inputs).unwrap();
    let x0 = inputs["positions"].data.to_f64();
    let (mut wrapped, mut host) = (x0.clone(), x0.clone());
    let mut unwrapped = x0.clone();
    for chunk in 0..chunks {
        program
            .run_on(&RunOptions {
                steps,
                profile: Profile::Off,
                progress: false,
            })
            .unwrap();
        let out: BTreeMap<String, HostArray> =
            program.read_outputs().unwrap().into_iter().collect();
        let x = out["positions"].data.to_f64();
        unwrapped = out["unwrapped"].data.to_f64();
        for i in 0..x.len() {
            host[i] += minimum_image(x[i] - wrapped[i], l);
            let images = (unwrapped[i] - x[i]) / l;
            assert!(
                (images - images.round()).abs() < 1e-5 * (1.0 + images.abs()),
                "chunk {chunk}, coordinate {i}: unwrapped {} minus wrapped {} is {images} boxes",
                unwrapped[i],
                x[i]
            );
            assert!(
                (unwrapped[i] - host[i]).abs() < 1e-4 * (1.0 + host[i].abs()),
                "chunk {chunk}, coordinate {i}: unwrapped {} vs the wrapped path {}",
                unwrapped[i],
                host[i]
            );
        }
        wrapped = x;
    }
    let n = x0.len() / 2;
    let crossed = (0..n)
        .filter(|&i| (0..2).any(|c| (unwrapped[2 * i + c] - wrapped[2 * i + c]).abs() > 0.5 * l))
        .count();
    let far = (0..n)
        .filter(|&i| (0..2).any(|c| (unwrapped[2 * i + c] - x0[2 * i + c]).abs() > 0.5 * l))
        .count();
    (crossed, far)
}

/// The unwrapped positions of both graphs over runs in which disks cross the box's
/// faces: active disks (V0 = 2, dt 0.05, 200 steps: 20 sigma along a slowly turning
/// heading, more than half the box, 15.9) and Brownian ones (D = 1: 1.4 sigma per axis
/// over the run).
#[test]
fn unwrapped_positions_follow_the_wrapped_path() {
    let Some(gpu) = gpu() else { return };
    let n = 64usize;
    let mut rng = Rng::new(89);
    let (x, l) = lattice_disks(&mut rng, n, 0.05, 1.0);
    let mesh = periodic_delaunay(&x, [l, l]).unwrap();
    let theta = random_headings(&mut rng, n);
    let inputs = disk_graph_inputs(&x, &mesh, [("angles", flat_particles(&theta, 1))]);
    let g = load_with(
        "abp_delaunay.json",
        &[
            ("n", "64"),
            ("density", "0.05"),
            ("speed", "2"),
            ("dt", "0.05"),
            ("diffusion", "0.01"),
        ],
        200,
        3,
    );
    let (crossed, far) = check_unwrapped(&gpu, &g, &inputs, l, 20, 10);
    eprintln!(
        "abp: {crossed} of {n} disks in another image, {far} more than half a box ({}) away",
        l / 2.0
    );
    assert!(far > n / 4, "{far} of {n} disks went past half the box");
    let charges = flat_particles(&vec![0.0; 2 * n], 2);
    let inputs = disk_graph_inputs(&x, &mesh, [("charges", charges)]);
    let g = load_with(
        "bd_delaunay.json",
        &[
            ("n", "64"),
            ("density", "0.05"),
            ("config", "\"custom\""),
            ("diffusion", "1"),
        ],
        200,
        3,
    );
    let (crossed, _) = check_unwrapped(&gpu, &g, &inputs, l, 20, 10);
    eprintln!("bd: {crossed} of {n} disks in another image");
    assert!(crossed > 0, "no disk crossed a face of the box");
}

/// The ids of the nodes of a plan's step launches that run on a run's last step only,
/// and of its prologue.
fn last_and_prologue(g: &Graph, p: &Plan) -> (BTreeSet<String>, BTreeSet<String>) {
    let ids = |ls: Vec<&Launch>| {
        ls.into_iter()
            .flat_map(|l| l.nodes())
            .map(|n| g.nodes[n].id.clone())
            .collect()
    };
    (
        ids(p.last_step_only.iter().map(|&i| &p.step[i]).collect()),
        ids(p.prologue.iter().collect()),
    )
}

/// The order is taken in the prologue, and the scatter back into the user's numbering
/// (positions, unwrapped positions, the mesh, charges, forces, headings) runs on a run's
/// last step only: the steps pay nothing for it, and no state is copied in them (the
/// order and the charges are kept unchanged).
#[test]
fn the_order_costs_the_steps_nothing() {
    let caps = DeviceCaps::baseline();
    let words = |n: u32| ValueType::Indices { n };
    let p2 = |n: u32, k: u32| ValueType::Particles { n, k };
    for (file, sets, last) in [
        (
            "bd_delaunay.json",
            vec![("range", "\"long\"")],
            vec![
                "charges_out",
                "forces_out",
                "mesh_out",
                "positions_out",
                "unwrapped_out",
            ],
        ),
        (
            "bd_delaunay.json",
            vec![("range", "\"short\"")],
            vec![
                "charges_out",
                "forces_out",
                "mesh_out",
                "positions_out",
                "unwrapped_out",
            ],
        ),
        (
            "abp_delaunay.json",
            vec![],
            vec!["angles_out", "mesh_out", "positions_out", "unwrapped_out"],
        ),
    ] {
        let g = load_with(file, &sets, 1, 0);
        let mut inputs = BTreeMap::from([
            ("positions".to_string(), p2(1024, 2)),
            ("mesh".to_string(), words(12288)),
        ]);
        if file == "abp_delaunay.json" {
            inputs.insert("angles".into(), p2(1024, 1));
        }
        let p = plan_graph(&caps, &g, inputs, None, true);
        let (l, pro) = last_and_prologue(&g, &p);
        assert_eq!(
            l,
            last.iter().map(|s| s.to_string()).collect(),
            "{file} {sets:?}"
        );
        for id in ["order_key", "order", "start", "ranks", "start_mesh"] {
            assert!(pro.contains(id), "{file}: {id} not in the prologue {pro:?}");
        }
        assert!(
            p.step.iter().all(|l| !matches!(l, Launch::Copy { .. })),
            "{file}: a state copied in the steps"
        );
        let every: BTreeSet<String> = p
            .step
            .iter()
            .enumerate()
            .filter(|(i, _)| !p.last_step_only.contains(i))
            .flat_map(|(_, l)| l.nodes())
            .map(|n| g.nodes[n].id.clone())
            .collect();
        assert!(!every.contains("species"), "{file}: {every:?}");
    }
}

/// A given mesh whose twins do not match is refused before upload, by the node that
/// checks it behind the relabelling into the internal order, naming its row as given.
#[test]
fn a_broken_given_mesh_is_refused_as_given() {
    let Some(gpu) = gpu() else { return };
    let n = 64usize;
    let mut rng = Rng::new(97);
    let (x, l) = lattice_disks(&mut rng, n, 0.3, 1.0);
    let mut mesh = periodic_delaunay(&x, [l, l]).unwrap();
    let t = 5;
    mesh[MESH_WORDS * t + 3] = mesh[MESH_WORDS * t + 4];
    let inputs = disk_graph_inputs(&x, &mesh, []);
    let g = load_with("bd_delaunay.json", &[("n", "64"), ("density", "0.3")], 1, 0);
    let p = plan_graph(&gpu.caps, &g, types_of(&inputs), None, true);
    let mut cache = KernelCache::default();
    let mut program = Program::compile(&gpu, &g, &p, &mut cache).unwrap();
    let err = program.upload(&inputs).unwrap_err().to_string();
    assert!(
        err.contains("`crossings` (pass_through_count), port `mesh`")
            && err.contains(&format!("row {t}"))
            && err.contains("twin"),
        "{err}"
    );
}
