//! Scenes: built into the graph they need (planned only with what they hold), their
//! mistakes named with their place, particles placed apart, the graph a scene builds
//! computing what the hand-written graph computes, species in trajectories.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use mesoflow::gpu::DeviceCaps;
use mesoflow::graph::{self, LoadOptions};
use mesoflow::plan::{self, PlanOptions};
use mesoflow::scene::{self, CompiledScene};
use mesoflow::value::HostData;
use serde_json::{Value, json};

use crate::util::{f32s, gpu, load_with, registry, run_graph, tmpdir};

/// A small periodic scene, no interactions, no hydrodynamics.
fn base() -> Value {
    json!({
        "scene": 1,
        "box": [12, 12, 12],
        "species": {"a": {"radius": 0.5}},
        "particles": [{"species": "a", "count": 50, "place": "random"}],
        "temperature": 1.0,
        "integrator": {"scheme": "euler_maruyama", "dt": 0.01},
        "run": {"steps": 3, "seed": 4}
    })
}

fn write_scene(dir: &Path, name: &str, v: &Value) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, serde_json::to_string_pretty(v).unwrap()).unwrap();
    p
}

fn compile(dir: &Path, name: &str, v: &Value) -> (PathBuf, CompiledScene) {
    let p = write_scene(dir, name, v);
    let c = scene::compile(&p, None).unwrap_or_else(|e| panic!("{e}"));
    (p, c)
}

/// The plan (as `inspect` prints it) of a scene's graph for its particles.
fn plan_text(path: &Path, c: &CompiledScene) -> String {
    let g = graph::load_text(path, &c.graph, registry(), &LoadOptions::default())
        .unwrap_or_else(|e| panic!("{e}\n{}", c.graph));
    let opts = PlanOptions {
        outputs: Some(vec!["positions".into()]),
        inputs: c.inputs.iter().map(|(k, v)| (k.clone(), v.ty)).collect(),
        fuse: true,
        in_place: true,
    };
    let p = plan::plan(&g, &opts, &DeviceCaps::baseline()).unwrap_or_else(|e| panic!("{e}"));
    plan::to_text(&g, &p)
}

fn with(mut v: Value, key: &str, value: Value) -> Value {
    v[key] = value;
    v
}

#[test]
fn a_scene_plans_only_what_it_holds() {
    let dir = tmpdir("scene_plans");
    // (what the scene holds, kinds its plan must run, kinds it must not)
    let electro = json!({"wca": {"sigma": 1.0}, "electrostatics": {"tolerance": 0.001}});
    let charged = json!({"p": {"radius": 0.5, "charge": 1}, "m": {"radius": 0.5, "charge": -1}});
    let two_sets = json!([
        {"species": "p", "count": 20, "place": "random"},
        {"species": "m", "count": 20, "place": "random"}
    ]);
    let cases: Vec<(&str, Value, &[&str], &[&str])> = vec![
        (
            "bare",
            base(),
            &["(random_normal)"],
            &["(neighbour_sum)", "(poisson)", "(rfft)", "(wall_force)"],
        ),
        (
            "wca",
            with(base(), "interactions", json!({"wca": {"sigma": 1.0}})),
            &["(neighbour_sum)"],
            &["(poisson)", "(rfft)"],
        ),
        (
            "gravity",
            with(base(), "interactions", json!({"gravity": [0, 0, -1]})),
            &["(add)"],
            &["(neighbour_sum)", "(poisson)", "(rfft)"],
        ),
        (
            "charges",
            with(
                with(with(base(), "species", charged), "particles", two_sets),
                "interactions",
                electro,
            ),
            &["(neighbour_sum)", "(poisson)", "(rfft)"],
            &["(stokes)"],
        ),
        (
            "fcm",
            with(
                base(),
                "hydrodynamics",
                json!({"model": "fcm", "tolerance": 0.01}),
            ),
            &["(rfft)", "(stokes)"],
            &["(neighbour_sum)", "(poisson)"],
        ),
        (
            "mpcd",
            with(
                with(
                    base(),
                    "hydrodynamics",
                    json!({"model": "mpcd", "params": {"density": 2}}),
                ),
                "integrator",
                json!({"scheme": "velocity_verlet", "dt": 0.1}),
            ),
            &["(mpcd_stream)", "(mpcd_bin_solute)", "(mpcd_collide)"],
            &[
                "(neighbour_sum)",
                "(rfft)",
                "(mpcd_measure)",
                "(random_normal)",
            ],
        ),
    ];
    for (name, v, must, must_not) in cases {
        let (p, c) = compile(&dir, &format!("{name}.json"), &v);
        let text = plan_text(&p, &c);
        for k in must {
            assert!(text.contains(k), "{name}: no {k} in\n{text}");
        }
        for k in must_not {
            assert!(!text.contains(k), "{name}: {k} planned in\n{text}");
        }
    }
}

