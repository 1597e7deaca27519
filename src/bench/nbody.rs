//! `mesoflow bench nbody`: the direct pair mobilities (rpy_open.json, rpy_wall.json), open
//! and above a wall, translation only and the grand mobility (forces and torques): the GPU
//! time of one product end to end, pair interactions per second (N^2 / time) and the
//! arithmetic rate at the kernel's flop count per pair (`FLOPS`, counted from the WGSL:
//! every add, multiply, divide and square root one flop), to set against the adapter's
//! f32 peak (an H200's is 67 TFLOP/s).

use std::path::PathBuf;

use mesoflow::expr::ParamValue;

use super::fcm::{Rng, load, mobility_inputs, particles};
use super::{BenchError, end_to_end_clock, ms, open_gpu, time_loaded};

pub struct NbodyBench {
    pub graphs_dir: PathBuf,
    pub sizes: Vec<u32>,
    pub reps: u64,
}

/// Flops per pair of each kernel as the traversal runs it (the displacement and its
/// square, the kernel's arithmetic, the accumulation), counted by hand from
/// shaders/pairs/rpy_open.wgsl and rpy_wall.wgsl on the branch apart from contact (about
/// +-10 %; a multiply-add counts two): open translation 37, open grand 93, wall
/// translation 185, wall grand 458.
const FLOPS: [(&str, bool, f64); 4] = [
    ("rpy_open.json", false, 37.0),
    ("rpy_open.json", true, 93.0),
    ("rpy_wall.json", false, 185.0),
    ("rpy_wall.json", true, 458.0),
];

pub fn run(bench: &NbodyBench) -> Result<(), BenchError> {
    let gpu = open_gpu(bench.reps)?;
    let registry = mesoflow::nodes::registry();
    outln!(
        "one mobility product (all_pairs), a = 1, eta = 1, N particles uniform in a cube of \
         side (N / 0.05)^(1/3) (above the wall at z = 0 for rpy_wall); time: median over {} \
         runs end to end ({}); pairs/s = N^2 / time; GFLOP/s at the flops per pair counted \
         from the kernel's source",
        bench.reps,
        end_to_end_clock(&gpu)
    );
    outln!(
        "{:>14} {:>9} {:>8} {:>10} {:>12} {:>11} {:>9}",
        "graph",
        "rotation",
        "N",
        "e2e ms",
        "pairs/s",
        "flops/pair",
        "GFLOP/s"
    );
    for &(graph, rotation, flops) in &FLOPS {
        let g = load(
            &bench.graphs_dir.join(graph),
            &[("rotation", ParamValue::Bool(rotation))],
            &registry,
        )?;
        for &n in &bench.sizes {
            let side = (n as f64 / 0.05).cbrt();
            let mut rng = Rng(0x9E37_79B9_7F4A_7C15 ^ n as u64);
            let x: Vec<[f64; 3]> = (0..n)
                .map(|_| {
                    let mut p = [0, 1, 2].map(|_| (rng.uniform() - 0.5) * side);
                    p[2] += 0.5 * side + 1.0;
                    p
                })
                .collect();
            let f: Vec<[f64; 3]> = (0..n)
                .map(|_| [0, 1, 2].map(|_| rng.uniform() - 0.5))
                .collect();
            let mut inputs = mobility_inputs(&x, &f);
            let mut outputs = vec!["velocities".to_string()];
            if rotation {
                inputs.insert("torques".into(), particles(&f));
                outputs.push("angular_velocities".into());
            }
            let run = time_loaded(&gpu, &g, &inputs, Some(outputs), bench.reps, true)?;
            let seconds = run.end_to_end().as_secs_f64();
            let pairs = n as f64 * n as f64 / seconds;
            outln!(
                "{:>14} {:>9} {:>8} {:>10.4} {:>12.3e} {:>11} {:>9.0}",
                graph,
                rotation,
                n,
                ms(run.end_to_end()),
                pairs,
                flops,
                pairs * flops / 1e9
            );
        }
    }
    Ok(())
}
