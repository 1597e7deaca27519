//! `mesoflow bench disks`: graphs/bd_delaunay.json (S1's Brownian disks with a Delaunay
//! mesh) per configuration, force range and size: the time of a step end to end (host
//! clock: the loops decide on the host), split by launch into forces (the all-pairs
//! node, or the cell list, the neighbour sum and its scatter), the move (with the
//! unwrapped positions), flips (the two flip loops, round trips included) and the
//! overlap correction (its loop; the scatters back into the user's numbering run on a
//! run's last step only and are listed apart, `outputs`), with the
//! loops' iterations per step and, for the long-range force, pair interactions per
//! second (N^2 / the all-pairs launch's time) and GFLOP/s at `LONG_FLOPS` per pair.
//!
//! The disks start on the widest jittered triangular lattice in the box
//! (`presets::lattice_disks`: spacing about 1.07 sigma at packing 0.79; numbered at
//! random, or in the lattice's order with `--order lattice`: the graph renumbers them
//! in its own Morton order in the prologue either way) and the
//! mesh is built on the host (`periodic_delaunay`, seconds at 2^20 disks).

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;

use mesoflow::expr::ParamValue;
use mesoflow::nodes::disks::mesh::periodic_delaunay;
use mesoflow::nodes::disks::presets::{configuration, lattice_disks_in};
use mesoflow::value::{HostArray, ValueType};

use super::fcm::load;
use super::{BenchError, Engine, ms, open_gpu, time_loaded_with};

pub struct DisksBench {
    pub graph: PathBuf,
    pub configs: Vec<String>,
    pub ranges: Vec<String>,
    pub sizes: Vec<u32>,
    pub reps: u64,
    /// The start's disks numbered in lattice order (`--order lattice`).
    pub in_order: bool,
    /// The flip loops' meshes written in place (`PlanOptions::in_place`; off with
    /// `--no-in-place`).
    pub in_place: bool,
    /// Each step's loops chained in one submission (`Program::set_chain_loops`; off with
    /// `--no-chain`).
    pub chain_loops: bool,
}

/// Flops per pair of the long-range kernel (shaders/disks/forces.wgsl, counted by hand:
/// minimum image 6, r^2 3, the reciprocal, its square root and the weight 4, the select
/// and accumulate 5).
const LONG_FLOPS: f64 = 18.0;

/// Which part of a step a launch is, by its node's id in bd_delaunay.json: the scatters
/// back into the user's numbering (`*_out`) are `outputs`, run on a run's last step only
/// and left out of the parts.
fn part(label: &str) -> &'static str {
    let id = label.split([' ', '/', ':', '(']).next().unwrap_or(label);
    match id {
        "force" | "force_sorted" | "zorder" | "zsort" | "zpositions" | "zcharges" | "cl"
        | "sorted_charges" | "verlet" | "short_sorted" | "short" | "species" | "charges"
        | "forces" => "forces",
        "flips" | "flip" | "settle" | "reflip" => "flips",
        "fans" | "overlaps" | "correct" => "overlap",
        _ if id.ends_with("_out") => "outputs",
        _ => "move",
    }
}

