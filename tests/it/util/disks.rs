//! Helpers of the 2-D disk tests (`disks/`): disk packings with a minimum separation,
//! random headings, a graph's disk inputs, graphs with loops run with their iterations per
//! step.

use std::collections::BTreeMap;

use mesoflow::exec::{Profile, Program};
use mesoflow::gpu::{GpuContext, KernelCache};
use mesoflow::graph::Graph;
use mesoflow::plan::{self, PlanOptions};
use mesoflow::value::HostArray;

use super::{Rng, flat_particles, indices, try_run_program, types_of};

/// Outputs by name and the iterations of each loop per step.
pub type LoopRun = (BTreeMap<String, HostArray>, Vec<(String, Vec<u32>)>);

/// Plans, compiles and runs a loaded graph for `steps` steps: the outputs and the
/// iterations of each loop per step, or the first error as text.
pub fn run_with_loops(
    gpu: &GpuContext,
    g: &Graph,
    inputs: &BTreeMap<String, HostArray>,
    steps: u64,
) -> Result<LoopRun, String> {
    run_with_loops_profiled(gpu, g, inputs, steps, Profile::Off)
}

/// [`run_with_loops`] under a profile (loops then timed through `time_loop`).
pub fn run_with_loops_profiled(
    gpu: &GpuContext,
    g: &Graph,
    inputs: &BTreeMap<String, HostArray>,
    steps: u64,
    profile: Profile,
) -> Result<LoopRun, String> {
    run_with_loops_planned(gpu, g, inputs, steps, profile, true)
}

/// [`run_with_loops_profiled`], outputs in place of their inputs
/// (`PlanOptions::in_place`) or each in a buffer of its own.
pub fn run_with_loops_planned(
    gpu: &GpuContext,
    g: &Graph,
    inputs: &BTreeMap<String, HostArray>,
    steps: u64,
    profile: Profile,
    in_place: bool,
) -> Result<LoopRun, String> {
    let opts = PlanOptions {
        outputs: None,
        inputs: types_of(inputs),
        fuse: true,
        in_place,
    };
    let p = plan::plan(g, &opts, &gpu.caps).map_err(|e| e.to_string())?;
    let mut cache = KernelCache::default();
    let mut program = Program::compile(gpu, g, &p, &mut cache).map_err(|e| e.to_string())?;
    let out = try_run_program(&mut program, inputs, steps, profile)?;
    Ok((out, program.loop_iterations().to_vec()))
}

/// `n` points in the periodic box `l` (centred at the origin) no two closer than
/// `min_dist` by the minimum image, by random sequential addition (panics when the box is
/// too full to place them in 1000 tries each).
pub fn disk_positions(rng: &mut Rng, n: usize, l: [f64; 2], min_dist: f64) -> Vec<f64> {
    let mut x: Vec<f64> = Vec::with_capacity(2 * n);
    for _ in 0..n {
        let mut placed = false;
        for _ in 0..1000 {
            let p = [
                rng.uniform(-0.5 * l[0], 0.5 * l[0]),
                rng.uniform(-0.5 * l[1], 0.5 * l[1]),
            ];
            let clear = x.chunks(2).all(|q| {
                let d: Vec<f64> = (0..2)
                    .map(|a| mesoflow::nodes::disks::minimum_image(p[a] - q[a], l[a]))
                    .collect();
                d[0] * d[0] + d[1] * d[1] >= min_dist * min_dist
            });
            if clear {
                x.extend(p);
                placed = true;
                break;
            }
        }
        assert!(placed, "no room for {n} disks of {min_dist} in {l:?}");
    }
    x
}

/// `n` disks of diameter `sigma` at packing `density` in a square periodic box, as
/// `presets::lattice_disks` places them with this rng: the widest triangular lattice of
/// at least `n` sites in the box (`presets::triangular_lattice`, spacing d), `n` of its
/// sites drawn at random, each jittered by up to `JITTER` (d - sigma) / 2 per coordinate
/// (no four points near a circle; no two closer than sigma); f32 values. Returns the
/// positions and the box side. Reaches the packings random addition cannot (0.79).
pub fn lattice_disks(rng: &mut Rng, n: usize, density: f64, sigma: f64) -> (Vec<f64>, f64) {
    use mesoflow::nodes::disks::presets::{JITTER, triangular_lattice};
    let l = (n as f64 * std::f64::consts::PI * 0.25 * sigma * sigma / density).sqrt();
    let (mut sites, d) = triangular_lattice(n, l);
    assert!(d >= sigma, "{n} disks do not fit a lattice in {l}");
    for i in 0..n {
        let j = i + (rng.uniform(0.0, (sites.len() - i) as f64) as usize).min(sites.len() - i - 1);
        sites.swap(i, j);
    }
    let jitter = JITTER * (d - sigma);
    let x = sites[..n]
        .iter()
        .flat_map(|p| {
            p.map(|c| {
                let c = mesoflow::nodes::disks::wrap(c + jitter * rng.uniform(-0.5, 0.5), l);
                c as f32 as f64
            })
        })
        .collect();
    (x, l)
}

/// The inputs `positions` (N x 2) and `mesh` (nodes/disks/mesh.rs's words) of a disk
/// graph (bd_delaunay.json, abp_delaunay.json, the loop tests' graphs), with the per-disk
/// arrays a graph reads beside them by name (bd's `charges` N x 2, abp's `angles` N x 1).
pub fn disk_graph_inputs<'a>(
    x: &[f64],
    mesh: &[u32],
    per_disk: impl IntoIterator<Item = (&'a str, HostArray)>,
) -> BTreeMap<String, HostArray> {
    let mut inputs = BTreeMap::from([
        ("positions".to_string(), flat_particles(x, 2)),
        ("mesh".to_string(), indices(mesh)),
    ]);
    inputs.extend(per_disk.into_iter().map(|(name, a)| (name.to_string(), a)));
    inputs
}

/// `n` headings uniform in [0, 2 pi), f32 values (abp_delaunay.json's `angles`).
pub fn random_headings(rng: &mut Rng, n: usize) -> Vec<f64> {
    (0..n)
        .map(|_| rng.uniform(0.0, std::f64::consts::TAU) as f32 as f64)
        .collect()
}
