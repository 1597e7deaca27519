//! graphs/dpstokes.json, the doubly periodic Stokes mobility, against the physics: the
//! open-space self-mobility of FCM's Gaussian far from everything, the Rotne-Prager-Blake
//! (Swan and Brady 2007) self-mobilities above a wall, symmetry about a slit's mid-plane,
//! periodic copies, the symmetric positive definite mobility matrix, and the errors that
//! name a particle out of its domain.

use std::collections::BTreeMap;
use std::f64::consts::PI;

use mesoflow::graph::Graph;
use mesoflow::value::HostArray;

use crate::util::mobility::{cholesky_min_pivot, eval, mobility_plan};
use crate::util::{
    compile_cached, gpu, load_with, mobility_recorder, particles, plan_graph, run_program, types_of,
};

type V3 = [f64; 3];

fn load(sets: &[(&str, String)]) -> Graph {
    let sets: Vec<(&str, &str)> = sets.iter().map(|(k, v)| (*k, v.as_str())).collect();
    load_with("dpstokes.json", &sets, 1, 0)
}

/// The mobility matrix (3N x 3N) of `g` at positions `x`, column by column.
fn mobility(g: &Graph, x: &[V3]) -> Vec<Vec<f64>> {
    let gpu = gpu().expect("a GPU");
    let n = x.len();
    let plan = mobility_plan(&gpu, g, n as u32, false, &["velocities"]);
    let mut program = compile_cached(&gpu, g, &plan);
    let mut m = vec![vec![0.0; 3 * n]; 3 * n];
    for col in 0..3 * n {
        let mut f = vec![[0.0; 3]; n];
        f[col / 3][col % 3] = 1.0;
        let u = &eval(&mut program, x, &f, None)["velocities"];
        for (row, m_row) in m.iter_mut().enumerate() {
            m_row[col] = u[row / 3][row % 3];
        }
    }
    m
}

/// The doubly periodic open-mode self-mobility (xx, zz; eta = 1) of the window the
/// planner picks for radius a in a box lx x ly (`stokes_slab::open_self_mobility`, f64,
/// over the window's 1-D transform).
fn open_doubly_periodic_self(kernel: &str, a: f64, lx: f64, ly: f64) -> (f64, f64) {
    use mesoflow::nodes::spread::window::Window;
    use mesoflow::nodes::stokes_slab::{open_self_mobility, plan};
    let p = plan(&[lx, ly], a, 1e-3, -3.0, 3.0, "none", false, kernel).unwrap();
    let (width, beta) = (p[7], p[9]);
    let (window, kmax) = if kernel == "es" {
        (
            Window::es_with_half_width(beta, p[5] as u32, width),
            3.0 * beta / width,
        )
    } else {
        (
            Window::Gaussian {
                sigma: width,
                support: p[5] as u32,
            },
            37f64.sqrt() / width,
        )
    };
    open_self_mobility(|k| window.transform(k, 1.0), kmax, lx, ly)
}

/// Rotne-Prager-Blake self-mobilities over 1 / (6 pi eta a) at height h (Swan and Brady
/// 2007; digest section 7.7): (parallel, perpendicular).
fn blake_self(a: f64, h: f64) -> (f64, f64) {
    let s = a / h;
    (
        1.0 - 9.0 / 16.0 * s + s.powi(3) / 8.0 - s.powi(5) / 16.0,
        1.0 - 9.0 / 8.0 * s + s.powi(3) / 2.0 - s.powi(5) / 8.0,
    )
}

/// The velocity of one particle at x under a force f.
fn pulled(g: &Graph, x: V3, f: V3) -> V3 {
    let gpu = gpu().expect("a GPU");
    let plan = mobility_plan(&gpu, g, 1, false, &["velocities"]);
    let mut program = compile_cached(&gpu, g, &plan);
    eval(&mut program, &[x], &[f], None)["velocities"][0]
}