pub fn run(bench: &DisksBench) -> Result<(), BenchError> {
    let gpu = open_gpu(bench.reps)?;
    let registry = mesoflow::nodes::registry();
    outln!(
        "bd_delaunay.json, dt 0.01, D 0.01, sigma 1; step: median over {} steps, each timed \
         alone end to end (host clock, from its recording to the end of its wait; {}); run/step: \
         a run of as many steps, unprofiled, over its steps (host clock: the host records a \
         step while the one before runs); parts: medians of each launch timed \
         alone (a loop with its body and round trips); iterations per step of the loops \
         (each counting its last, empty round); long range: pairs/s = N^2 / the all-pairs kernel time, \
         GFLOP/s at {LONG_FLOPS} flops per pair; the flip loops' meshes {}",
        bench.reps,
        if bench.chain_loops {
            "a step's loops chained in one submission, one status read a step"
        } else {
            "--no-chain: a host round trip per loop"
        },
        if bench.in_place {
            "written in place (no copies per iteration)"
        } else {
            "copied (--no-in-place: the flip node's copy and repeat's per iteration)"
        }
    );
    outln!(
        "{:>6} {:>7} {:>8} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10} {:>7} {:>7} {:>7} {:>11} {:>8}",
        "config",
        "range",
        "N",
        "step ms",
        "run/step",
        "forces ms",
        "move ms",
        "flips ms",
        "overlap ms",
        "flips",
        "overlap",
        "settle",
        "pairs/s",
        "GFLOP/s"
    );
    for config in &bench.configs {
        let Some((_, fraction, _, _, density)) = configuration(config) else {
            return Err(BenchError::Args(format!(
                "no configuration `{config}`: c0 to c4"
            )));
        };
        for range in &bench.ranges {
            let (law, neighbours) = match range.as_str() {
                "long" => ("long", "cells"),
                "short" => ("short", "cells"),
                "verlet" => ("short", "verlet"),
                other => {
                    return Err(BenchError::Args(format!(
                        "range `{other}`: long, short or verlet"
                    )));
                }
            };
            for &n in &bench.sizes {
                let (x, _, l) = lattice_disks_in(
                    n as usize,
                    density,
                    1.0,
                    fraction,
                    0x5EED ^ n as u64,
                    bench.in_order,
                )
                .map_err(BenchError::Args)?;
                let mesh = periodic_delaunay(&x, [l, l])
                    .map_err(|e| BenchError::Args(format!("the mesh of {n} disks: {e}")))?;
                let g = load(
                    &bench.graph,
                    &[
                        ("n", ParamValue::Number(n as f64)),
                        ("config", ParamValue::Text(config.clone())),
                        ("range", ParamValue::Text(law.into())),
                        ("neighbours", ParamValue::Text(neighbours.into())),
                    ],
                    &registry,
                )?;
                let inputs = BTreeMap::from([
                    (
                        "positions".to_string(),
                        HostArray::f32(
                            ValueType::Particles { n, k: 2 },
                            x.iter().map(|&v| v as f32).collect(),
                        ),
                    ),
                    (
                        "mesh".to_string(),
                        HostArray::u32(
                            ValueType::Indices {
                                n: mesh.len() as u32,
                            },
                            mesh,
                        ),
                    ),
                ]);
                // A size that fails (a pass-through at this dt, the device's memory) is
                // reported on its row and the table goes on.
                let run = match time_loaded_with(
                    &gpu,
                    &g,
                    &inputs,
                    None,
                    bench.reps,
                    Engine {
                        fuse: true,
                        in_place: bench.in_place,
                        chain_loops: bench.chain_loops,
                    },
                ) {
                    Ok(run) => run,
                    Err(e) => {
                        outln!("{config:>6} {range:>7} {n:>8} failed: {e}");
                        continue;
                    }
                };
                let mut parts: BTreeMap<&str, Duration> = BTreeMap::new();
                for t in run.timings.iter().filter(|t| !t.last_step_only) {
                    *parts.entry(part(&t.label)).or_default() += t.median;
                }
                let mean = |name: &str| {
                    run.loops
                        .iter()
                        .find(|(l, _)| l == name)
                        .map(|(_, c)| {
                            c.iter().map(|&k| k as f64).sum::<f64>() / c.len().max(1) as f64
                        })
                        .unwrap_or(0.0)
                };
                let forces = parts.get("forces").copied().unwrap_or_default();
                // The all-pairs kernel alone (not the Morton sort around it).
                let pair_kernel: Duration = run
                    .timings
                    .iter()
                    .filter(|t| t.label.starts_with("force_sorted"))
                    .map(|t| t.median)
                    .sum();
                let (pairs, gflops) = if law == "long" {
                    let p = n as f64 * n as f64 / pair_kernel.as_secs_f64().max(1e-12);
                    (format!("{p:.3e}"), format!("{:.0}", p * LONG_FLOPS / 1e9))
                } else {
                    ("-".into(), "-".into())
                };
                outln!(
                    "{:>6} {:>7} {:>8} {:>10.3} {:>10.3} {:>10.3} {:>10.3} {:>10.3} {:>10.3} {:>7.2} {:>7.2} {:>7.2} {:>11} {:>8}",
                    config,
                    range,
                    n,
                    ms(run.end_to_end()),
                    ms(run.run_step),
                    ms(forces),
                    ms(parts.get("move").copied().unwrap_or_default()),
                    ms(parts.get("flips").copied().unwrap_or_default()),
                    ms(parts.get("overlap").copied().unwrap_or_default()),
                    mean("flips"),
                    mean("overlaps"),
                    mean("settle"),
                    pairs,
                    gflops
                );
                for t in &run.timings {
                    outln!(
                        "        {:<8} {:<48} {:>10.3} ms",
                        part(&t.label),
                        t.label,
                        ms(t.median)
                    );
                    // MESOFLOW_BENCH_DISPATCHES: each dispatch of the launch (a loop's
                    // iterations are timed on the GPU only where they are fixed, as in
                    // benches/bd_delaunay_fixed.json).
                    for (kernel, median, _) in &t.dispatches {
                        outln!("            {:<52} {:>10.4} ms", kernel, ms(*median));
                    }
                }
            }
        }
    }
    Ok(())
}
