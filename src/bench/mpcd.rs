//! `mesoflow bench mpcd`: particle-steps per second of `graphs/mpcd.json` (3D SRD,
//! periodic cubic box, 10 particles per cell by default; `--dims 2`: graphs/mpcd2d.json in
//! a square) at several particle counts: the GPU time of one step end to end, and the sum
//! of its launches (streaming and binning, collision), the state drawn by the graph
//! itself. `--spheres S` times graphs/mpcd_spheres.json with S spheres of radius
//! `--sphere-radius` on a cubic lattice (S a cube: 1, 8, 64...), neutrally buoyant when
//! they move (`--set spheres=moving`). With `MESOFLOW_BENCH_DISPATCHES` the per-dispatch
//! times show where a step goes.

use std::collections::BTreeMap;
use std::path::PathBuf;

use mesoflow::expr::ParamValue;
use mesoflow::gpu::GpuContext;

use mesoflow::value::{HostArray, ValueType};

use super::fcm::{load, param, particles};
use super::{BenchError, end_to_end_clock, ms, time_loaded};

pub struct MpcdBench {
    /// The graph; None: mpcd.json, mpcd2d.json (dims 2) or mpcd_spheres.json (spheres).
    pub graph: Option<PathBuf>,
    /// 2 or 3.
    pub dims: u32,
    /// Spheres on a cubic lattice (0: none).
    pub spheres: u32,
    pub sphere_radius: f64,
    /// Approximate particle counts (rounded to whole cubic boxes of cells).
    pub sizes: Vec<u64>,
    pub density: f64,
    pub reps: u64,
    /// Other graph params.
    pub sets: Vec<(String, ParamValue)>,
}

pub fn run(bench: &MpcdBench) -> Result<(), BenchError> {
    if bench.reps == 0 || bench.density <= 0.0 {
        return Err(BenchError::Args(
            "--reps and --density must be positive".into(),
        ));
    }
    if bench.dims != 2 && bench.dims != 3 {
        return Err(BenchError::Args(format!(
            "--dims {}: MPCD runs in 2 or 3 dimensions",
            bench.dims
        )));
    }
    let lattice = sphere_lattice_side(bench)?;
    let graph = bench.graph.clone().unwrap_or_else(|| {
        PathBuf::from(match (bench.dims, bench.spheres) {
            (2, _) => "graphs/mpcd2d.json",
            (_, 0) => "graphs/mpcd.json",
            _ => "graphs/mpcd_spheres.json",
        })
    });
    let moving = bench
        .sets
        .iter()
        .any(|(k, v)| k == "spheres" && *v == ParamValue::Text("moving".into()));
    let gpu = GpuContext::new()?;
    let registry = mesoflow::nodes::registry();
    outln!("adapter: {}", gpu.caps.summary());
    let others: Vec<String> = bench.sets.iter().map(|(k, v)| format!("{k}={v}")).collect();
    outln!(
        "graph {}; {}D, periodic box, cell 1, {} particles per cell{}{}; \
         time of one step over {} steps: e2e, the step end to end ({}), median and mean; \
         launches: sum of its launches' medians and means; the rate from e2e",
        graph.display(),
        bench.dims,
        bench.density,
        if bench.spheres > 0 {
            format!(
                ", {} spheres of radius {} on a {lattice}^3 lattice{}",
                bench.spheres,
                bench.sphere_radius,
                if moving {
                    " (moving, neutrally buoyant)"
                } else {
                    " (fixed)"
                }
            )
        } else {
            String::new()
        },
        if others.is_empty() {
            String::new()
        } else {
            format!(", {}", others.join(" "))
        },
        bench.reps,
        end_to_end_clock(&gpu)
    );
    outln!(
        "{:>10} {:>6} {:>10} {:>5} {:>10} {:>10} {:>12} {:>12} {:>16} {:>9}",
        "N",
        "L",
        "cells",
        "sort",
        "e2e ms",
        "e2e mean",
        "launches ms",
        "launch mean",
        "particle-steps/s",
        "ns/part."
    );
    outln!(
        "(sort: the graph's sort_every; where it is set the rate comes from the mean step, the reordering amortised)"
    );
    for &target in &bench.sizes {
        let cells_wanted = target as f64 / bench.density;
        let side = if bench.dims == 2 {
            cells_wanted.sqrt()
        } else {
            cells_wanted.cbrt()
        }
        .round()
        // Even: the biased rule's supercells pair whole cells.
        .max(2.0);
        let side = side + side % 2.0;
        let mut sets = vec![
            ("box", ParamValue::Numbers(vec![side; bench.dims as usize])),
            ("density", ParamValue::Number(bench.density)),
        ];
        if bench.spheres > 0 {
            sets.push(("sphere_radius", ParamValue::Number(bench.sphere_radius)));
        }
        sets.extend(bench.sets.iter().map(|(k, v)| (k.as_str(), v.clone())));
        let g = load(&graph, &sets, &registry)?;
        let density = match param(&g, "density") {
            Some(ParamValue::Number(d)) => d,
            _ => bench.density,
        };
        let sort_every = match param(&g, "sort_every") {
            Some(ParamValue::Number(k)) => k,
            _ => 0.0,
        };
        let cells = side.powi(bench.dims as i32);
        let n = (cells * density).round();
        let mass = match param(&g, "mass") {
            Some(ParamValue::Number(m)) => m,
            _ => 1.0,
        };
        let inputs = if bench.spheres > 0 {
            sphere_inputs(lattice, side, bench.sphere_radius, density * mass, moving)?
        } else {
            BTreeMap::new()
        };
        let run = time_loaded(
            &gpu,
            &g,
            &inputs,
            Some(vec!["positions".into(), "velocities".into()]),
            bench.reps,
            true,
        )?;
        if std::env::var_os("MESOFLOW_BENCH_DISPATCHES").is_some() {
            for t in &run.timings {
                out!("{}", t.breakdown());
            }
        }
        // With a reordering every few steps, the rate comes from the mean step (the
        // reordering amortised); otherwise from the median.
        let step = if sort_every > 0.0 {
            run.mean_end_to_end()
        } else {
            run.end_to_end()
        }
        .as_secs_f64();
        outln!(
            "{:>10} {:>6} {:>10} {:>5} {:>10.4} {:>10.4} {:>12.4} {:>12.4} {:>16.3e} {:>9.3}",
            n,
            side,
            cells,
            sort_every,
            ms(run.end_to_end()),
            ms(run.mean_end_to_end()),
            ms(run.launch_sum()),
            ms(run.mean_launch_sum()),
            n / step,
            step * 1e9 / n
        );
    }
    Ok(())
}