/// Open z: the self-mobility matches the doubly periodic sum of the window's Green
/// function (an independent f64 computation), for either window, at any height and
/// off-grid placement, and a particle pulled along x moves only along x.
#[test]
fn the_open_mode_matches_the_doubly_periodic_sum() {
    if gpu().is_none() {
        return;
    }
    let (a, l) = (1.0, 16.0);
    for kernel in ["es", "gaussian"] {
        let (xx, zz) = open_doubly_periodic_self(kernel, a, l, l);
        let g = load(&[
            ("box", format!("[{l}, {l}]")),
            ("zmin", "-3.0".into()),
            ("zmax", "3.0".into()),
            ("walls", "\"none\"".into()),
            ("kernel", format!("\"{kernel}\"")),
        ]);
        for x in [[0.3, -0.2, 0.0], [5.1, 7.9, -2.6], [-8.0, 0.0, 2.99]] {
            let u = pulled(&g, x, [1.0, 0.0, 0.0]);
            assert!(
                (u[0] - xx).abs() < 2e-3 * xx,
                "{kernel} at {x:?}: xx {} against {xx}",
                u[0]
            );
            assert!(
                u[1].abs().max(u[2].abs()) < 1e-6 * u[0],
                "at {x:?}: off-axis {u:?}"
            );
            let w = pulled(&g, x, [0.0, 0.0, 1.0]);
            eprintln!(
                "{kernel} at {x:?}: xx {:.6} ({xx:.6}) zz {:.6} ({zz:.6})",
                u[0], w[2]
            );
            assert!(
                (w[2] - zz).abs() < 2e-3 * zz,
                "{kernel} at {x:?}: zz {} against {zz}",
                w[2]
            );
        }
    }
}

/// Brenner's (1961) exact perpendicular self-mobility over 1 / (6 pi eta a) of a sphere
/// at height h above a wall: 1 / lambda, lambda = (4/3) sinh(al) sum_n n (n + 1) / ((2n -
/// 1)(2n + 3)) [(2 sinh((2n + 1) al) + (2n + 1) sinh(2 al)) / (4 sinh^2((n + 1/2) al) -
/// (2n + 1)^2 sinh^2(al)) - 1], cosh(al) = h / a (f64, until the terms vanish).
fn brenner_perpendicular(a: f64, h: f64) -> f64 {
    let al = (h / a).acosh();
    let mut sum = 0.0;
    for n in 1..400 {
        let m = n as f64;
        if (2.0 * m + 1.0) * al > 600.0 {
            break;
        }
        let num = 2.0 * ((2.0 * m + 1.0) * al).sinh() + (2.0 * m + 1.0) * (2.0 * al).sinh();
        let den = 4.0 * ((m + 0.5) * al).sinh().powi(2) - ((2.0 * m + 1.0) * al.sinh()).powi(2);
        sum += m * (m + 1.0) / ((2.0 * m - 1.0) * (2.0 * m + 3.0)) * (num / den - 1.0);
    }
    1.0 / (4.0 / 3.0 * al.sinh() * sum)
}

/// Above a bottom wall in a wide box, the self-mobilities approach Rotne-Prager-Blake's
/// closed forms from 2 a to 10 a (within 2 %). At 1.5 a the window is not RPB's sphere
/// either: the perpendicular mobility lies between the exact sphere's (Brenner, 0.312)
/// and RPB's (0.382), within 3 % of RPB.
#[test]
fn bottom_wall_self_mobilities_approach_rotne_prager_blake() {
    if gpu().is_none() {
        return;
    }
    let a = 1.0;
    let t0 = 1.0 / (6.0 * PI * a);
    assert!((brenner_perpendicular(a, 1.5) - 0.31197).abs() < 1e-4);
    for kernel in ["es", "gaussian"] {
        let g = load(&[
            ("box", "[128.0, 128.0]".into()),
            ("zmin", "0.0".into()),
            ("zmax", "10.0".into()),
            ("walls", "\"bottom\"".into()),
            ("kernel", format!("\"{kernel}\"")),
        ]);
        for h in [1.5, 2.0, 4.0, 10.0] {
            let (par, perp) = blake_self(a, h);
            let near = if h < 2.0 { 0.03 } else { 0.02 };
            let u = pulled(&g, [0.3, -0.2, h], [1.0, 0.0, 0.0]);
            let w = pulled(&g, [0.3, -0.2, h], [0.0, 0.0, 1.0]);
            eprintln!(
                "{kernel} h {h}: par {:.5} ({par:.5}) perp {:.5} ({perp:.5}, exact {:.5})",
                u[0] / t0,
                w[2] / t0,
                brenner_perpendicular(a, h)
            );
            assert!(
                (u[0] / t0 - par).abs() < near * par,
                "{kernel} h {h}: parallel {} against {par}",
                u[0] / t0
            );
            assert!(
                (w[2] / t0 - perp).abs() < near * perp
                    && (h >= 2.0 || w[2] / t0 > brenner_perpendicular(a, h)),
                "{kernel} h {h}: perpendicular {} against {perp}",
                w[2] / t0
            );
            assert!(
                u[1].abs().max(u[2].abs()) < 1e-6 * u[0],
                "{kernel} h {h}: off-axis {u:?}"
            );
        }
    }
}

