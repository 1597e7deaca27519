//! Deterministic runs (`DeviceCaps::deterministic`, `run --deterministic`): every shipped
//! graph gives the same bits twice, also with its dispatches folded differently (a
//! lower workgroup cap: other threads take other particles); spreading's fixed-point sums
//! do not depend on the order of the particles; bin_sort is stable; and the results stay
//! within the graphs' tolerances of the f64 references.

use std::collections::BTreeMap;
use std::f64::consts::PI;

use mesoflow::gpu::GpuContext;
use mesoflow::value::{HostArray, HostData, ValueType};

use crate::util::mobility::{eval, fourier_mobility, hasimoto, mobility_plan, random_positions};
use crate::util::{
    Rng, compile_cached, gpu, indices, load_with, rel_max_err, run_graph, run_node, u32s, with_caps,
};

/// An array's words as bits (f32 or u32), for bitwise comparison.
fn bits(a: &HostArray) -> Vec<u32> {
    match &a.data {
        HostData::F32(v) => v.iter().map(|x| x.to_bits()).collect(),
        HostData::U32(v) => v.clone(),
    }
}

/// Words of `a` and `b` that differ, and the largest relative difference among them.
fn differences(a: &HostArray, b: &HostArray) -> (usize, f64) {
    let (x, y) = (bits(a), bits(b));
    assert_eq!(x.len(), y.len());
    let mut worst: f64 = 0.0;
    let mut n = 0;
    for (p, q) in x.iter().zip(&y) {
        if p != q {
            n += 1;
            if let HostData::F32(_) = a.data {
                let (u, v) = (f32::from_bits(*p) as f64, f32::from_bits(*q) as f64);
                worst = worst.max((u - v).abs() / u.abs().max(v.abs()).max(1e-30));
            }
        }
    }
    (n, worst)
}

/// Random particle rows in [-2, 2)^cols (inside every shipped graph's default box and
/// the small ones below).
fn rows(rng: &mut Rng, n: u32, cols: u32) -> HostArray {
    rng.array(ValueType::Particles { n, k: cols }, -2.0, 2.0)
}

/// One shipped graph at a small size: file, `--set` values, steps, the inputs given
/// (name, rows, columns), and the outputs compared (all for `None`).
struct Case {
    file: &'static str,
    sets: &'static [(&'static str, &'static str)],
    steps: u64,
    inputs: &'static [(&'static str, u32, u32)],
    outputs: Option<&'static [&'static str]>,
}

/// FCM's outputs but the angular velocities (which need torques and a finer rotation
/// grid than these small boxes give).
const FCM_OUTPUTS: Option<&[&str]> = Some(&["velocities", "noise", "fluctuating_velocities"]);

const PARTICLES: &[(&str, u32, u32)] = &[("positions", 48, 3), ("forces", 48, 3)];