#[test]
fn scene_mistakes_are_named_with_their_place() {
    let dir = tmpdir("scene_mistakes");
    let cases: Vec<(Value, &str)> = vec![
        (
            with(base(), "colour", json!("red")),
            "unknown field `colour`",
        ),
        (with(base(), "scene", json!(2)), "scene schema version 2"),
        (
            with(base(), "particles", json!([{"species": "b", "count": 3}])),
            "particles[0].species: no species `b` (species: a)",
        ),
        (
            with(base(), "particles", json!([{"species": "a"}])),
            "particles[0]: give either `positions` (an NPY file) or `count`",
        ),
        (
            with(
                base(),
                "particles",
                json!([{"species": "a", "count": 3, "place": "hexagonal"}]),
            ),
            "particles[0].place: unknown `hexagonal`",
        ),
        (
            with(
                base(),
                "particles",
                json!([{"species": "a", "count": 3000, "place": "random"}]),
            ),
            "particles[0]: placed",
        ),
        (
            with(
                base(),
                "species",
                json!({"a": {"radius": 0.5}, "b": {"radius": 1.0}}),
            ),
            "radii a 0.5, b 1 differ",
        ),
        (
            with(
                base(),
                "integrator",
                json!({"scheme": "leapfrog", "dt": 0.1}),
            ),
            "integrator.scheme: unknown `leapfrog`",
        ),
        (
            with(
                base(),
                "integrator",
                json!({"scheme": "euler_maruyama", "dt": -1}),
            ),
            "integrator.dt: expected a positive number, got -1",
        ),
        (
            with(
                with(base(), "hydrodynamics", json!({"model": "fcm"})),
                "walls",
                json!({"type": "bottom", "zmin": 0, "zmax": 12}),
            ),
            "its mobility is triply periodic and knows no wall",
        ),
        (
            with(
                base(),
                "walls",
                json!({"type": "bottom", "zmin": 0, "zmax": 10}),
            ),
            "box[2] = 12 but the walls span zmax - zmin = 10",
        ),
        (
            with(
                base(),
                "species",
                json!({"a": {"radius": 0.5, "charge": 1}}),
            ),
            "species carry charges but interactions.electrostatics is not given",
        ),
        (
            with(
                base(),
                "integrator",
                json!({"scheme": "langevin_gjf", "dt": 0.01}),
            ),
            "`langevin_gjf` needs the friction",
        ),
        (
            with(
                with(base(), "hydrodynamics", json!({"model": "fcm"})),
                "integrator",
                json!({"scheme": "velocity_verlet", "dt": 0.01}),
            ),
            "is inertial and takes no mobility",
        ),
        (
            with(base(), "hydrodynamics", json!({"model": "mpcd"})),
            "hydrodynamics.model `mpcd` moves the particles by velocity Verlet",
        ),
        (
            with(
                with(
                    base(),
                    "hydrodynamics",
                    json!({"model": "mpcd", "viscosity": 2}),
                ),
                "integrator",
                json!({"scheme": "velocity_verlet", "dt": 0.1}),
            ),
            "hydrodynamics.viscosity: not a param of `mpcd`",
        ),
        (
            with(
                with(
                    with(base(), "hydrodynamics", json!({"model": "mpcd"})),
                    "integrator",
                    json!({"scheme": "velocity_verlet", "dt": 0.1}),
                ),
                "walls",
                json!({"type": "bottom", "zmin": -6, "zmax": 6}),
            ),
            "walls.type `bottom` with hydrodynamics.model `mpcd`",
        ),
        (
            with(
                with(
                    with(
                        base(),
                        "hydrodynamics",
                        json!({"model": "mpcd", "params": {"dt": 1}}),
                    ),
                    "integrator",
                    json!({"scheme": "velocity_verlet", "dt": 0.1}),
                ),
                "species",
                json!({"a": {"radius": 0.5, "mass": 2}, "b": {"radius": 0.5}}),
            ),
            "hydrodynamics.params.dt: set by the scene",
        ),
        (
            with(
                with(
                    with(base(), "hydrodynamics", json!({"model": "mpcd"})),
                    "integrator",
                    json!({"scheme": "velocity_verlet", "dt": 0.1}),
                ),
                "species",
                json!({"a": {"radius": 0.5, "mass": 2}, "b": {"radius": 0.5}}),
            ),
            "species: masses a 2, b 1 differ",
        ),
        (
            with(
                with(base(), "hydrodynamics", json!({"params": {"cell": 1}})),
                "integrator",
                json!({"scheme": "velocity_verlet", "dt": 0.1}),
            ),
            "takes no mobility to give them to",
        ),
        (
            with(
                base(),
                "output",
                json!({"file": "t.npy", "every": 1, "values": ["positions", "energy"]}),
            ),
            "an NPY file holds one output",
        ),
    ];
    for (i, (v, want)) in cases.iter().enumerate() {
        let p = write_scene(&dir, &format!("case{i}.json"), v);
        let err = match scene::compile(&p, None) {
            Ok(_) => panic!("case {i} compiled ({want})"),
            Err(e) => e.to_string(),
        };
        assert!(err.contains(want), "case {i}: {err}\nwanted: {want}");
        assert!(err.contains(&format!("case{i}.json")), "case {i}: {err}");
    }
    // A mobility param the mobility graph does not take: named by the graph loader,
    // with where the scene bound it.
    let v = with(
        base(),
        "hydrodynamics",
        json!({"model": "fcm", "params": {"kernal": "es"}}),
    );
    let (p, c) = compile(&dir, "bound.json", &v);
    let err = graph::load_text(&p, &c.graph, registry(), &LoadOptions::default())
        .err()
        .expect("an unknown mobility param")
        .to_string();
    assert!(
        err.contains("unknown param `kernal` (did you mean `kernel`?)")
            && err.contains("bound as `mobility.kernal`"),
        "{err}"
    );
}