/// A slit is symmetric about its mid-plane (a particle and its mirror image move as mirror
/// images), and a very tall slit approaches the bottom wall alone.
#[test]
fn slits_are_symmetric_and_tall_ones_approach_one_wall() {
    if gpu().is_none() {
        return;
    }
    let slit = load(&[
        ("box", "[16.0, 16.0]".into()),
        ("zmin", "-2.0".into()),
        ("zmax", "4.0".into()),
        ("walls", "\"slit\"".into()),
    ]);
    let f = [0.6, -0.3, 0.8];
    let low = pulled(&slit, [0.3, 1.1, -0.5], f);
    let high = pulled(&slit, [0.3, 1.1, 2.5], [f[0], f[1], -f[2]]);
    for c in 0..3 {
        let want = if c == 2 { -low[c] } else { low[c] };
        assert!(
            (high[c] - want).abs() < 1e-3 * low[0].abs(),
            "component {c}: {high:?} against the mirror of {low:?}"
        );
    }
    // Mid-height: the perpendicular force moves it along z only.
    let mid = pulled(&slit, [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]);
    assert!(mid[0].abs().max(mid[1].abs()) < 1e-6 * mid[2], "{mid:?}");
    let box_ = ("box", "[24.0, 24.0]".to_string());
    let tall = load(&[
        box_.clone(),
        ("zmin", "0.0".into()),
        ("zmax", "40.0".into()),
        ("walls", "\"slit\"".into()),
    ]);
    let one = load(&[
        box_,
        ("zmin", "0.0".into()),
        ("zmax", "40.0".into()),
        ("walls", "\"bottom\"".into()),
    ]);
    for f in [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]] {
        let (a, b) = (
            pulled(&tall, [0.2, 0.1, 2.0], f),
            pulled(&one, [0.2, 0.1, 2.0], f),
        );
        let c = if f[0] == 1.0 { 0 } else { 2 };
        assert!(
            (a[c] - b[c]).abs() < 5e-3 * b[c],
            "{f:?}: tall slit {a:?}, bottom wall {b:?}"
        );
    }
}

/// The mobility matrix is symmetric (to the tolerance: the discrete operator is not
/// exactly self-adjoint) and positive definite, with a pair that overlaps and
/// a particle within a radius of the wall; doubling the box with copied particles gives
/// the same velocities.
#[test]
#[allow(clippy::needless_range_loop)]
fn the_mobility_matrix_is_spd_and_periodic() {
    if gpu().is_none() {
        return;
    }
    let x: Vec<V3> = vec![
        [0.0, 0.0, 2.0],
        [1.2, 0.3, 2.2],
        [-3.0, 4.0, 0.6],
        [7.9, -7.9, 5.0],
    ];
    let g = load(&[
        ("box", "[16.0, 16.0]".into()),
        ("zmin", "0.0".into()),
        ("zmax", "6.0".into()),
        ("walls", "\"bottom\"".into()),
    ]);
    let m = mobility(&g, &x);
    let n = m.len();
    let scale = m[0][0];
    for i in 0..n {
        for j in 0..i {
            assert!(
                (m[i][j] - m[j][i]).abs() < 1e-3 * scale,
                "M[{i}][{j}] = {}, M[{j}][{i}] = {}",
                m[i][j],
                m[j][i]
            );
        }
    }
    let sym: Vec<Vec<f64>> = (0..n)
        .map(|i| (0..n).map(|j| 0.5 * (m[i][j] + m[j][i])).collect())
        .collect();
    let pivot = cholesky_min_pivot(&sym);
    assert!(
        pivot.is_some_and(|p| p > 0.0),
        "not positive definite: smallest pivot {pivot:?}"
    );
    // Periodic copies: the box doubled along x with every particle copied 16 along.
    let wide = load(&[
        ("box", "[32.0, 16.0]".into()),
        ("zmin", "0.0".into()),
        ("zmax", "6.0".into()),
        ("walls", "\"bottom\"".into()),
    ]);
    let gpu = gpu().expect("a GPU");
    let f: Vec<V3> = vec![
        [1.0, 0.2, -0.3],
        [0.0, -1.0, 0.5],
        [0.3, 0.3, 1.0],
        [-0.5, 0.0, 0.2],
    ];
    let run = |g: &Graph, x: &[V3], f: &[V3]| -> Vec<f64> {
        let data: BTreeMap<String, HostArray> = [
            ("positions".to_string(), particles(x)),
            ("forces".to_string(), particles(f)),
        ]
        .into();
        let plan = plan_graph(&gpu.caps, g, types_of(&data), Some(&["velocities"]), true);
        let mut program = compile_cached(&gpu, g, &plan);
        run_program(&mut program, &data, 1)["velocities"]
            .data
            .to_f64()
    };
    let small = run(&g, &x, &f);
    let copies: Vec<V3> = x
        .iter()
        .chain(x.iter())
        .enumerate()
        .map(|(i, p)| {
            let shift = if i < x.len() { 0.0 } else { 16.0 };
            [
                p[0] + shift - if p[0] + shift >= 16.0 { 32.0 } else { 0.0 },
                p[1],
                p[2],
            ]
        })
        .collect();
    let f2: Vec<V3> = f.iter().chain(f.iter()).copied().collect();
    let big = run(&wide, &copies, &f2);
    let top = small.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for (i, v) in small.iter().enumerate() {
        for copy in [i, i + small.len()] {
            assert!(
                (big[copy] - v).abs() < 1e-3 * top,
                "word {i}: {v} in the box, {} doubled",
                big[copy]
            );
        }
    }
}