/// Every graph under graphs/ (and graphs/examples/) that runs, at sizes lavapipe takes.
const CASES: &[Case] = &[
    Case {
        file: "fcm.json",
        sets: &[("box", "[8, 8, 8]"), ("temperature", "1")],
        steps: 1,
        inputs: PARTICLES,
        outputs: FCM_OUTPUTS,
    },
    Case {
        // The sorted path: bin_sort by Morton block, then the box or tile kernels.
        file: "fcm.json",
        sets: &[
            ("box", "[8, 8, 8]"),
            ("sort_particles", "true"),
            ("temperature", "1"),
        ],
        steps: 1,
        inputs: PARTICLES,
        outputs: FCM_OUTPUTS,
    },
    Case {
        file: "fcm.json",
        sets: &[
            ("box", "[8, 8, 8]"),
            ("spread_tiles", "\"on\""),
            ("temperature", "1"),
        ],
        steps: 1,
        inputs: PARTICLES,
        outputs: FCM_OUTPUTS,
    },
    Case {
        file: "pse.json",
        sets: &[("box", "[10, 10, 10]"), ("temperature", "1")],
        steps: 1,
        inputs: PARTICLES,
        outputs: None,
    },
    Case {
        file: "poisson.json",
        // An 8^3 grid (the planner takes at least 32): FFTs fold their dispatches
        // within the second run's two workgroups per dimension only that small.
        sets: &[("box", "[8, 8, 8]"), ("split", "0"), ("grid", "[8, 8, 8]")],
        steps: 1,
        inputs: &[("positions", 48, 3), ("charges", 48, 1)],
        outputs: None,
    },
    Case {
        file: "poisson.json",
        sets: &[
            ("box", "[8, 8, 8]"),
            ("width", "0.3"),
            ("split", "2"),
            ("grid", "[8, 8, 8]"),
        ],
        steps: 1,
        inputs: &[("positions", 48, 3), ("charges", 48, 1)],
        outputs: None,
    },
    Case {
        file: "rpy_open.json",
        sets: &[("temperature", "1"), ("rotation", "true")],
        steps: 1,
        inputs: &[("positions", 48, 3), ("forces", 48, 3), ("torques", 48, 3)],
        outputs: None,
    },
    Case {
        file: "rpy_wall.json",
        sets: &[
            ("temperature", "1"),
            ("rotation", "true"),
            ("wall_height", "-3"),
        ],
        steps: 1,
        inputs: &[("positions", 48, 3), ("forces", 48, 3), ("torques", 48, 3)],
        outputs: None,
    },
    Case {
        file: "bd_fcm.json",
        sets: &[("box", "[8, 8, 8]")],
        steps: 2,
        inputs: &[("positions", 32, 3)],
        outputs: None,
    },
    Case {
        file: "mpcd.json",
        sets: &[("box", "[6, 6, 6]"), ("density", "5")],
        steps: 3,
        inputs: &[],
        outputs: None,
    },
    Case {
        file: "mpcd2d.json",
        sets: &[("box", "[8, 8]"), ("density", "5")],
        steps: 3,
        inputs: &[],
        outputs: None,
    },
    Case {
        file: "mpcd_solute.json",
        sets: &[("box", "[6, 6, 6]"), ("density", "5")],
        steps: 3,
        inputs: &[("solute_positions", 4, 3), ("solute_velocities", 4, 3)],
        outputs: None,
    },
    Case {
        // Sphere radii are given as 1.5 and masses drawn positive (run_twice), not drawn
        // as the other rows.
        file: "mpcd_spheres.json",
        sets: &[
            ("box", "[8, 8, 8]"),
            ("density", "5"),
            ("sphere_radius", "1.5"),
            ("spheres", "\"moving\""),
        ],
        steps: 3,
        inputs: &[
            ("sphere_positions", 2, 3),
            ("sphere_radii", 2, 1),
            ("sphere_masses", 2, 1),
        ],
        outputs: None,
    },
    Case {
        file: "examples/colloids.json",
        sets: &[("n", "64"), ("side", "8")],
        steps: 3,
        inputs: &[],
        outputs: None,
    },
    Case {
        // Three FCM evaluations per step, their streams apart.
        file: "lib/integrators/midpoint.json",
        sets: &[
            ("mobility", "\"fcm.json\""),
            ("mobility.box", "[8, 8, 8]"),
            ("forces", "\"lib/forces/harmonic_trap.json\""),
        ],
        steps: 2,
        inputs: &[("positions", 32, 3)],
        outputs: None,
    },
    Case {
        file: "lib/integrators/langevin_gjf.json",
        sets: &[("forces", "\"lib/forces/harmonic_trap.json\"")],
        steps: 2,
        inputs: &[("positions", 32, 3), ("velocities", 32, 3)],
        outputs: None,
    },
    Case {
        file: "examples/relax.json",
        sets: &[],
        steps: 2,
        inputs: &[("positions", 32, 3)],
        outputs: None,
    },
    Case {
        file: "examples/trap_bd.json",
        sets: &[("n", "256")],
        steps: 2,
        inputs: &[],
        outputs: None,
    },
];