fn positions(c: &CompiledScene) -> Vec<[f64; 3]> {
    let HostData::F32(v) = &c.inputs["positions"].data else {
        panic!("f32 positions")
    };
    v.chunks_exact(3)
        .map(|r| [r[0] as f64, r[1] as f64, r[2] as f64])
        .collect()
}

#[test]
fn generated_particles_are_placed_apart_inside_their_region() {
    let dir = tmpdir("scene_place");
    // Two species of different radii (no hydrodynamics takes them: Langevin), near
    // random close packing of the larger ones' own share, and a lattice.
    let v = json!({
        "scene": 1,
        "box": [10, 10, 8],
        "walls": {"type": "slit", "zmin": -4, "zmax": 4},
        "species": {"big": {"radius": 1.0}, "small": {"radius": 0.3}},
        "particles": [
            {"species": "big", "count": 60, "place": "random", "z": [-3, 3]},
            {"species": "small", "count": 300, "place": "random"}
        ],
        "temperature": 1.0,
        "integrator": {"scheme": "langevin_gjf", "dt": 0.01, "friction": 1.0}
    });
    let (_, c) = compile(&dir, "two.json", &v);
    let x = positions(&c);
    let radius = |i: usize| if i < 60 { 1.0 } else { 0.3 };
    assert_eq!(x.len(), 360);
    for (i, p) in x.iter().enumerate() {
        let (lo, hi) = if i < 60 { (-3.0, 3.0) } else { (-3.7, 3.7) };
        assert!(
            p[2] >= lo - 1e-6 && p[2] <= hi + 1e-6,
            "particle {i} at z {}",
            p[2]
        );
        assert!(
            p[0].abs() <= 5.0 && p[1].abs() <= 5.0,
            "particle {i} at {p:?}"
        );
        for (j, q) in x.iter().enumerate().skip(i + 1) {
            let mut d2 = 0.0;
            for d in 0..3 {
                let mut r = p[d] - q[d];
                if d < 2 {
                    r -= 10.0 * (r / 10.0).round();
                }
                d2 += r * r;
            }
            let contact = radius(i) + radius(j);
            assert!(
                d2.sqrt() >= contact * (1.0 - 1e-6),
                "particles {i} and {j} {} apart, contact at {contact}",
                d2.sqrt()
            );
        }
    }
    assert_eq!(c.species.typeid.iter().filter(|&&t| t == 1).count(), 300);
    // Inertial: Maxwell-Boltzmann velocities of zero total momentum.
    let HostData::F32(v) = &c.inputs["velocities"].data else {
        panic!()
    };
    for d in 0..3 {
        let p: f64 = v.iter().skip(d).step_by(3).map(|&x| x as f64).sum();
        assert!(p.abs() < 1e-3, "momentum {p} along {d}");
    }
    // A lattice of 64 in a cube: 4 per axis, spacing 3, a half spacing from the faces.
    let v = with(
        base(),
        "particles",
        json!([{"species": "a", "count": 64, "place": "lattice"}]),
    );
    let (_, c) = compile(&dir, "lattice.json", &v);
    let x = positions(&c);
    for p in &x {
        for c in p {
            let k = (c + 6.0 - 1.5) / 3.0;
            assert!(
                (k - k.round()).abs() < 1e-6 && (0.0..4.0).contains(&k),
                "site {p:?}"
            );
        }
    }
}