/// A particle below the bottom wall, above a slit's top or out of [zmin, zmax] on an open
/// side is an error that names it.
#[test]
fn particles_through_a_wall_are_refused() {
    let Some(gpu) = gpu() else { return };
    // Open sides are padded in the grid, but the particles' domain stays [zmin, zmax].
    // Sorted particles too: the sort's gather passes the rows through to the check.
    for (walls, z, sort) in [
        ("bottom", -0.1, false),
        ("slit", 6.5, false),
        ("bottom", 6.5, false),
        ("none", -0.5, false),
        ("bottom", -0.1, true),
        ("slit", 6.5, true),
    ] {
        let g = load(&[
            ("box", "[16.0, 16.0]".into()),
            ("zmin", "0.0".into()),
            ("zmax", "6.0".into()),
            ("walls", format!("\"{walls}\"")),
            ("sort_particles", sort.to_string()),
        ]);
        let data: BTreeMap<String, HostArray> = [
            (
                "positions".to_string(),
                particles(&[[0.0, 0.0, 2.0], [1.0, 0.0, z]]),
            ),
            ("forces".to_string(), particles(&[[0.0; 3]; 2])),
        ]
        .into();
        let plan = plan_graph(&gpu.caps, &g, types_of(&data), Some(&["velocities"]), true);
        let mut program = compile_cached(&gpu, &g, &plan);
        let err = program.upload(&data).unwrap_err().to_string();
        assert!(
            err.contains("row 1") && err.contains("positions"),
            "{walls}: {err}"
        );
    }
}