/// The side k of the cubic lattice of `--spheres` (k^3 spheres), checked against the box.
fn sphere_lattice_side(bench: &MpcdBench) -> Result<u32, BenchError> {
    if bench.spheres == 0 {
        return Ok(0);
    }
    let k = (bench.spheres as f64).cbrt().round() as u32;
    if bench.dims != 3 || k.pow(3) != bench.spheres {
        return Err(BenchError::Args(format!(
            "--spheres {}: spheres sit on a cubic lattice in 3D, so their count is a cube (1, 8, 27, 64...)",
            bench.spheres
        )));
    }
    if bench.sphere_radius.is_nan() || bench.sphere_radius <= 0.0 {
        return Err(BenchError::Args(format!(
            "--sphere-radius {}: must be positive",
            bench.sphere_radius
        )));
    }
    Ok(k)
}

/// Sphere inputs for mpcd_spheres.json: k^3 spheres of radius r at the centres of a k^3
/// lattice of the cube of side `side` centred at the origin, with the mass of the solvent
/// they displace (`mass_density` per unit volume) when they move.
fn sphere_inputs(
    k: u32,
    side: f64,
    r: f64,
    mass_density: f64,
    moving: bool,
) -> Result<BTreeMap<String, HostArray>, BenchError> {
    let spacing = side / k as f64;
    if 2.0 * r >= spacing {
        return Err(BenchError::Args(format!(
            "{} spheres of radius {r} do not fit apart in a box of side {side} (lattice spacing {spacing})",
            k.pow(3)
        )));
    }
    let at = |i: u32| (i as f64 + 0.5) * spacing - side / 2.0;
    let mut centres = Vec::new();
    for i in 0..k {
        for j in 0..k {
            for l in 0..k {
                centres.push([at(i), at(j), at(l)]);
            }
        }
    }
    let s = centres.len();
    let column = |v: f64| {
        HostArray::f32(
            ValueType::Particles { n: s as u32, k: 1 },
            vec![v as f32; s],
        )
    };
    let mut inputs = BTreeMap::from([
        ("sphere_positions".to_string(), particles(&centres)),
        ("sphere_radii".to_string(), column(r)),
    ]);
    if moving {
        let mass = mass_density * 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
        inputs.insert("sphere_masses".to_string(), column(mass));
    }
    Ok(inputs)
}