/// The colloid demo's scene (shrunk) against the hand-written bd_fcm.json: with the
/// integrator drawing from the same stream as bd_fcm.json's mobility, the same
/// positions bit for bit.
#[test]
fn a_scene_runs_the_graph_it_replaces() {
    let Some(gpu) = gpu() else { return };
    let dir = tmpdir("scene_vs_graph");
    let v = json!({
        "scene": 1,
        "box": [16, 16, 16],
        "species": {"colloid": {"radius": 1.0}},
        "particles": [{"species": "colloid", "count": 40, "place": "random"}],
        "hydrodynamics": {"model": "fcm", "viscosity": 1.0, "tolerance": 0.001},
        "temperature": 1.0,
        "integrator": {"scheme": "euler_maruyama", "dt": 0.05, "params": {"stream": 1}},
        "run": {"steps": 3, "seed": 9}
    });
    let (p, c) = compile(&dir, "colloids.json", &v);
    let opts = LoadOptions {
        steps: 3,
        seed: 9,
        ..Default::default()
    };
    let g = graph::load_text(&p, &c.graph, registry(), &opts).unwrap_or_else(|e| panic!("{e}"));
    let from_scene = run_graph(&gpu, &g, &c.inputs, Some(&["positions"]), 3, true);
    let by_hand = load_with(
        "bd_fcm.json",
        &[("box", "[16, 16, 16]"), ("dt", "0.05"), ("radius", "1.0")],
        3,
        9,
    );
    let inputs = BTreeMap::from([("positions".to_string(), c.inputs["positions"].clone())]);
    let written = run_graph(&gpu, &by_hand, &inputs, Some(&["positions"]), 3, true);
    let (a, b) = (f32s(&from_scene["positions"]), f32s(&written["positions"]));
    let start = f32s(&c.inputs["positions"]);
    assert!(
        a.iter().zip(&start).any(|(x, y)| x != y),
        "the particles moved"
    );
    assert_eq!(a, b, "the scene's graph and bd_fcm.json differ");
}