/// Runs every case twice (the second time with at most 2 workgroups per dispatch
/// dimension: the same kernels over folded grids, other threads on other elements) and
/// returns, per case and output, the words that differ and their largest relative
/// difference.
fn run_twice(gpu: &mut GpuContext, deterministic: bool) -> Vec<(String, usize, f64)> {
    let mut found = Vec::new();
    for (i, case) in CASES.iter().enumerate() {
        let g = load_with(case.file, case.sets, case.steps, 7);
        let mut rng = Rng::new(100 + i as u64);
        let inputs: BTreeMap<String, HostArray> = case
            .inputs
            .iter()
            .map(|&(name, n, k)| {
                // Positive sizes: mpcd_spheres.json's radii (its per-sphere virtual
                // particle count is set for 1.5) and masses; its two spheres apart.
                let a = match name {
                    "sphere_radii" => rng.array(ValueType::Particles { n, k }, 1.5, 1.5),
                    "sphere_masses" => rng.array(ValueType::Particles { n, k }, 50.0, 100.0),
                    // Spheres apart (overlapping ones are refused).
                    "sphere_positions" => HostArray::f32(
                        ValueType::Particles { n, k },
                        (0..n * k).map(|i| if i < k { -2.0 } else { 1.5 }).collect(),
                    ),
                    _ => rows(&mut rng, n, k),
                };
                (name.to_string(), a)
            })
            .collect();
        let first = with_caps(
            gpu,
            |c| c.deterministic = deterministic,
            |gpu| run_graph(gpu, &g, &inputs, case.outputs, case.steps, true),
        );
        let second = with_caps(
            gpu,
            |c| {
                c.deterministic = deterministic;
                c.max_workgroups_per_dim = 2;
            },
            |gpu| run_graph(gpu, &g, &inputs, case.outputs, case.steps, true),
        );
        assert!(!first.is_empty(), "{}: no outputs", case.file);
        for (name, a) in &first {
            let (n, worst) = differences(a, &second[name]);
            found.push((format!("{} {:?}: {name}", case.file, case.sets), n, worst));
        }
    }
    found
}

#[test]
fn every_shipped_graph_is_bitwise_reproducible() {
    let Some(mut gpu) = gpu() else { return };
    let found = run_twice(&mut gpu, true);
    let differ: Vec<_> = found.iter().filter(|(_, n, _)| *n > 0).collect();
    for (what, n, worst) in &found {
        eprintln!("{what}: {n} words differ (largest relative {worst:.1e})");
    }
    assert!(differ.is_empty(), "deterministic runs differ: {differ:?}");
}

/// Spreading params of one strategy on a 16^3 grid of side 8 (a Gaussian of support 8).
fn spread_params(strategy: &str) -> String {
    format!(
        r#"{{"box": [8, 8, 8], "grid": [16, 16, 16], "window": "gaussian", "width": 0.5, "tolerance": 1e-4, {strategy}}}"#
    )
}

/// The particles in reverse order, rows of `k` words.
fn reversed(a: &HostArray, k: usize) -> HostArray {
    let HostData::F32(v) = &a.data else {
        panic!("f32 rows")
    };
    let rows: Vec<f32> = v.chunks(k).rev().flatten().copied().collect();
    HostArray::f32(a.ty, rows)
}

