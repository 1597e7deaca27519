//! graphs/bd_delaunay.json end to end, step by step: after every step the mesh is a valid
//! triangulation of the torus with no inverted triangle and no illegal edge (f64, within
//! the f32 tolerance), no pair of disks (all pairs) overlaps, and no edge was passed
//! through; the same bit for bit with the flip loops' meshes written in place or copied.

use std::collections::BTreeMap;

use mesoflow::exec::{Profile, Program, RunOptions};
use mesoflow::gpu::KernelCache;
use mesoflow::nodes::disks::mesh::{check_torus_mesh, illegal_edges, periodic_delaunay};
use mesoflow::nodes::disks::minimum_image;
use mesoflow::plan::{self, PlanOptions};
use mesoflow::value::{HostArray, HostData};

use crate::util::disks::{
    disk_graph_inputs, disk_positions, lattice_disks, random_headings, run_with_loops_planned,
};
use crate::util::{Rng, flat_particles, gpu, load_with, types_of, u32s};

/// The smallest distance between two of the disks (minimum image, all pairs).
fn closest_pair(x: &[f64], l: f64) -> f64 {
    let n = x.len() / 2;
    let mut closest = f64::INFINITY;
    for i in 0..n {
        for j in i + 1..n {
            let r = [0, 1].map(|a| minimum_image(x[2 * j + a] - x[2 * i + a], l));
            closest = closest.min(r[0].hypot(r[1]));
        }
    }
    closest
}

/// 256 disks of S1's c1 (half alpha = mu = 1, half alpha = -1, mu = 1) at packing 0.4,
/// long-range forces, S1's dt and D, 6 steps.
#[test]
fn bd_delaunay_keeps_a_delaunay_mesh_and_no_overlaps_every_step() {
    let Some(gpu) = gpu() else { return };
    let (n, density) = (256usize, 0.4);
    let l = (n as f64 * std::f64::consts::PI / 4.0 / density).sqrt();
    let mut rng = Rng::new(43);
    let x0: Vec<f64> = disk_positions(&mut rng, n, [l, l], 1.0)
        .iter()
        .map(|&v| v as f32 as f64)
        .collect();
    let charges: Vec<f64> = (0..n)
        .flat_map(|i| if i % 2 == 0 { [1.0, 1.0] } else { [-1.0, 1.0] })
        .collect();
    let mesh = periodic_delaunay(&x0, [l, l]).unwrap();
    let inputs = disk_graph_inputs(&x0, &mesh, [("charges", flat_particles(&charges, 2))]);
    let steps = 6;
    let g = load_with(
        "bd_delaunay.json",
        &[("n", "256"), ("density", "0.4"), ("config", "\"custom\"")],
        steps,
        5,
    );
    let opts = PlanOptions {
        outputs: None,
        inputs: types_of(&inputs),
        fuse: true,
        in_place: true,
    };
    let p = plan::plan(&g, &opts, &gpu.caps).unwrap();
    let mut cache = KernelCache::default();
    let mut program = Program::compile(&gpu, &g, &p, &mut cache).unwrap();
    program.upload(&inputs).unwrap();
    let mut previous = x0;
    for step in 0..steps {
        let one = RunOptions {
            steps: 1,
            profile: Profile::Off,
            progress: false,
        };
        program.run_on(&one).unwrap();
        let out: BTreeMap<String, HostArray> =
            program.read_outputs().unwrap().into_iter().collect();
        let x = out["positions"].data.to_f64();
        let mesh = u32s(&out["mesh"]);
        assert_eq!(u32s(&out["pass_throughs"]), vec![0], "step {step}");
        let stats =
            check_torus_mesh(&mesh, &x, [l, l]).unwrap_or_else(|e| panic!("step {step}: {e}"));
        assert_eq!(stats.inverted, 0, "step {step}");
        // The GPU flips above 1e-5 m^2 in f32: the f64 check allows the f32 band.
        assert_eq!(
            illegal_edges(&mesh, &x, [l, l], 2e-5),
            Vec::<usize>::new(),
            "step {step}"
        );
        let closest = closest_pair(&x, l);
        assert!(closest >= 1.0 - 1e-5, "step {step}: closest pair {closest}");
        // The move's overlaps (the correction loop's count after its first round,
        // `repeat`'s `first`): among the pairs all rounds counted, none where one round
        // sufficed, and two to twice as many disks as pairs.
        let [pairs, disks] = u32s(&out["overlapping_disks"])[..] else {
            panic!("step {step}: overlapping_disks holds two words")
        };
        let total = u32s(&out["overlapping_pairs"])[0];
        let rounds = u32s(&out["overlap_rounds"])[0];
        assert!(pairs <= total, "step {step}: {pairs} of {total}");
        assert_eq!(
            rounds == 1,
            pairs == 0,
            "step {step}: {rounds} rounds, {pairs} pairs"
        );
        assert!(
            (pairs == 0 && disks == 0) || (2..=2 * pairs).contains(&disks),
            "step {step}: {disks} disks in {pairs} pairs"
        );
        let moved = (0..n)
            .map(|i| {
                let d = [0, 1].map(|a| minimum_image(x[2 * i + a] - previous[2 * i + a], l));
                d[0].hypot(d[1])
            })
            .fold(0.0, f64::max);
        assert!(
            moved > 0.0 && moved < 1.0,
            "step {step}: largest move {moved}"
        );
        previous = x;
    }
    let loops = program.loop_iterations().to_vec();
    let flips = &loops
        .iter()
        .find(|(name, _)| name == "flips")
        .expect("flip loop")
        .1;
    let overlaps = &loops
        .iter()
        .find(|(name, _)| name == "overlaps")
        .expect("overlap loop")
        .1;
    assert_eq!(flips.len(), steps as usize);
    assert!(flips.iter().all(|&k| k >= 1) && overlaps.iter().all(|&k| k >= 1));
    eprintln!("flip rounds per step {flips:?}, overlap rounds per step {overlaps:?}");
}