/// `mesoflow run SCENE` writes the scene's trajectory with its species (GSD's
/// particles/types, typeid, diameter, mass, charge in the first frame).
#[test]
fn a_scene_trajectory_carries_its_species() {
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("scene_gsd");
    let v = json!({
        "scene": 1,
        "box": [10, 10, 10],
        "species": {"big": {"radius": 0.5, "mass": 2.0}, "tiny": {"radius": 0.5, "mass": 0.5}},
        "particles": [
            {"species": "big", "count": 5, "place": "random"},
            {"species": "tiny", "count": 7, "place": "lattice"}
        ],
        "interactions": {"gravity": [0, 0, -1]},
        "temperature": 1.0,
        "integrator": {"scheme": "euler_maruyama", "dt": 0.01},
        "run": {"steps": 4, "seed": 2},
        "output": {"file": "traj.gsd", "every": 2}
    });
    let p = write_scene(&dir, "small.json", &v);
    let o = Command::new(env!("CARGO_BIN_EXE_mesoflow"))
        .args(["run", p.to_str().unwrap()])
        .current_dir(&dir)
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .expect("run mesoflow");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(o.status.success(), "{text}");
    let read = mesoflow::gsd::GsdRead::open(&dir.join("traj.gsd")).unwrap();
    let (n, m, types) = read.chunk(0, "particles/types").expect("types");
    assert_eq!((n, m), (2, 5));
    assert_eq!(types, b"big\0\0tiny\0");
    let (n, _, ids) = read.chunk(0, "particles/typeid").expect("typeid");
    assert_eq!(n, 12);
    let ids: Vec<u32> = ids
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    assert_eq!(ids, [0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 1, 1]);
    let (_, _, mass) = read.chunk(0, "particles/mass").expect("mass");
    let mass: Vec<f32> = mass
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    assert_eq!(&mass[4..6], &[2.0, 0.5]);
    // The scene's box (HOOMD's six floats: Lx, Ly, Lz, then no tilt).
    let (_, _, b) = read.chunk(0, "configuration/box").expect("box");
    let b: Vec<f32> = b
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    assert_eq!(b, [10.0, 10.0, 10.0, 0.0, 0.0, 0.0]);
    // Species once, positions every frame (steps 2 and 4).
    assert!(read.chunk(1, "particles/typeid").is_none());
    assert!(read.chunk(1, "particles/position").is_some());
}

