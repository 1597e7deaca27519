//! The start of `bench disks` and the example (`presets::lattice_disks`) at a size where
//! the old lattice failed: a triangular lattice of spacing `L / floor(L / sigma)` (1.005
//! sigma at N = 16384) with the surplus sites left empty at random packed the occupied
//! regions nearly as densely as close packing; the first move's overlaps spread through
//! them, the overlap correction ran ~100 rounds on its fixed mesh, moving disks by more
//! than a diameter, left the mesh folded with disks 0.08 sigma apart, and step 2 counted
//! pass-throughs (`flips` halt 68 to 75 on lavapipe, c0 short at N = 16384).

use mesoflow::nodes::disks::mesh::{check_torus_mesh, illegal_edges, periodic_delaunay};
use mesoflow::nodes::disks::minimum_image;
use mesoflow::nodes::disks::presets::lattice_disks;

use crate::util::disks::{disk_graph_inputs, run_with_loops};
use crate::util::{gpu, load_with, u32s};

/// The shortest edge of a torus mesh (the nearest pair, the mesh being Delaunay).
fn shortest_edge(mesh: &[u32], x: &[f64], l: f64) -> f64 {
    mesh.chunks(6)
        .flat_map(|t| (0..3).map(move |k| (t[k] as usize, t[(k + 1) % 3] as usize)))
        .map(|(a, b)| {
            let d = [0, 1].map(|c| minimum_image(x[2 * b + c] - x[2 * a + c], l));
            d[0].hypot(d[1])
        })
        .fold(f64::INFINITY, f64::min)
}

/// N = 16384 at c0's packing 0.79, the bench's seed: the disks start with room between
/// them (nearest pair above 1.02 sigma, the old lattice's was 1.005), their mesh is
/// Delaunay for the f32 positions the GPU reads (the old jitter of 1e-4 sigma left 25
/// edges illegal there), and three steps of bd_delaunay.json (c0, short range) run
/// without a pass-through, with a few overlap rounds per step, ending with a valid
/// mesh and no overlapping pair.
#[test]
fn lattice_start_at_16384_runs_without_pass_through() {
    let n = 16384;
    let (x, _, l) = lattice_disks(n, 0.79, 1.0, 0.7, 0x5EED ^ n as u64).unwrap();
    let x32: Vec<f64> = x.iter().map(|&c| c as f32 as f64).collect();
    let mesh = periodic_delaunay(&x, [l, l]).unwrap();
    let nearest = shortest_edge(&mesh, &x, l);
    assert!(nearest > 1.02, "nearest pair at start {nearest}");
    assert_eq!(illegal_edges(&mesh, &x32, [l, l], 0.0), Vec::<usize>::new());

    let Some(gpu) = gpu() else { return };
    let inputs = disk_graph_inputs(&x32, &mesh, []);
    let steps = 3;
    let n_text = n.to_string();
    let g = load_with(
        "bd_delaunay.json",
        &[("n", &n_text), ("config", "\"c0\""), ("range", "\"short\"")],
        steps,
        1,
    );
    let (out, loops) = run_with_loops(&gpu, &g, &inputs, steps).unwrap();
    assert_eq!(u32s(&out["pass_throughs"]), vec![0]);
    let overlaps = &loops.iter().find(|(n, _)| n == "overlaps").unwrap().1;
    assert!(
        overlaps.iter().all(|&r| r <= 10),
        "overlap rounds {overlaps:?}"
    );
    let end_x = out["positions"].to_ref().data;
    let end_mesh: Vec<u32> = out["mesh"]
        .to_ref()
        .data
        .iter()
        .map(|&v| v as u32)
        .collect();
    let stats = check_torus_mesh(&end_mesh, &end_x, [l, l]).unwrap();
    assert_eq!(stats.inverted, 0);
    let nearest = shortest_edge(&end_mesh, &end_x, l);
    assert!(
        nearest > 1.0 - 1e-3,
        "nearest pair after {steps} steps {nearest}"
    );
}