/// graphs/abp_delaunay.json, dilute (packing 0.005, mean free path ~80 sigma against
/// 5 sigma run): 400 active disks' mean squared displacement after K steps against the
/// exact discrete law V0^2 dt^2 sum_(j,k < K) exp(-D dt |j - k|) (the headings a random
/// walk of variance 2 D dt a step), the headings' spread 2 D dt K, and after the run a
/// valid Delaunay torus mesh with no overlapping pair.
#[test]
fn abp_delaunay_disks_follow_the_active_msd_and_never_overlap() {
    let Some(gpu) = gpu() else { return };
    let (n, density, speed, dt, d) = (400usize, 0.005, 1.0, 0.05, 0.5);
    let steps = 100u64;
    let l = (n as f64 * std::f64::consts::PI / 4.0 / density).sqrt();
    let mut rng = Rng::new(71);
    let x0: Vec<f64> = disk_positions(&mut rng, n, [l, l], 1.0)
        .iter()
        .map(|&v| v as f32 as f64)
        .collect();
    let theta0 = random_headings(&mut rng, n);
    let mesh = periodic_delaunay(&x0, [l, l]).unwrap();
    let inputs = disk_graph_inputs(&x0, &mesh, [("angles", flat_particles(&theta0, 1))]);
    let g = load_with(
        "abp_delaunay.json",
        &[
            ("n", "400"),
            ("density", "0.005"),
            ("speed", "1"),
            ("dt", "0.05"),
            ("diffusion", "0.5"),
        ],
        steps,
        9,
    );
    let out = crate::util::run_graph(&gpu, &g, &inputs, None, steps, true);
    let x = out["positions"].data.to_f64();
    let theta = out["angles"].data.to_f64();
    let msd = (0..n)
        .map(|i| {
            let r = [0, 1].map(|a| minimum_image(x[2 * i + a] - x0[2 * i + a], l));
            r[0] * r[0] + r[1] * r[1]
        })
        .sum::<f64>()
        / n as f64;
    let k = steps as i64;
    let want = speed
        * speed
        * dt
        * dt
        * (0..k)
            .flat_map(|a| (0..k).map(move |b| (a - b).abs()))
            .map(|m| (-d * dt * m as f64).exp())
            .sum::<f64>();
    let spread = (0..n).map(|i| (theta[i] - theta0[i]).powi(2)).sum::<f64>() / n as f64;
    let closest = closest_pair(&x, l);
    eprintln!(
        "MSD {msd} vs {want}; heading spread {spread} vs {}; closest pair {closest}",
        2.0 * d * dt * steps as f64
    );
    // One disk's |r|^2 at D t = 2.5 has a relative standard deviation below 0.7, so the
    // mean over 400 about 3.5%: 15% is 4 of those (rare collisions shorten runs by less).
    assert!((msd / want - 1.0).abs() < 0.15, "MSD {msd} vs {want}");
    // The mean of 400 squared normals: relative standard deviation sqrt(2/400) = 7%.
    let spread_want = 2.0 * d * dt * steps as f64;
    assert!(
        (spread / spread_want - 1.0).abs() < 0.3,
        "{spread} vs {spread_want}"
    );
    assert!(closest >= 1.0 - 1e-4, "closest pair {closest}");
    let final_mesh = u32s(&out["mesh"]);
    let stats = check_torus_mesh(&final_mesh, &x, [l, l]).unwrap();
    assert_eq!(stats.inverted, 0);
    assert_eq!(u32s(&out["pass_throughs"]), vec![0]);
}

/// The words of an array, f32 as their bits: equal words are bit for bit equal results.
fn words(a: &HostArray) -> Vec<u32> {
    match &a.data {
        HostData::F32(v) => v.iter().map(|x| x.to_bits()).collect(),
        HostData::U32(v) => v.clone(),
    }
}

/// bd_delaunay.json with its flip loops' meshes written in place (the plan's default) and
/// copied (`PlanOptions::in_place` off): 256 disks of c0 at packing 0.79, 4 steps, every
/// output (positions, mesh, forces, flip rounds, flips, settle flips) and the loops'
/// iterations per step bit for bit the same.
#[test]
fn bd_delaunay_is_the_same_with_its_meshes_in_place_or_copied() {
    let Some(gpu) = gpu() else { return };
    let n = 256usize;
    let mut rng = Rng::new(53);
    let (x0, l) = lattice_disks(&mut rng, n, 0.79, 1.0);
    let mesh = periodic_delaunay(&x0, [l, l]).unwrap();
    let inputs = disk_graph_inputs(&x0, &mesh, []);
    let steps = 4;
    let g = load_with(
        "bd_delaunay.json",
        &[("n", "256"), ("config", "\"c0\"")],
        steps,
        7,
    );
    let runs = [true, false].map(|in_place| {
        run_with_loops_planned(&gpu, &g, &inputs, steps, Profile::Off, in_place)
            .unwrap_or_else(|e| panic!("in place {in_place}: {e}"))
    });
    let [(a, loops_a), (b, loops_b)] = &runs;
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (name, v) in a {
        assert_eq!(words(v), words(&b[name]), "output {name}");
    }
    assert_eq!(loops_a, loops_b);
    let flips = &loops_a
        .iter()
        .find(|(l, _)| l == "flips")
        .expect("flip loop")
        .1;
    assert!(flips.iter().all(|&k| k >= 1), "{loops_a:?}");
    eprintln!("loop iterations per step {loops_a:?}");
}