/// Every scene of `scenes/`, shrunk (fewer particles in a box of at most 16 across, a
/// wall domain's height kept in step), builds, plans and runs two steps to finite values.
#[test]
fn the_shipped_scenes_build_and_run() {
    let Some(gpu) = gpu() else { return };
    let dir = tmpdir("shipped_scenes");
    let mut names: Vec<PathBuf> = std::fs::read_dir(crate::util::root().join("scenes"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    names.sort();
    assert!(names.len() >= 5, "{names:?}");
    for path in names {
        let mut v: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        let side = 16.0;
        v["box"][0] = json!(side);
        v["box"][1] = json!(side);
        if v.get("walls").is_some() {
            let lo = v["walls"]["zmin"].as_f64().unwrap();
            v["walls"]["zmax"] = json!(lo + side);
            v["box"][2] = json!(side);
            for set in v["particles"].as_array_mut().unwrap() {
                if set.get("z").is_some() {
                    set["z"] = json!([lo + 4.0, lo + 10.0]);
                }
            }
        } else {
            v["box"][2] = json!(side);
        }
        for set in v["particles"].as_array_mut().unwrap() {
            set["count"] = json!(12);
        }
        let name = path.file_name().unwrap().to_str().unwrap().to_string();
        let (p, c) = compile(&dir, &format!("shrunk_{name}"), &v);
        let opts = LoadOptions {
            steps: 2,
            seed: 1,
            ..Default::default()
        };
        let g = graph::load_text(&p, &c.graph, registry(), &opts)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let out = run_graph(&gpu, &g, &c.inputs, Some(&["positions", "energy"]), 2, true);
        let x = f32s(&out["positions"]);
        assert_eq!(x.len(), 3 * c.species.typeid.len(), "{name}");
        assert!(x.iter().all(|v| v.is_finite()), "{name}: positions {x:?}");
        assert!(f32s(&out["energy"])[0].is_finite(), "{name}: energy");
        assert_ne!(x, f32s(&c.inputs["positions"]), "{name}: nothing moved");
    }
}

/// A scene run stopped with a checkpoint goes on bit for bit (its particles placed again
/// from the same seed, checked against the checkpoint's inputs).
#[test]
fn a_scene_resumes_bit_for_bit() {
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("scene_resume");
    let v = json!({
        "scene": 1,
        "box": [6, 6, 6],
        "species": {"bead": {"radius": 0.5}},
        "particles": [{"species": "bead", "count": 40, "place": "random"}],
        "interactions": {"wca": {"sigma": 1.0}},
        "temperature": 1.0,
        "integrator": {"scheme": "langevin_gjf", "dt": 0.005, "friction": 1.0},
        "run": {"steps": 6, "seed": 8},
        "output": {"file": "ignored.gsd", "every": 2}
    });
    let p = write_scene(&dir, "fluid.json", &v);
    let run = |args: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_mesoflow"))
            .arg("run")
            .arg(&p)
            .args(args)
            .current_dir(&dir)
            .env("XDG_RUNTIME_DIR", std::env::temp_dir())
            .output()
            .expect("run mesoflow");
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    run(&["--output", "positions=full.npy"]);
    run(&[
        "--steps",
        "4",
        "--output",
        "positions=half.npy",
        "--checkpoint",
        "cp.gsd",
    ]);
    run(&[
        "--steps",
        "2",
        "--resume",
        "cp.gsd",
        "--output",
        "positions=resumed.npy",
    ]);
    let read = |f: &str| std::fs::read(dir.join(f)).unwrap();
    assert_eq!(read("full.npy"), read("resumed.npy"));
    assert_ne!(read("full.npy"), read("half.npy"));
    // --output given: the scene's own trajectory and interval stand aside.
    assert!(!dir.join("ignored.gsd").exists());
}

/// `lj` with its tail: the energy the scene's graph reports against the f64
/// Lennard-Jones sum (truncated at 2.5 sigma and shifted) at the positions it reports.
#[test]
fn a_lennard_jones_scene_has_the_truncated_and_shifted_energy() {
    let Some(gpu) = gpu() else { return };
    let dir = tmpdir("scene_lj");
    // A small cluster whose pairs span the well and the tail (1.0 to 2.9 apart).
    let x: Vec<f32> = vec![
        0.0, 0.0, 0.0, 1.12, 0.0, 0.0, 0.0, 1.6, 0.0, 0.4, 0.3, 2.2, -1.3, 0.9, -0.8, 3.9, 3.9, 3.9,
    ];
    let n = x.len() / 3;
    mesoflow::npy::write(
        &dir.join("x.npy"),
        &mesoflow::value::HostArray::f32(
            mesoflow::value::ValueType::Particles { n: n as u32, k: 3 },
            x,
        ),
    )
    .unwrap();
    let v = json!({
        "scene": 1,
        "box": [10, 10, 10],
        "species": {"atom": {"radius": 0.5}},
        "particles": [{"species": "atom", "positions": "x.npy"}],
        "interactions": {"lj": {"epsilon": 1.3, "sigma": 1.0, "cutoff": 2.5}},
        "temperature": 0.0,
        "integrator": {"scheme": "velocity_verlet", "dt": 0.0005},
        "run": {"steps": 1}
    });
    let (p, c) = compile(&dir, "lj.json", &v);
    let g = graph::load_text(&p, &c.graph, registry(), &LoadOptions::default())
        .unwrap_or_else(|e| panic!("{e}"));
    let out = run_graph(&gpu, &g, &c.inputs, Some(&["positions", "energy"]), 1, true);
    let y: Vec<f64> = f32s(&out["positions"]).iter().map(|&v| v as f64).collect();
    let lj = |r: f64| 4.0 * 1.3 * ((1.0 / r).powi(12) - (1.0 / r).powi(6));
    let mut want = 0.0;
    for i in 0..n {
        for j in i + 1..n {
            let mut r2 = 0.0;
            for d in 0..3 {
                let mut dx = y[3 * i + d] - y[3 * j + d];
                dx -= 10.0 * (dx / 10.0).round();
                r2 += dx * dx;
            }
            let r = r2.sqrt();
            if r < 2.5 {
                want += lj(r) - lj(2.5);
            }
        }
    }
    let got = f32s(&out["energy"])[0] as f64;
    assert!(
        (got - want).abs() < 1e-5 * want.abs().max(1.0),
        "energy {got} against {want}"
    );
}

/// A polymer melt in an MPCD solvent: beads that start at rest are brought to the
/// solvent's temperature by the collisions they join (and nothing else: their forces
/// conserve energy), and the solvent and beads together conserve momentum.
#[test]
fn an_mpcd_scene_thermalises_its_particles_and_conserves_momentum() {
    let Some(gpu) = gpu() else { return };
    let dir = tmpdir("scene_mpcd");
    // 15 chains of 20 beads of mass 5 in 1728 cells of 5 solvent particles: 900 degrees
    // of freedom, so one frame's kinetic temperature has a relative standard deviation
    // of sqrt(2/900) = 4.7%; five frames 20 collisions apart (a bead's velocity forgets
    // itself within a few collisions) average to about 2.1%: 10% is 4.7 of those. The
    // cell thermostat holds the solvent at kT = 1 (it scales relative velocities, so each
    // cell keeps its momentum).
    let chains: Vec<Value> = (0..15)
        .map(|_| json!({"species": "bead", "count": 20, "place": "chain"}))
        .collect();
    let v = json!({
        "scene": 1,
        "box": [12, 12, 12],
        "species": {"bead": {"radius": 0.5, "mass": 5.0}},
        "particles": chains,
        "interactions": {"wca": {"sigma": 1.0}, "bonds": {"stiffness": 30.0, "rest_length": 1.0}},
        "hydrodynamics": {"model": "mpcd", "params": {"density": 5}},
        "temperature": 1.0,
        "integrator": {"scheme": "velocity_verlet", "dt": 0.1},
        "run": {"seed": 8}
    });
    let (p, mut c) = compile(&dir, "melt.json", &v);
    let ns = c.species.typeid.len();
    assert_eq!(ns, 300);
    c.inputs.insert(
        "velocities".into(),
        mesoflow::value::HostArray::f32(c.inputs["velocities"].ty, vec![0.0; 3 * ns]),
    );
    let g = graph::load_text(
        &p,
        &c.graph,
        registry(),
        &LoadOptions {
            steps: 1,
            seed: 8,
            ..Default::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let outputs = ["velocities", "solvent_velocities"];
    let plan = crate::util::plan_graph(
        &gpu.caps,
        &g,
        crate::util::types_of(&c.inputs),
        Some(&outputs),
        true,
    );
    let mut program = crate::util::compile_cached(&gpu, &g, &plan);
    program.upload(&c.inputs).unwrap_or_else(|e| panic!("{e}"));
    let read = |program: &mut mesoflow::exec::Program, steps: u64| {
        let (_, out) = program
            .run_on_and_read(&mesoflow::exec::RunOptions {
                steps,
                profile: mesoflow::exec::Profile::Off,
                progress: false,
            })
            .unwrap_or_else(|e| panic!("{e}"));
        let out: BTreeMap<String, mesoflow::value::HostArray> = out.into_iter().collect();
        let vs = f32s(&out["velocities"]);
        let v = f32s(&out["solvent_velocities"]);
        let kt = 5.0 * vs.iter().map(|&x| (x as f64).powi(2)).sum::<f64>() / (3 * ns) as f64;
        let momentum: Vec<f64> = (0..3)
            .map(|d| {
                v.iter().skip(d).step_by(3).map(|&x| x as f64).sum::<f64>()
                    + 5.0 * vs.iter().skip(d).step_by(3).map(|&x| x as f64).sum::<f64>()
            })
            .collect();
        (kt, momentum)
    };
    let (kt_first, p_first) = read(&mut program, 1);
    let mut temperatures = Vec::new();
    let mut p_last = p_first.clone();
    for _ in 0..10 {
        let (kt, momentum) = read(&mut program, 20);
        temperatures.push(kt);
        p_last = momentum;
    }
    eprintln!(
        "kT after 1 step {kt_first}, then every 20: {temperatures:?}; momentum {p_first:?} -> {p_last:?}"
    );
    // The beads started at rest: their temperature is the collisions' doing (their forces
    // conserve energy, a few kT of bond and WCA energy at most over 300 beads).
    let late = &temperatures[5..];
    let mean = late.iter().sum::<f64>() / late.len() as f64;
    assert!(
        (mean - 1.0).abs() < 0.1,
        "the beads' kT {mean} ({temperatures:?})"
    );
    // Momentum: f32 rounding of about 1e-7 of each velocity per step, a random walk over
    // 9000 particles and 200 steps (~1e-4); the thermal scale sqrt(sum m kT) is ~100.
    for d in 0..3 {
        assert!(
            (p_last[d] - p_first[d]).abs() < 2e-3,
            "momentum {p_first:?} -> {p_last:?}"
        );
    }
}