/// Sorting the particles by column (what dpstokes.json does where the grid outgrows the
/// cache) changes only the order of the sums: the same velocities and angular velocities
/// in the input's order, for particles spread over many columns, a few sharing one.
#[test]
fn sorting_the_particles_changes_only_rounding() {
    let Some(gpu) = gpu() else { return };
    let n = 60;
    let mut state = 12345u64;
    let mut uniform = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let x: Vec<V3> = (0..n)
        .map(|i| {
            if i < 4 {
                [3.0 + 0.1 * i as f64, -2.0, 1.5 + i as f64]
            } else {
                [
                    24.0 * uniform() - 12.0,
                    24.0 * uniform() - 12.0,
                    1.0 + 5.0 * uniform(),
                ]
            }
        })
        .collect();
    let f: Vec<V3> = (0..n)
        .map(|_| [uniform() - 0.5, uniform() - 0.5, uniform() - 0.5])
        .collect();
    let t: Vec<V3> = (0..n)
        .map(|_| [uniform() - 0.5, uniform() - 0.5, uniform() - 0.5])
        .collect();
    let data: BTreeMap<String, HostArray> = [
        ("positions".to_string(), particles(&x)),
        ("forces".to_string(), particles(&f)),
        ("torques".to_string(), particles(&t)),
    ]
    .into();
    let run = |sort: bool| {
        let g = load(&[
            ("box", "[24.0, 24.0]".into()),
            ("zmin", "0.0".into()),
            ("zmax", "7.0".into()),
            ("walls", "\"bottom\"".into()),
            ("rotation", "true".into()),
            ("sort_particles", sort.to_string()),
        ]);
        let plan = plan_graph(
            &gpu.caps,
            &g,
            types_of(&data),
            Some(&["velocities", "angular_velocities"]),
            true,
        );
        let ran_sort = !plan
            .pruned
            .iter()
            .any(|&node| g.nodes[node].id == "mobility/order");
        assert_eq!(ran_sort, sort, "the plan sorts only when asked");
        let mut program = compile_cached(&gpu, &g, &plan);
        let out = run_program(&mut program, &data, 1);
        (
            out["velocities"].data.to_f64(),
            out["angular_velocities"].data.to_f64(),
        )
    };
    let (u0, w0) = run(false);
    let (u1, w1) = run(true);
    for (a, b) in [(&u0, &u1), (&w0, &w1)] {
        let scale = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(scale > 0.0);
        for (i, (p, q)) in a.iter().zip(b).enumerate() {
            assert!(
                (p - q).abs() <= 1e-5 * scale,
                "entry {i}: unsorted {p}, sorted {q} (scale {scale})"
            );
        }
    }
}

/// Fluctuation-dissipation near a wall: the noise's covariance is the mobility (assembled
/// from M F runs), element by element within five standard errors; the drift's mean is
/// kT div M (central differences of assembled mobilities), within five standard errors,
/// and points away from the wall.
#[test]
fn noise_covariance_and_drift_match_the_mobility() {
    if gpu().is_none() {
        return;
    }
    let sets =
        r#"{"box": [8.0, 8.0], "zmin": 0.0, "zmax": 3.0, "walls": "bottom", "temperature": 1.0}"#;
    let x: Vec<V3> = vec![[0.0, 0.0, 1.3], [1.5, 0.5, 2.0]];
    let n = x.len();
    let steps = 1000u64;
    let (dir, g) = mobility_recorder("dpstokes.json", sets, n, steps, &["noise", "drift"], 5);
    let out = {
        let gpu = gpu().expect("a GPU");
        let data: BTreeMap<String, HostArray> = [("positions".to_string(), particles(&x))].into();
        let plan = plan_graph(&gpu.caps, &g, types_of(&data), None, true);
        let mut program = compile_cached(&gpu, &g, &plan);
        run_program(&mut program, &data, steps)
    };
    let _ = std::fs::remove_dir_all(&dir);
    let noise = out["noise"].to_ref().data;
    let drift = out["drift"].to_ref().data;
    let single = load(&[
        ("box", "[8.0, 8.0]".into()),
        ("zmin", "0.0".into()),
        ("zmax", "3.0".into()),
        ("walls", "\"bottom\"".into()),
    ]);
    let m = mobility(&single, &x);
    let dim = 3 * n;
    for p in 0..dim {
        for q in 0..dim {
            let cov: f64 = (0..steps as usize)
                .map(|s| noise[s * dim + p] * noise[s * dim + q])
                .sum::<f64>()
                / steps as f64;
            let se = ((m[p][p] * m[q][q] + m[p][q] * m[p][q]) / steps as f64).sqrt();
            assert!(
                (cov - m[p][q]).abs() < 5.0 * se,
                "noise covariance [{p}][{q}] = {cov:e}, M = {:e} (standard error {se:e})",
                m[p][q]
            );
        }
    }
    // kT div M: (div M)_i = sum_j d M_ij / d x_j, by central differences of assembled
    // matrices (kT = 1).
    let delta = 0.02;
    let mut div = vec![0.0; dim];
    for j in 0..dim {
        let at = |d: f64| {
            let mut y = x.clone();
            y[j / 3][j % 3] += d;
            mobility(&single, &y)
        };
        let (up, down) = (at(delta), at(-delta));
        for i in 0..dim {
            div[i] += (up[i][j] - down[i][j]) / (2.0 * delta);
        }
    }
    for i in 0..dim {
        let samples: Vec<f64> = (0..steps as usize).map(|s| drift[s * dim + i]).collect();
        let mean = samples.iter().sum::<f64>() / steps as f64;
        let var = samples.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / steps as f64;
        let se = (var / steps as f64).sqrt();
        assert!(
            (mean - div[i]).abs() < 5.0 * se + 2e-3 * div[i].abs(),
            "drift word {i}: {mean:e} against kT div M {:e} (standard error {se:e})",
            div[i]
        );
    }
    assert!(
        div[2] > 0.0 && div[5] > 0.0,
        "the drift points away from the wall: {div:?}"
    );
}

