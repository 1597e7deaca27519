//! Brownian disks with excluded volume kept by a Delaunay triangulation (S1, Carter et
//! al. 2017) with graphs/bd_delaunay.json: one of the paper's five two-species
//! configurations, a picture before and after, and the iterations of the flip and
//! overlap loops per step.
//!
//!     cargo run --release --example disks -- [config c0..c4] [n] [steps] [range long|short]
//!
//! The configurations are the graph's presets (`config`, nodes/disks/presets.rs: the
//! digest's reconstruction of S1's Table 1; the order of alpha and mu within c2 to c4 is
//! uncertain); the graph draws each disk's species. The disks start on the widest
//! triangular lattice of at least N sites in the box (spacing about 1.07 sigma at
//! packing 0.79) with N of its sites taken at random and a jitter of a quarter of the gap
//! (`presets::lattice_disks`: no four points near a circle, so the periodic Delaunay
//! triangulation is unique, also in f32); writes disks_<config>_start.svg and _end.svg (by species)
//! and prints the largest cluster's fraction (contact 1.02 sigma) before and after.

use std::collections::BTreeMap;
use std::path::Path;

use mesoflow::exec::{Profile, Program, RunOptions};
use mesoflow::expr::ParamValue;
use mesoflow::gpu::{GpuContext, KernelCache};
use mesoflow::graph::{self, LoadOptions};
use mesoflow::nodes::disks::clusters::{CONTACT, largest_cluster_fraction};
use mesoflow::nodes::disks::mesh::periodic_delaunay;
use mesoflow::nodes::disks::presets::{configuration, lattice_disks};
use mesoflow::nodes::disks::svg::disks_svg;
use mesoflow::plan::{self, PlanOptions};
use mesoflow::value::{HostArray, ValueType};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let name = args.get(1).map(String::as_str).unwrap_or("c1");
    let n: usize = args.get(2).map(|s| s.parse()).transpose()?.unwrap_or(400);
    let steps: u64 = args.get(3).map(|s| s.parse()).transpose()?.unwrap_or(100);
    let range = args.get(4).map(String::as_str).unwrap_or("long");
    let Some((_, fraction, first, _, density)) = configuration(name) else {
        return Err(format!("no configuration `{name}`: c0 to c4").into());
    };
    let sigma = 1.0;
    // The graph draws each disk's species (two_species, seed 1, its species stream): the
    // picture's colours come from the charges it outputs.
    let (x, _, l) = lattice_disks(n, density, sigma, fraction, 0x2545_F491_4F6C_DD1D)?;
    let mesh = periodic_delaunay(&x, [l, l])?;
    let mesh0 = mesh.clone();

    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs/bd_delaunay.json");
    let overrides = [
        ("n", ParamValue::Number(n as f64)),
        ("config", ParamValue::Text(name.to_string())),
        ("range", ParamValue::Text(range.to_string())),
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
        in_place: true,
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
    // Species 1 is the configuration's first (alpha, mu).
    let q = outputs["charges"].to_ref().data;
    let species: Vec<u32> = q
        .chunks(2)
        .map(|r| u32::from(r[0] != first[0] || r[1] != first[1]))
        .collect();
    std::fs::write(
        format!("disks_{name}_start.svg"),
        disks_svg(&x, &species, &mesh0, [l, l], sigma, 600.0 / l),
    )?;
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
    // The last step's move left these overlaps before its correction (S1's overlapping
    // fraction: the disks in at least one overlapping pair, over n).
    let overlapping = outputs["overlapping_disks"].to_ref().data;
    println!(
        "last step: {} overlapping pairs after the move, overlapping fraction {:.4}",
        overlapping[0],
        overlapping[1] / n as f64
    );
    println!(
        "largest cluster (contact {CONTACT} sigma): {:.3} of the disks at the start, {:.3} at the end",
        largest_cluster_fraction(&mesh0, &x, [l, l], sigma),
        largest_cluster_fraction(&end_mesh, &end_x, [l, l], sigma)
    );
    println!("pictures: disks_{name}_start.svg, disks_{name}_end.svg");
    Ok(())
}