#[test]
fn deterministic_spreading_does_not_depend_on_the_order_of_the_particles() {
    // The per-particle kernels add each particle's w v on its own: with integer sums the
    // grid is the same bits whatever order the particles (and so the atomics) come in.
    // With float atomics the order rounds differently (tested below as the contrast).
    let Some(mut gpu) = gpu() else { return };
    let mut rng = Rng::new(3);
    let n = 400;
    let pos = rng.array(ValueType::Particles { n, k: 3 }, -4.0, 4.0);
    let vals = rng.array(ValueType::Particles { n, k: 3 }, -1.0, 1.0);
    let forward: BTreeMap<String, HostArray> = [
        ("positions".into(), pos.clone()),
        ("values".into(), vals.clone()),
    ]
    .into();
    let backward: BTreeMap<String, HostArray> = [
        ("positions".into(), reversed(&pos, 3)),
        ("values".into(), reversed(&vals, 3)),
    ]
    .into();
    for strategy in [r#""lanes": "auto""#, r#""lanes": "off""#] {
        let p = spread_params(strategy);
        let (a, b) = with_caps(
            &mut gpu,
            |c| c.deterministic = true,
            |gpu| {
                (
                    run_node(gpu, "spread", &p, &forward).remove("out").unwrap(),
                    run_node(gpu, "spread", &p, &backward)
                        .remove("out")
                        .unwrap(),
                )
            },
        );
        let (differ, worst) = differences(&a, &b);
        assert_eq!(
            differ, 0,
            "{strategy}: {differ} words differ between the two orders (largest relative {worst:e})"
        );
        // And the fixed-point grid is the f64 reference's within f32 rounding.
        let want = &crate::util::reference(
            "spread",
            &p,
            &[Some(&forward["positions"]), Some(&forward["values"])],
        )[0];
        let (err, _) = rel_max_err(&a, want);
        assert!(err < crate::util::spread::TOL, "{strategy}: error {err:e}");
    }
}