/// The sedimentation example at kT = 0: a lone sphere's first step falls by dt times its
/// weight times the perpendicular mobility dpstokes.json gives at its height.
#[test]
fn the_sedimentation_example_falls_at_the_wall_mobility() {
    if gpu().is_none() {
        return;
    }
    let (dt, weight, h) = (0.5, 2.0, 6.0);
    let sets = [
        ("n", "1".to_string()),
        ("side", "32.0".into()),
        ("start_low", format!("{h}")),
        ("start_high", format!("{h}")),
        ("temperature", "0.0".into()),
        ("weight", format!("{weight}")),
        ("dt", format!("{dt}")),
        ("save_every", "1".into()),
    ];
    let sets: Vec<(&str, &str)> = sets.iter().map(|(k, v)| (*k, v.as_str())).collect();
    let steps = 2;
    let g = load_with("examples/sediment.json", &sets, steps, 3);
    let out = {
        let gpu = gpu().expect("a GPU");
        let data = BTreeMap::new();
        let plan = plan_graph(&gpu.caps, &g, types_of(&data), None, true);
        let mut program = compile_cached(&gpu, &g, &plan);
        run_program(&mut program, &data, steps)
    };
    let heights = out["mean_height"].data.to_f64();
    let wall = load(&[
        ("box", "[32.0, 32.0]".into()),
        ("zmin", "0.0".into()),
        ("zmax", "16.0".into()),
        ("walls", "\"bottom\"".into()),
    ]);
    let u = pulled(&wall, [1.0, -2.0, h], [0.0, 0.0, -weight]);
    let want = h + dt * u[2];
    assert!(
        (heights[0] - want).abs() < 1e-4 * (h - want).abs().max(1e-3),
        "first step to {}, want {want}",
        heights[0]
    );
    assert!(
        heights[1] < heights[0],
        "the sphere stopped falling: {heights:?}"
    );
}

/// (velocity, angular velocity) of one particle at x under a force f and a torque t, with
/// rotation.
fn grand_one(g: &Graph, x: V3, f: V3, t: V3) -> (V3, V3) {
    let gpu = gpu().expect("a GPU");
    let plan = mobility_plan(&gpu, g, 1, true, &["velocities", "angular_velocities"]);
    let mut program = compile_cached(&gpu, g, &plan);
    let out = eval(&mut program, &[x], &[f], Some(&[t]));
    (out["velocities"][0], out["angular_velocities"][0])
}

