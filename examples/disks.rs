//! Brownian disks with excluded volume kept by a Delaunay triangulation (S1, Carter et
//! al. 2017) with graphs/bd_delaunay.json: one of the paper's five two-species
//! configurations, a picture before and after, and the iterations of the flip and
//! overlap loops per step.
//!
//!     cargo run --release --example disks -- [config c0..c4] [n] [steps] [range long|short]
//!
//! The configurations are the digest's reconstruction of S1's Table 1 (the extracted
//! table was scrambled; the order of alpha and mu within c2 to c4 is uncertain). The
//! disks start on a triangular lattice of spacing at least sigma with N of its sites
//! taken at random and a 1e-4 sigma jitter (no four points on a circle, so the periodic
//! Delaunay triangulation is unique); writes disks_<config>_start.svg and _end.svg.

use std::collections::BTreeMap;
use std::path::Path;

use mesoflow::exec::{Profile, Program, RunOptions};
use mesoflow::expr::ParamValue;
use mesoflow::gpu::{GpuContext, KernelCache};
use mesoflow::graph::{self, LoadOptions};
use mesoflow::nodes::disks::mesh::periodic_delaunay;
use mesoflow::nodes::disks::svg::disks_svg;
use mesoflow::plan::{self, PlanOptions};
use mesoflow::value::{HostArray, ValueType};

/// A configuration: name, fraction of species 1, (alpha, mu) of species 1 and 2,
/// packing fraction.
type Config = (&'static str, f64, [f64; 2], [f64; 2], f64);

const CONFIGS: [Config; 5] = [
    ("c0", 0.7, [1.0, 1.0], [-1.0, 1.0], 0.79),
    ("c1", 0.5, [1.0, 1.0], [-1.0, 1.0], 0.52),
    ("c2", 0.5, [1.0, 1.0], [-1.0, -2.0], 0.52),
    ("c3", 0.5, [1.0, -1.0], [-2.0, 1.0], 0.79),
    ("c4", 0.5, [1.0, 1.0], [-1.0, -4.0], 0.0873),
];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let name = args.get(1).map(String::as_str).unwrap_or("c1");
    let n: usize = args.get(2).map(|s| s.parse()).transpose()?.unwrap_or(400);
    let steps: u64 = args.get(3).map(|s| s.parse()).transpose()?.unwrap_or(100);
    let range = args.get(4).map(String::as_str).unwrap_or("long");
    let Some(&(_, phi1, q1, q2, density)) = CONFIGS.iter().find(|c| c.0 == name) else {
        return Err(format!("no configuration `{name}`: c0 to c4").into());
    };
    let sigma = 1.0;
    let l = (n as f64 * std::f64::consts::PI * 0.25 * sigma * sigma / density).sqrt();

    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    // A triangular lattice filling the box with spacing >= sigma (an even number of rows
    // for the periodic stacking), N sites drawn without replacement.
    let nx = (l / sigma).floor() as usize;
    let ny = 2 * (l / (sigma * 3f64.sqrt())).floor() as usize;
    if nx * ny < n {
        return Err(format!(
            "{n} disks do not fit the lattice of {nx} x {ny} sites in a box of {l:.2}"
        )
        .into());
    }
    let (ax, ay) = (l / nx as f64, l / ny as f64);
    let mut sites: Vec<[f64; 2]> = (0..ny)
        .flat_map(|j| {
            (0..nx).map(move |i| {
                let shift = if j % 2 == 1 { 0.5 * ax } else { 0.0 };
                [i as f64 * ax + shift - 0.5 * l, j as f64 * ay - 0.5 * l]
            })
        })
        .collect();
    let last = sites.len() - 1;
    for i in 0..n {
        let j = i + (uniform() * (sites.len() - i) as f64) as usize;
        sites.swap(i, j.min(last));
    }
    let x: Vec<f64> = sites[..n]
        .iter()
        .flat_map(|p| p.map(|c| c + 1e-4 * sigma * (uniform() - 0.5)))
        .collect();
    let species: Vec<u32> = (0..n).map(|_| (uniform() >= phi1) as u32).collect();
    let charges: Vec<f64> = species
        .iter()
        .flat_map(|&s| if s == 0 { q1 } else { q2 })
        .collect();
    let mesh = periodic_delaunay(&x, [l, l])?;
    std::fs::write(
        format!("disks_{name}_start.svg"),
        disks_svg(&x, &species, &mesh, [l, l], sigma, 600.0 / l),
    )?;

    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs/bd_delaunay.json");
    let overrides = [
        ("n", ParamValue::Number(n as f64)),
        ("density", ParamValue::Number(density)),
        ("range", ParamValue::Text(range.to_string())),
        (
            "cutoff",
            ParamValue::Number(if range == "short" { 2.5 * sigma } else { 0.0 }),
        ),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    let registry = mesoflow::nodes::registry();
    let g = graph::load(
        &path,
        &registry,
        &LoadOptions {
            overrides,
            steps,
            seed: 1,
        },
    )?;
    let f32s = |v: &[f64]| v.iter().map(|&c| c as f32).collect::<Vec<f32>>();
    let inputs: BTreeMap<String, HostArray> = [
        (
            "positions".to_string(),
            HostArray::f32(ValueType::Particles { n: n as u32, k: 2 }, f32s(&x)),
        ),
        (
            "charges".to_string(),
            HostArray::f32(ValueType::Particles { n: n as u32, k: 2 }, f32s(&charges)),
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
    ]
    .into_iter()
    .collect();
    let gpu = GpuContext::new()?;
    let opts = PlanOptions {
        outputs: None,
        inputs: inputs.iter().map(|(k, a)| (k.clone(), a.ty)).collect(),
        fuse: true,
    };
    let p = plan::plan(&g, &opts, &gpu.caps)?;
    let mut program = Program::compile(&gpu, &g, &p, &mut KernelCache::default())?;
    program.upload(&inputs)?;
    let started = std::time::Instant::now();
    program.run(&RunOptions {
        steps,
        profile: Profile::Off,
        progress: false,
    })?;
    let elapsed = started.elapsed();
    let outputs: BTreeMap<String, HostArray> = program.read_outputs()?.into_iter().collect();
    let end_x = outputs["positions"].to_ref().data;
    let end_mesh: Vec<u32> = outputs["mesh"]
        .to_ref()
        .data
        .iter()
        .map(|&v| v as u32)
        .collect();
    std::fs::write(
        format!("disks_{name}_end.svg"),
        disks_svg(&end_x, &species, &end_mesh, [l, l], sigma, 600.0 / l),
    )?;
    println!(
        "{name}: {n} disks, packing {density} (box {l:.2}), {range} range, {steps} steps on {} in {:.2} s",
        gpu.caps.summary(),
        elapsed.as_secs_f64()
    );
    for (label, counts) in program.loop_iterations() {
        let mean = counts.iter().map(|&c| c as f64).sum::<f64>() / counts.len().max(1) as f64;
        let max = counts.iter().max().copied().unwrap_or(0);
        println!(
            "loop {label}: {mean:.2} iterations per step (the last of each finding nothing), at most {max}"
        );
    }
    println!("pictures: disks_{name}_start.svg, disks_{name}_end.svg");
    Ok(())
}
