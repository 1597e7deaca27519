//! What must not change fcm.json's velocities beyond rounding (where the grid lies, the
//! order particles are served in), and settings refused with clear errors.

use mesoflow::expr::ParamValue;
use mesoflow::plan::PlanOptions;
use mesoflow::value::ValueType;

use crate::util::mobility::{eval, mobility_plan, random_positions};
use crate::util::{Rng, compile_cached, gpu, load_error, load_with};

/// Moving every particle by the same vector moves nothing else: velocities agree within
/// the tolerance (exactly up to rounding for whole cells).
#[test]
fn velocities_do_not_depend_on_where_the_grid_is() {
    let Some(gpu) = gpu() else { return };
    let (l, n, tol) = (12.0, 16usize, 1e-3);
    let g = load_with(
        "fcm.json",
        &[("box", "[12, 12, 12]"), ("tolerance", "0.001")],
        1,
        0,
    );
    let plan = mobility_plan(&gpu, &g, n as u32, false, &["velocities"]);
    let mut fcm = compile_cached(&gpu, &g, &plan);
    // The planner's grid for L = 12 a at 1e-3: 20 cells (18 = 2 3^2 is not a full-rate FFT size).
    assert_eq!(
        g.params
            .iter()
            .find(|p| p.name == "grid")
            .map(|p| p.value.clone()),
        Some(ParamValue::Numbers(vec![20.0; 3]))
    );
    let h = l / 20.0;
    let mut rng = Rng::new(71);
    let x = random_positions(&mut rng, n, [l; 3]);
    let f: Vec<[f64; 3]> = (0..n)
        .map(|_| [0, 1, 2].map(|_| rng.uniform(-1.0, 1.0)))
        .collect();
    let base = eval(&mut fcm, &x, &f, None)["velocities"].clone();
    let biggest = base.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    for (shift, bound) in [
        ([0.37, -1.91, 4.4], tol),
        ([h * 3.0, -h * 5.0, h], 2e-5),
        ([0.5 * h, 0.5 * h, 0.5 * h], tol),
    ] {
        let moved: Vec<[f64; 3]> = x
            .iter()
            .map(|p| [0, 1, 2].map(|a| p[a] + shift[a]))
            .collect();
        let v = &eval(&mut fcm, &moved, &f, None)["velocities"];
        let worst = (0..n)
            .flat_map(|i| (0..3).map(move |a| (i, a)))
            .map(|(i, a)| (v[i][a] - base[i][a]).abs())
            .fold(0.0f64, f64::max)
            / biggest;
        eprintln!("shift {shift:?}: {worst:e}");
        assert!(worst <= bound, "shift {shift:?}: {worst:e} > {bound:e}");
    }
}

/// Serving particles in Morton order (what fcm.json does on grids larger than the cache)
/// changes only the order of the grid's float additions: every output (forces and torques
/// in, noise drawn) comes back in the input order and agrees with the unsorted run to f32
/// rounding.
#[test]
fn sorting_particles_changes_nothing_but_rounding() {
    let Some(gpu) = gpu() else { return };
    let (l, n) = (12.0, 64usize);
    let mut rng = Rng::new(5);
    let x = random_positions(&mut rng, n, [l; 3]);
    let f: Vec<[f64; 3]> = (0..n)
        .map(|_| [0, 1, 2].map(|_| rng.uniform(-1.0, 1.0)))
        .collect();
    let t: Vec<[f64; 3]> = (0..n)
        .map(|_| [0, 1, 2].map(|_| rng.uniform(-1.0, 1.0)))
        .collect();
    let outputs = [
        "velocities",
        "angular_velocities",
        "noise",
        "fluctuating_velocities",
    ];
    let run = |sort: &str| {
        let g = load_with(
            "fcm.json",
            &[
                ("box", "[12, 12, 12]"),
                ("rotation", "true"),
                ("temperature", "1"),
                ("sort_particles", sort),
            ],
            1,
            9,
        );
        let plan = mobility_plan(&gpu, &g, n as u32, true, &outputs);
        let read_through: Vec<&str> = plan
            .forwarded
            .iter()
            .map(|&i| g.nodes[i].id.as_str())
            .collect();
        let sorted = !outputs.iter().any(|o| read_through.contains(o));
        assert_eq!(
            sorted,
            sort == "true",
            "sort_particles = {sort}: {read_through:?}"
        );
        let mut fcm = compile_cached(&gpu, &g, &plan);
        eval(&mut fcm, &x, &f, Some(&t))
    };
    let (plain, sorted) = (run("false"), run("true"));
    for out in outputs {
        let (a, b) = (&plain[out], &sorted[out]);
        let biggest = a.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
        let worst = a
            .iter()
            .flatten()
            .zip(b.iter().flatten())
            .map(|(p, q)| (p - q).abs())
            .fold(0.0f64, f64::max)
            / biggest;
        eprintln!("{out}: sorted vs input order {worst:e}");
        assert!(biggest > 0.0 && worst < 1e-5, "{out}: {worst:e}");
    }
}