/// Torques: far from everything the rotational self-mobility is 1 / (8 pi eta a^3) (the
/// torque Gaussian's), and above a wall it follows Rotne-Prager-Blake's rotational and
/// coupling terms (1 - 5/16 s^3, 1 - 1/8 s^3, and a force along x turning the sphere about
/// y by s^4 / 8 of 1 / (8 pi eta a^2), as if it rolled); torques only and forces only.
#[test]
fn torques_turn_the_spheres_as_rotne_prager_blake() {
    if gpu().is_none() {
        return;
    }
    let a: f64 = 1.0;
    let r0 = 1.0 / (8.0 * PI * a.powi(3));
    let rt0 = 1.0 / (8.0 * PI * a * a);
    let open = load(&[
        ("box", "[32.0, 32.0]".into()),
        ("zmin", "-2.0".into()),
        ("zmax", "2.0".into()),
        ("walls", "\"none\"".into()),
        ("rotation", "true".into()),
    ]);
    let (u, w) = grand_one(&open, [0.2, 0.1, 0.3], [0.0; 3], [1.0, 0.0, 0.0]);
    assert!(
        (w[0] - r0).abs() < 5e-3 * r0,
        "open rotation {} against {r0}",
        w[0]
    );
    assert!(
        u.iter().all(|v| v.abs() < 1e-3 * rt0),
        "a torque alone moved the sphere: {u:?}"
    );
    let (_, w) = grand_one(&open, [0.2, 0.1, 0.3], [0.0; 3], [0.0, 0.0, 1.0]);
    assert!(
        (w[2] - r0).abs() < 5e-3 * r0,
        "open rotation about z {} against {r0}",
        w[2]
    );
    let wall = load(&[
        ("box", "[64.0, 64.0]".into()),
        ("zmin", "0.0".into()),
        ("zmax", "5.0".into()),
        ("walls", "\"bottom\"".into()),
        ("rotation", "true".into()),
    ]);
    for h in [2.0, 4.0] {
        let s = a / h;
        let x = [0.3, -0.2, h];
        let (_, wx) = grand_one(&wall, x, [0.0; 3], [1.0, 0.0, 0.0]);
        let (_, wz) = grand_one(&wall, x, [0.0; 3], [0.0, 0.0, 1.0]);
        let (_, wf) = grand_one(&wall, x, [1.0, 0.0, 0.0], [0.0; 3]);
        let (par, perp, roll) = (
            r0 * (1.0 - 5.0 / 16.0 * s.powi(3)),
            r0 * (1.0 - s.powi(3) / 8.0),
            rt0 * s.powi(4) / 8.0,
        );
        eprintln!(
            "h {h}: rot par {:.5} ({:.5}) perp {:.5} ({:.5}) roll {:.3e} ({:.3e})",
            wx[0] / r0,
            par / r0,
            wz[2] / r0,
            perp / r0,
            wf[1] / rt0,
            roll / rt0
        );
        assert!(
            (wx[0] - par).abs() < 0.02 * r0,
            "h {h}: rotation about x {} against {par}",
            wx[0]
        );
        assert!(
            (wz[2] - perp).abs() < 0.02 * r0,
            "h {h}: rotation about z {} against {perp}",
            wz[2]
        );
        assert!(
            (wf[1] - roll).abs() < 0.01 * rt0,
            "h {h}: rolling {} against {roll}",
            wf[1]
        );
    }
}

/// Extreme boxes: a very tall domain (hundreds of Chebyshev points) gives the short one's
/// mobility near the wall; a very flat slit (Lx = 16 H) stays finite, slows the sphere
/// more than one wall does, and more across the slit than along it.
#[test]
fn very_tall_and_very_flat_boxes_stay_accurate() {
    if gpu().is_none() {
        return;
    }
    let make = |zmax: f64, walls: &str, side: f64| {
        load(&[
            ("box", format!("[{side}, {side}]")),
            ("zmin", "0.0".into()),
            ("zmax", format!("{zmax}")),
            ("walls", format!("\"{walls}\"")),
        ])
    };
    let x = [0.3, 0.2, 2.0];
    let (short, tall) = (make(6.0, "bottom", 16.0), make(120.0, "bottom", 16.0));
    for f in [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]] {
        let (a, b) = (pulled(&short, x, f), pulled(&tall, x, f));
        let c = if f[0] == 1.0 { 0 } else { 2 };
        assert!(
            (a[c] - b[c]).abs() < 2e-3 * a[c],
            "{f:?}: short {a:?}, tall {b:?}"
        );
    }
    let flat = make(4.0, "slit", 64.0);
    let one = make(4.0, "bottom", 64.0);
    let (sx, sz) = (
        pulled(&flat, x, [1.0, 0.0, 0.0]),
        pulled(&flat, x, [0.0, 0.0, 1.0]),
    );
    let bx = pulled(&one, x, [1.0, 0.0, 0.0]);
    assert!(
        sx[0] > 0.0 && sz[2] > 0.0 && sx[0].is_finite(),
        "{sx:?} {sz:?}"
    );
    assert!(
        sx[0] < bx[0],
        "the slit {} against one wall {}",
        sx[0],
        bx[0]
    );
    assert!(sz[2] < sx[0], "across {} against along {}", sz[2], sx[0]);
}