#[test]
fn float_atomic_spreading_depends_on_the_order_of_the_particles() {
    // The contrast that makes the test above meaningful on any adapter (lavapipe may
    // well run its atomics in one order from run to run): the default plan's float adds
    // round differently when the particles come in another order.
    let Some(gpu) = gpu() else { return };
    let mut rng = Rng::new(3);
    let n = 400;
    let pos = rng.array(ValueType::Particles { n, k: 3 }, -4.0, 4.0);
    let vals = rng.array(ValueType::Particles { n, k: 3 }, -1.0, 1.0);
    let forward: BTreeMap<String, HostArray> = [
        ("positions".into(), pos.clone()),
        ("values".into(), vals.clone()),
    ]
    .into();
    let backward: BTreeMap<String, HostArray> = [
        ("positions".into(), reversed(&pos, 3)),
        ("values".into(), reversed(&vals, 3)),
    ]
    .into();
    let p = spread_params(r#""lanes": "off""#);
    let a = run_node(&gpu, "spread", &p, &forward)
        .remove("out")
        .unwrap();
    let b = run_node(&gpu, "spread", &p, &backward)
        .remove("out")
        .unwrap();
    let (differ, worst) = differences(&a, &b);
    eprintln!(
        "float atomics: {differ} words differ between the two orders (largest relative {worst:.1e})"
    );
    assert!(
        differ > 0,
        "float atomic sums came out the same in both orders"
    );
}

#[test]
fn deterministic_bin_sort_is_stable_inside_a_bin() {
    // Many keys in few bins, so that workgroups meet at every counter: the order inside
    // a bin is then the input order, exactly the stable reference's.
    let Some(mut gpu) = gpu() else { return };
    let n = 20000;
    let keys: Vec<u32> = crate::util::random_keys(n, 20, 11);
    let data: BTreeMap<String, HostArray> = [("keys".into(), indices(&keys))].into();
    let params = r#"{"bins": 16}"#;
    let out = with_caps(
        &mut gpu,
        |c| c.deterministic = true,
        |gpu| run_node(gpu, "bin_sort", params, &data),
    );
    let perm = u32s(&out["perm"]);
    let mut want: Vec<u32> = (0..n as u32).collect();
    want.sort_by_key(|&i| keys[i as usize].min(16));
    let moved = perm.iter().zip(&want).filter(|(a, b)| a != b).count();
    assert_eq!(moved, 0, "{moved} slots out of stable order");
    let sorted: Vec<u32> = want.iter().map(|&i| keys[i as usize]).collect();
    assert_eq!(u32s(&out["keys"]), sorted);
}

#[test]
fn deterministic_fcm_and_pse_stay_within_their_tolerances() {
    // The graphs' own accuracy checks, planned deterministic: FCM's self-mobility against
    // the f64 Fourier sum of its Gaussian, PSE's pair mobility against the f64 Ewald sum,
    // at 1e-3 and 1e-4; and each within f32 rounding of the default plan's result.
    let Some(mut gpu) = gpu() else { return };
    let l = 16.0;
    let sigma = 1.0 / PI.sqrt();
    let fcm_exact = fourier_mobility([0.0; 3], [l; 3], 1.0, sigma, sigma)[0][0];
    let m_self = hasimoto(1.0, l) / (6.0 * PI);
    let mut rng = Rng::new(21);
    for tol in [1e-3, 1e-4] {
        let sets_owned = [
            ("box", format!("[{l}, {l}, {l}]")),
            ("tolerance", tol.to_string()),
        ];
        let sets: Vec<(&str, &str)> = sets_owned.iter().map(|(k, v)| (*k, v.as_str())).collect();
        let spots = random_positions(&mut rng, 3, [l; 3]);
        let fcm = load_with("fcm.json", &sets, 1, 0);
        // Velocities of one particle per spot and axis, deterministic or not.
        let mut fcm_velocities = |deterministic: bool| {
            with_caps(
                &mut gpu,
                |c| c.deterministic = deterministic,
                |gpu| {
                    let plan = mobility_plan(gpu, &fcm, 1, false, &["velocities"]);
                    let mut program = compile_cached(gpu, &fcm, &plan);
                    let mut v = Vec::new();
                    for x in &spots {
                        for a in 0..3 {
                            let mut f = [[0.0; 3]];
                            f[0][a] = 1.0;
                            v.push(eval(&mut program, &[*x], &f, None)["velocities"][0][a]);
                        }
                    }
                    v
                },
            )
        };
        let (det, default) = (fcm_velocities(true), fcm_velocities(false));
        let worst = det
            .iter()
            .map(|v| (v / fcm_exact - 1.0).abs())
            .fold(0.0, f64::max);
        let apart = det
            .iter()
            .zip(&default)
            .map(|(a, b)| (a - b).abs() / fcm_exact)
            .fold(0.0, f64::max);
        eprintln!(
            "deterministic FCM at {tol:e}: self-mobility error {worst:.2e}, {apart:.1e} from the default plan"
        );
        assert!(worst <= tol, "FCM at {tol:e}: {worst:e}");
        assert!(
            apart < 1e-6,
            "FCM at {tol:e}: {apart:e} from the default plan"
        );

        let pse = load_with("pse.json", &sets, 1, 0);
        let x0 = [1.1, -2.3, 0.7];
        let x1 = [2.9, -1.2, 1.9];
        let r = [0, 1, 2].map(|c| x1[c] - x0[c]);
        let want = mesoflow::nodes::pse::periodic_rpy(r, l, 1.0, 1.0, 0.8).unwrap();
        let mut pse_velocities = |deterministic: bool| {
            with_caps(
                &mut gpu,
                |c| c.deterministic = deterministic,
                |gpu| {
                    let plan = mobility_plan(gpu, &pse, 2, false, &["velocities"]);
                    let mut program = compile_cached(gpu, &pse, &plan);
                    let mut m = [[0.0; 3]; 3];
                    for b in 0..3 {
                        let mut f = [[0.0; 3]; 2];
                        f[0][b] = 1.0;
                        let v = &eval(&mut program, &[x0, x1], &f, None)["velocities"];
                        for a in 0..3 {
                            m[a][b] = v[1][a];
                        }
                    }
                    m
                },
            )
        };
        let (det, default) = (pse_velocities(true), pse_velocities(false));
        let (mut worst, mut apart): (f64, f64) = (0.0, 0.0);
        for a in 0..3 {
            for b in 0..3 {
                worst = worst.max((det[a][b] - want[a][b]).abs() / m_self);
                apart = apart.max((det[a][b] - default[a][b]).abs() / m_self);
            }
        }
        eprintln!(
            "deterministic PSE at {tol:e}: pair-mobility error / self {worst:.2e}, {apart:.1e} from the default plan"
        );
        assert!(worst <= tol, "PSE at {tol:e}: {worst:e}");
        assert!(
            apart < 1e-6,
            "PSE at {tol:e}: {apart:e} from the default plan"
        );
    }
}
