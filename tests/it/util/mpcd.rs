//! MPCD (tests/it/mpcd/): random fluid particles, the f64 moments of cells, and graphs
//! run with the shared kernel cache (graphs/mpcd.json and others, or built by a test).

use std::collections::BTreeMap;

use mesoflow::graph::Graph;
use mesoflow::value::HostArray;

use super::{Rng, gpu, load_with, random_points, run_cached};

/// Random particles in a box: positions uniform, velocities uniform in [-2, 2) plus a flow.
pub fn random_particles(rng: &mut Rng, n: usize, l: &[f64]) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let d = l.len();
    let x = random_points(rng, n, l)
        .chunks(d)
        .map(|row| row.to_vec())
        .collect();
    let v = (0..n)
        .map(|_| {
            (0..d)
                .map(|a| rng.uniform(-2.0, 2.0) + 0.3 * a as f64)
                .collect()
        })
        .collect();
    (x, v)
}

/// The thermostat named in mpcd_collide params (`none` without one): mpcd_bin takes the
/// same, as it then sums |v|^2 too.
pub fn thermostat_of(collide: &str) -> &'static str {
    ["rescale", "monte_carlo"]
        .into_iter()
        .find(|t| collide.contains(&format!(r#""thermostat": "{t}""#)))
        .unwrap_or("none")
}

/// A species: cell per particle, velocities, mass.
pub type Species<'a> = (&'a [u32], &'a [Vec<f64>], f64);

/// Per cell: mass (units of m), momentum and twice the kinetic energy of every species.
pub fn mass_moments(species: &[Species<'_>], ncells: usize) -> Vec<(f64, [f64; 3], f64)> {
    let mut m = vec![(0.0, [0.0; 3], 0.0); ncells];
    for &(cells, v, mass) in species {
        for (p, &c) in cells.iter().enumerate() {
            let e = &mut m[c as usize];
            e.0 += mass;
            for (a, &va) in v[p].iter().enumerate() {
                e.1[a] += mass * va;
                e.2 += mass * va * va;
            }
        }
    }
    m
}

/// Per cell: (count, sum v, sum |v|^2) in f64 over the given cells (one species of unit
/// mass).
pub fn cell_moments(cells: &[u32], v: &[Vec<f64>], ncells: usize) -> Vec<(f64, [f64; 3], f64)> {
    mass_moments(&[(cells, v, 1.0)], ncells)
}

/// Runs a loaded graph on the shared GPU for `steps` steps and returns the named outputs.
pub fn run_loaded(
    g: &Graph,
    inputs: &BTreeMap<String, HostArray>,
    outputs: &[&str],
    steps: u64,
) -> BTreeMap<String, HostArray> {
    let gpu = gpu().expect("GPU");
    run_cached(&gpu, g, inputs, Some(outputs), steps, true).0
}

/// graphs/`name` with these `--set` values (JSON literals), run for `steps` steps.
pub fn run_graph_file(
    name: &str,
    sets: &[(&str, &str)],
    steps: u64,
    seed: u64,
    outputs: &[&str],
) -> BTreeMap<String, HostArray> {
    let g = load_with(name, sets, steps, seed);
    run_loaded(&g, &BTreeMap::new(), outputs, steps)
}

/// graphs/mpcd.json with these `--set` values (JSON literals), run for `steps` steps.
pub fn run_mpcd(
    sets: &[(&str, &str)],
    steps: u64,
    seed: u64,
    outputs: &[&str],
) -> BTreeMap<String, HostArray> {
    run_graph_file("mpcd.json", sets, steps, seed, outputs)
}
