//! Molecular dynamics of charged soft spheres with graphs/md_charged.json, from the
//! library: a neutral rock-salt-like lattice of Gaussian charges with random velocities,
//! velocity Verlet with the Poisson forces plus a WCA repulsion, and the energy drift.
//!
//!     cargo run --release --example charged_md -- [steps] [dt]
//!
//! Prints the total energy at the start and end, its largest excursion over the run, and
//! the excursion relative to the kinetic energy (velocity Verlet's is O(dt^2): halve dt,
//! a quarter of it).

use std::collections::BTreeMap;
use std::path::Path;

use mesoflow::exec::{Profile, Program, RunOptions};
use mesoflow::expr::ParamValue;
use mesoflow::gpu::{GpuContext, KernelCache};
use mesoflow::graph::{self, LoadOptions};
use mesoflow::plan::{self, PlanOptions};
use mesoflow::value::{HostArray, ValueType};

fn array(rows: &[f64], k: u32) -> HostArray {
    HostArray::f32(
        ValueType::Particles {
            n: rows.len() as u32 / k,
            k,
        },
        rows.iter().map(|&x| x as f32).collect(),
    )
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let steps: u64 = args.get(1).map(|s| s.parse()).transpose()?.unwrap_or(500);
    let dt: f64 = args.get(2).map(|s| s.parse()).transpose()?.unwrap_or(0.01);
    let (per_side, spacing) = (6usize, 2.5);
    let side = spacing * per_side as f64;

    // A jittered lattice of alternating charges, velocities uniform in [-1, 1) without net
    // momentum (a small xorshift: the example needs no random crate).
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let (mut x, mut v, mut q) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..per_side {
        for j in 0..per_side {
            for k in 0..per_side {
                for c in [i, j, k] {
                    x.push((c as f64 + 0.5) * spacing - side / 2.0 + 0.4 * (uniform() - 0.5));
                }
                for _ in 0..3 {
                    v.push(2.0 * uniform() - 1.0);
                }
                q.push(if (i + j + k) % 2 == 0 { 1.0 } else { -1.0 });
            }
        }
    }
    let n = q.len();
    for c in 0..3 {
        let mean = (0..n).map(|p| v[3 * p + c]).sum::<f64>() / n as f64;
        (0..n).for_each(|p| v[3 * p + c] -= mean);
    }

    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs/md_charged.json");
    let overrides = [
        ("box", ParamValue::Numbers(vec![side; 3])),
        ("dt", ParamValue::Number(dt)),
        ("wca_sigma", ParamValue::Number(1.2)),
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
    let inputs: BTreeMap<String, HostArray> = [
        ("positions".to_string(), array(&x, 3)),
        ("velocities".to_string(), array(&v, 3)),
        ("charges".to_string(), array(&q, 1)),
    ]
    .into_iter()
    .collect();
    let gpu = GpuContext::new()?;
    let opts = PlanOptions {
        outputs: Some(vec!["energies".into(), "kinetic_energy".into()]),
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
    let outputs: BTreeMap<String, HostArray> = program.read_outputs()?.into_iter().collect();
    let elapsed = started.elapsed();
    let e = outputs["energies"].to_ref().data;
    let kinetic0 = 0.5 * v.iter().map(|c| c * c).sum::<f64>();
    let (lo, hi) = e
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &y| {
            (a.min(y), b.max(y))
        });
    println!(
        "{n} charged soft spheres (width 0.5, WCA sigma 1.2) in a periodic box of side {side}, {steps} steps of dt = {dt} on {} in {:.2} s",
        gpu.caps.summary(),
        elapsed.as_secs_f64()
    );
    println!(
        "total energy: first step {:.7}, last step {:.7}, drift {:.3e}; excursion over the run {:.3e} = {:.2e} of the initial kinetic energy {kinetic0:.4}",
        e[0],
        e[e.len() - 1],
        e[e.len() - 1] - e[0],
        hi - lo,
        (hi - lo) / kinetic0
    );
    println!(
        "kinetic energy after the run: {:.4}",
        outputs["kinetic_energy"].to_ref().data[0]
    );
    Ok(())
}