/// Two spheres at the same height above a wall, in a wide box: the pair mobility (the
/// velocity of one under a force on the other, along the line, across it and normal to
/// the wall) is rpy_wall.json's Rotne-Prager-Blake pair mobility (itself checked against
/// its f64 twin and Blake's solution in tests/it/nbody.rs) to a few 1e-3 of the self
/// mobility.
#[test]
fn pair_mobilities_at_one_height_follow_rotne_prager_blake() {
    if gpu().is_none() {
        return;
    }
    let dp = load(&[
        ("box", "[96.0, 96.0]".into()),
        ("zmin", "0.0".into()),
        ("zmax", "5.0".into()),
        ("walls", "\"bottom\"".into()),
    ]);
    let rpb = load_with("rpy_wall.json", &[("wall_height", "0.0")], 1, 0);
    let t0 = 1.0 / (6.0 * PI);
    for (h, r) in [(2.0, 3.0), (3.0, 6.0)] {
        let x = [[-r / 2.0, 0.3, h], [r / 2.0, 0.3, h]];
        let (m, want) = (mobility(&dp, &x), mobility(&rpb, &x));
        for (row, col) in [(3, 0), (4, 1), (5, 2), (0, 0), (2, 2)] {
            assert!(
                (m[row][col] - want[row][col]).abs() < 5e-3 * t0,
                "h {h}, r {r}: M[{row}][{col}] = {:.5e}, Rotne-Prager-Blake {:.5e}",
                m[row][col],
                want[row][col]
            );
        }
    }
}

/// The fused solve between the Chebyshev transforms (slab fused and staged, slab_solve's
/// two kernels) and the chain of nodes (slab chain) give the same velocities and angular
/// velocities, every wall mode, torques included (their curl enters the forcing the fused
/// node reads; the angular velocities take the curl of its output) and not (staged then
/// takes the forces' values along z, no forward transform before it).
#[test]
fn the_fused_slab_solve_gives_the_chains_mobility() {
    let Some(gpu) = gpu() else { return };
    let n = 12;
    let x: Vec<V3> = (0..n)
        .map(|i| {
            let s = i as f64;
            [
                (7.3 * s).sin() * 9.0,
                (3.1 * s + 1.0).cos() * 9.0,
                1.2 + 0.4 * s,
            ]
        })
        .collect();
    let f: Vec<V3> = (0..n)
        .map(|i| [0, 1, 2].map(|a| ((i * 3 + a) as f64 * 1.7).sin()))
        .collect();
    let t: Vec<V3> = (0..n)
        .map(|i| [0, 1, 2].map(|a| ((i * 3 + a) as f64 * 0.9).cos()))
        .collect();
    let data: BTreeMap<String, HostArray> = [
        ("positions".to_string(), particles(&x)),
        ("forces".to_string(), particles(&f)),
        ("torques".to_string(), particles(&t)),
    ]
    .into();
    for walls in ["none", "bottom", "slit"] {
        let run = |slab: &str, rotation: bool| {
            let g = load(&[
                ("box", "[20.0, 24.0]".into()),
                ("zmin", "0.0".into()),
                ("zmax", "6.5".into()),
                ("walls", format!("\"{walls}\"")),
                ("rotation", rotation.to_string()),
                ("slab", format!("\"{slab}\"")),
            ]);
            let mut data = data.clone();
            if !rotation {
                data.remove("torques");
            }
            let outputs: &[&str] = if rotation {
                &["velocities", "angular_velocities"]
            } else {
                &["velocities"]
            };
            let plan = plan_graph(&gpu.caps, &g, types_of(&data), Some(outputs), true);
            let ran = |id: &str| {
                !plan
                    .pruned
                    .iter()
                    .any(|&node| g.nodes[node].id == format!("mobility/{id}"))
            };
            assert_eq!(
                ran("fused_velocity_plane"),
                slab != "chain",
                "{walls}: the plan runs slab {slab}"
            );
            // The staged kernel takes the forces' values along z itself, unless the torques'
            // curl is added to their coefficients first.
            assert_eq!(
                ran("force_coefficients"),
                slab != "staged" || rotation,
                "{walls}: slab {slab}, rotation {rotation}: the forward transform"
            );
            let mut program = compile_cached(&gpu, &g, &plan);
            let out = run_program(&mut program, &data, 1);
            outputs
                .iter()
                .map(|o| out[*o].data.to_f64())
                .collect::<Vec<_>>()
        };
        for rotation in [true, false] {
            let want = run("chain", rotation);
            for slab in ["fused", "staged"] {
                let got = run(slab, rotation);
                for (what, a, b) in [
                    ("velocities", &want[0], &got[0]),
                    (
                        "angular velocities",
                        want.last().unwrap(),
                        got.last().unwrap(),
                    ),
                ] {
                    let scale = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                    assert!(scale > 0.0);
                    for (i, (p, q)) in a.iter().zip(b).enumerate() {
                        assert!(
                            (p - q).abs() <= 1e-5 * scale,
                            "{walls} rotation {rotation} {what} entry {i}: chain {p}, {slab} {q} (scale {scale})"
                        );
                    }
                }
            }
        }
    }
}