#[test]
fn bad_settings_get_clear_errors() {
    // Tighter than f32 can hold.
    let e = load_error("fcm.json", &[("tolerance", "1e-7")]);
    assert!(
        e.contains("tolerance") && e.contains("1e-6") || e.contains("0.000001"),
        "{e}"
    );
    // Viscosity zero: the Green function's node says so.
    let e = load_error("fcm.json", &[("viscosity", "0")]);
    assert!(e.contains("viscosity") && e.contains("flow"), "{e}");
    // Rotation with a window that ties the radius to the cell.
    let e = load_error(
        "fcm.json",
        &[("rotation", "true"), ("kernel", "\"peskin4\"")],
    );
    assert!(e.contains("rotation") && e.contains("gaussian"), "{e}");
    // A box thinner than the spheres' diameter (3a is planned: the window wraps).
    let e = load_error("fcm.json", &[("box", "[24, 24, 1.5]")]);
    assert!(e.contains("diameter") && e.contains("`box`"), "{e}");

    // Torques without the rotation grid: the torque window says it is too coarse.
    let g = load_with("fcm.json", &[], 1, 0);
    let caps = mesoflow::gpu::DeviceCaps::baseline();
    let p3 = ValueType::Particles { n: 4, k: 3 };
    let opts = PlanOptions {
        outputs: Some(vec!["velocities".into()]),
        inputs: [("positions", p3), ("forces", p3), ("torques", p3)]
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect(),
        fuse: true,
        in_place: true,
    };
    let e = mesoflow::plan::plan(&g, &opts, &caps)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("spread_torques") && e.contains("min_width_cells"),
        "{e}"
    );
    // Without torques the same graph plans: the torque nodes are never built into work.
    let opts = PlanOptions {
        inputs: [("positions", p3), ("forces", p3)]
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect(),
        ..opts
    };
    let p = mesoflow::plan::plan(&g, &opts, &caps).unwrap_or_else(|e| panic!("{e}"));
    // Spread, rfft + stokes folded, irfft, interpolate: no torque work, the Green function
    // costs no pass of its own, and this grid (48^3) fits in cache, so the particles are
    // not sorted (the gathers and the scatter back are read through, the sort is pruned).
    let ran: Vec<&str> = p
        .launches()
        .flat_map(|(_, l)| l.nodes())
        .map(|n| g.nodes[n].id.as_str())
        .collect();
    assert!(!ran.iter().any(|id| id.contains("torque")), "{ran:?}");
    assert!(p.step.iter().any(|l| matches!(
        l,
        mesoflow::plan::Launch::Transform {
            fold: mesoflow::plan::TransformFold::Hosts(_),
            ..
        }
    )));
    assert!(!ran.contains(&"order") && !ran.contains(&"cell"), "{ran:?}");
    let read_through: Vec<&str> = p
        .forwarded
        .iter()
        .map(|&n| g.nodes[n].id.as_str())
        .collect();
    assert_eq!(
        read_through,
        ["sorted_positions", "sorted_forces", "forcing", "velocities"],
        "the forcing sum and the permutations are read through"
    );
}
