//! graphs/rpy_open.json (with torques) and graphs/rpy_wall.json (Rotne-Prager-Blake)
//! against physics: the grand open RPY against an f64 sum written here from the closed
//! forms; the wall self mobilities against Swan and Brady's closed forms at several
//! heights (translation, rotation, coupling) and the damping below one radius; a pair of
//! small spheres far from each other against Blake's point-force solution written here;
//! the GPU against the kernels' f64 twin; symmetry and positive definiteness of the
//! assembled grand mobility (overlapping pairs, spheres touching and overlapping the
//! wall); fluctuation-dissipation (noise covariance = M); the drift against a central
//! finite-difference divergence; particles below the wall refused by name.

use std::collections::BTreeMap;
use std::f64::consts::PI;

use mesoflow::graph::Graph;
use mesoflow::nodes::pairs::blake::blake;
use mesoflow::value::HostArray;

use crate::util::mobility::{cholesky_min_pivot, eval, mobility_plan};
use crate::util::{
    Rng, compile_cached, gpu, load_with, mobility_recorder, particles, plan_graph, run_program,
    types_of, vectors,
};

type V3 = [f64; 3];

fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// The open grand RPY mobility (eta = 1) applied to (f, t) of j, seen at i, r = x_i - x_j,
/// from the textbook closed forms (Wajnryb et al. 2013 for the overlap forms).
fn grand_rpy(r: V3, a: f64, f: V3, t: V3, same: bool) -> (V3, V3) {
    if same {
        return (
            f.map(|x| x / (6.0 * PI * a)),
            t.map(|x| x / (8.0 * PI * a * a * a)),
        );
    }
    let d = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
    let e = r.map(|x| x / d);
    let ef = e[0] * f[0] + e[1] * f[1] + e[2] * f[2];
    let et = e[0] * t[0] + e[1] * t[1] + e[2] * t[2];
    let (tt_i, tt_e, rr_i, rr_e, c) = if d >= 2.0 * a {
        let k = 1.0 / (8.0 * PI * d);
        let s = a * a / (d * d);
        let k3 = 1.0 / (16.0 * PI * d * d * d);
        (
            k * (1.0 + 2.0 * s / 3.0),
            k * (1.0 - 2.0 * s),
            -k3,
            3.0 * k3,
            1.0 / (8.0 * PI * d * d * d),
        )
    } else {
        let k = 1.0 / (6.0 * PI * a);
        let kr = 1.0 / (8.0 * PI * a * a * a);
        let x = d / a;
        (
            k * (1.0 - 9.0 * x / 32.0),
            k * 3.0 * x / 32.0,
            kr * (1.0 - 27.0 * x / 32.0 + 5.0 * x * x * x / 64.0),
            kr * (9.0 * x / 32.0 - 3.0 * x * x * x / 64.0),
            (1.0 - 3.0 * x / 8.0) / (16.0 * PI * a * a * a),
        )
    };
    let tf = cross(t, r);
    let ff = cross(f, r);
    let u = [0, 1, 2].map(|k| tt_i * f[k] + tt_e * ef * e[k] + c * tf[k]);
    let w = [0, 1, 2].map(|k| rr_i * t[k] + rr_e * et * e[k] + c * ff[k]);
    (u, w)
}

fn load(name: &str, sets: &[(&str, String)]) -> Graph {
    let sets: Vec<(&str, &str)> = sets.iter().map(|(k, v)| (*k, v.as_str())).collect();
    load_with(name, &sets, 1, 0)
}

/// (velocities, angular velocities) of graph `g` (rotation on) for these inputs.
fn grand(g: &Graph, x: &[V3], f: &[V3], t: &[V3]) -> (Vec<V3>, Vec<V3>) {
    let gpu = gpu().expect("a GPU");
    let plan = mobility_plan(
        &gpu,
        g,
        x.len() as u32,
        true,
        &["velocities", "angular_velocities"],
    );
    let mut program = compile_cached(&gpu, g, &plan);
    let mut out = eval(&mut program, x, f, Some(t));
    (
        out.remove("velocities").expect("velocities"),
        out.remove("angular_velocities")
            .expect("angular velocities"),
    )
}

/// The grand mobility (6N x 6N, rows and columns ordered as f_0, t_0, f_1, ...) of a graph
/// by unit forces and torques, one at a time.
#[allow(clippy::needless_range_loop)]
fn assemble(g: &Graph, x: &[V3]) -> Vec<Vec<f64>> {
    let n = x.len();
    let mut m = vec![vec![0.0; 6 * n]; 6 * n];
    for col in 0..6 * n {
        let mut f = vec![[0.0; 3]; n];
        let mut t = vec![[0.0; 3]; n];
        let (p, c) = (col / 6, col % 6);
        if c < 3 {
            f[p][c] = 1.0;
        } else {
            t[p][c - 3] = 1.0;
        }
        let (u, w) = grand(g, x, &f, &t);
        for i in 0..n {
            for k in 0..3 {
                m[6 * i + k][col] = u[i][k];
                m[6 * i + 3 + k][col] = w[i][k];
            }
        }
    }
    m
}

/// The grand mobility (6N x 6N, ordered as `assemble`) of an f64 pair function
/// `pair(x_i, x_j, f_j, t_j, i == j) -> (u_i, w_i)`.
fn grand_matrix(x: &[V3], pair: impl Fn(V3, V3, V3, V3, bool) -> (V3, V3)) -> Vec<Vec<f64>> {
    let n = x.len();
    let mut m = vec![vec![0.0; 6 * n]; 6 * n];
    for i in 0..n {
        for j in 0..n {
            for c in 0..6 {
                let (mut f, mut t) = ([0.0; 3], [0.0; 3]);
                if c < 3 {
                    f[c] = 1.0;
                } else {
                    t[c - 3] = 1.0;
                }
                let (u, w) = pair(x[i], x[j], f, t, i == j);
                for k in 0..3 {
                    m[6 * i + k][6 * j + c] = u[k];
                    m[6 * i + 3 + k][6 * j + c] = w[k];
                }
            }
        }
    }
    m
}

fn relative_max(got: &[Vec<f64>], want: &[Vec<f64>]) -> f64 {
    let scale = want.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    got.iter()
        .flatten()
        .zip(want.iter().flatten())
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()))
        / scale
}

/// Positions of small clusters: overlapping pairs, one at contact, others apart.
fn cluster(rng: &mut Rng, n: usize, height: f64) -> Vec<V3> {
    (0..n)
        .map(|_| {
            [
                rng.uniform(-2.0, 2.0),
                rng.uniform(-2.0, 2.0),
                height + rng.uniform(0.0, 3.0),
            ]
        })
        .collect()
}

/// The open grand mobility (forces and torques) against the closed forms, overlapping
/// pairs included.
#[test]
fn open_grand_rpy_matches_the_closed_forms() {
    if gpu().is_none() {
        return;
    }
    let a = 0.8;
    let g = load(
        "rpy_open.json",
        &[("rotation", "true".into()), ("radius", format!("{a}"))],
    );
    let mut rng = Rng::new(31);
    let x = cluster(&mut rng, 7, 0.0);
    let got = assemble(&g, &x);
    let want = grand_matrix(&x, |xi, xj, f, t, same| {
        grand_rpy([0, 1, 2].map(|k| xi[k] - xj[k]), a, f, t, same)
    });
    let err = relative_max(&got, &want);
    assert!(err < 2e-6, "open grand RPY: relative error {err:e}");
    assert!(cholesky_min_pivot(&want).is_some());
}

/// One sphere above the wall: translation parallel and perpendicular, rotation parallel
/// and perpendicular, and the coupling, against Swan and Brady's self mobilities (over
/// 6 pi eta a, 8 pi eta a^3, 8 pi eta a^2):
/// 1 - 9/16 s + 1/8 s^3 - 1/16 s^5, 1 - 9/8 s + 1/2 s^3 - 1/8 s^5, 1 - 5/16 s^3,
/// 1 - 1/8 s^3 and 1/8 s^4, s = a / h; below h = a, the same at h = a times (h / a)^2.
#[test]
fn wall_self_mobilities_are_swan_and_brady_s() {
    if gpu().is_none() {
        return;
    }
    let (a, wall) = (1.5, -2.0);
    let g = load(
        "rpy_wall.json",
        &[
            ("rotation", "true".into()),
            ("radius", format!("{a}")),
            ("wall_height", format!("{wall}")),
        ],
    );
    let t0 = 1.0 / (6.0 * PI * a);
    let r0 = 1.0 / (8.0 * PI * a.powi(3));
    let rt0 = 1.0 / (8.0 * PI * a * a);
    for hh in [0.5, 1.0, 1.2, 2.0, 4.0, 8.0] {
        let x = [[0.7, -0.3, wall + hh * a]];
        let m = assemble(&g, &x);
        let s = 1.0 / hh.max(1.0);
        let damp = hh.min(1.0).powi(2);
        let want = [
            (
                0,
                0,
                t0 * (1.0 - 9.0 / 16.0 * s + s.powi(3) / 8.0 - s.powi(5) / 16.0),
            ),
            (
                1,
                1,
                t0 * (1.0 - 9.0 / 16.0 * s + s.powi(3) / 8.0 - s.powi(5) / 16.0),
            ),
            (
                2,
                2,
                t0 * (1.0 - 9.0 / 8.0 * s + s.powi(3) / 2.0 - s.powi(5) / 8.0),
            ),
            (3, 3, r0 * (1.0 - 5.0 / 16.0 * s.powi(3))),
            (4, 4, r0 * (1.0 - 5.0 / 16.0 * s.powi(3))),
            (5, 5, r0 * (1.0 - s.powi(3) / 8.0)),
            // A force along x turns the sphere about y as if it rolled on the wall:
            // w_y = (1/8) s^4 f_x / (8 pi eta a^2), and the coupling is symmetric.
            (4, 0, rt0 * s.powi(4) / 8.0),
            (0, 4, rt0 * s.powi(4) / 8.0),
            (3, 1, -rt0 * s.powi(4) / 8.0),
            (1, 3, -rt0 * s.powi(4) / 8.0),
            (2, 5, 0.0),
            (0, 1, 0.0),
        ];
        for (row, col, w) in want {
            let got = m[row][col];
            let scale = [t0, r0, rt0][if row < 3 && col < 3 {
                0
            } else if row >= 3 && col >= 3 {
                1
            } else {
                2
            }];
            assert!(
                (got - damp * w).abs() < 2e-6 * scale,
                "h = {hh} a: M[{row}][{col}] = {got:e}, want {:e}",
                damp * w
            );
        }
    }
}

/// Blake's point-force solution near a wall (eta = 1, wall z = 0): the velocity at x from a
/// force f at y, Stokeslet minus its image plus the source doublet and Stokes doublet
/// images (Blake 1971), written here from the textbook form.
fn blake_stokeslet(x: V3, y: V3, f: V3) -> V3 {
    let h = y[2];
    let r = [x[0] - y[0], x[1] - y[1], x[2] - y[2]];
    let rr = [x[0] - y[0], x[1] - y[1], x[2] + y[2]];
    let oseen = |r: V3, f: V3| {
        let d = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
        let rf = r[0] * f[0] + r[1] * f[1] + r[2] * f[2];
        [0, 1, 2].map(|k| f[k] / d + rf * r[k] / (d * d * d))
    };
    let mut u = oseen(r, f);
    let img = oseen(rr, f);
    let d = (rr[0] * rr[0] + rr[1] * rr[1] + rr[2] * rr[2]).sqrt();
    let (d3, d5) = (d.powi(3), d.powi(5));
    // The image system's extra terms (Blake 1971): with M = diag(1, 1, -1) on the force,
    // 2 h sum_k M_kk f_k d/dR_k [h R_i / R^3 - delta_i3 / R - R_i R_3 / R^3].
    let mut extra = [0.0; 3];
    for i in 0..3 {
        for k in 0..3 {
            let m = if k == 2 { -1.0 } else { 1.0 };
            let dik = if i == k { 1.0 } else { 0.0 };
            let di3 = if i == 2 { 1.0 } else { 0.0 };
            let d3k = if k == 2 { 1.0 } else { 0.0 };
            let dphi = h * (dik / d3 - 3.0 * rr[i] * rr[k] / d5) + di3 * rr[k] / d3
                - (dik * rr[2] + rr[i] * d3k) / d3
                + 3.0 * rr[i] * rr[2] * rr[k] / d5;
            extra[i] += 2.0 * h * m * f[k] * dphi;
        }
    }
    for k in 0..3 {
        u[k] = (u[k] - img[k] + extra[k]) / (8.0 * PI);
    }
    u
}

/// Two small spheres far from each other and from the wall: the pair mobility tends to
/// Blake's point-force solution (corrections O(a^2 / r^2); measured 2e-4 of the free
/// Stokeslet at a / r = 0.016).
#[test]
fn far_apart_small_spheres_see_blake_s_solution() {
    if gpu().is_none() {
        return;
    }
    let a = 0.01;
    let g = load("rpy_wall.json", &[("radius", format!("{a}"))]);
    let gpu = gpu().expect("checked");
    for (xi, xj) in [
        ([0.0, 0.0, 1.0], [1.5, 0.5, 2.0]),
        ([0.3, -0.2, 0.7], [0.1, 0.4, 0.5]),
        ([0.0, 0.0, 3.0], [0.0, 0.0, 1.0]),
    ] {
        for axis in 0..3 {
            let mut f = [[0.0; 3]; 2];
            f[1][axis] = 1.0;
            let data: BTreeMap<String, HostArray> = [
                ("positions".to_string(), particles(&[xi, xj])),
                ("forces".to_string(), particles(&f)),
            ]
            .into_iter()
            .collect();
            let plan = plan_graph(&gpu.caps, &g, types_of(&data), Some(&["velocities"]), true);
            let mut program = compile_cached(&gpu, &g, &plan);
            let u = vectors(&run_program(&mut program, &data, 1)["velocities"])[0];
            let want = blake_stokeslet(xi, xj, f[1]);
            // Relative to the free Stokeslet's 1 / (8 pi eta r): the image nearly cancels
            // some components, where the spheres' O(a^2 / r^2) corrections then stand out.
            let r = ((0..3).map(|k| (xi[k] - xj[k]).powi(2)).sum::<f64>()).sqrt();
            let scale = 1.0 / (8.0 * PI * r);
            for k in 0..3 {
                assert!(
                    (u[k] - want[k]).abs() < 1e-3 * scale,
                    "{xi:?} from {xj:?}, force along {axis}: u = {u:?}, Blake {want:?}"
                );
            }
        }
    }
}

/// The GPU kernel against its f64 twin (blake.rs), every block, spheres overlapping each
/// other and the wall.
#[test]
fn wall_kernel_matches_its_f64_twin() {
    if gpu().is_none() {
        return;
    }
    let (a, wall) = (1.0, 0.5);
    let g = load(
        "rpy_wall.json",
        &[
            ("rotation", "true".into()),
            ("wall_height", format!("{wall}")),
        ],
    );
    let mut rng = Rng::new(17);
    let mut x = cluster(&mut rng, 6, wall + 0.4);
    x.push([x[0][0] + 0.3, x[0][1], x[0][2] + 0.2]);
    let got = assemble(&g, &x);
    let want = grand_matrix(&x, |xi, xj, f, t, same| {
        blake(xi, xj, f, t, a, 1.0, wall, same)
    });
    let err = relative_max(&got, &want);
    assert!(err < 5e-6, "wall kernel against its twin: {err:e}");
}

/// The assembled grand mobility is symmetric and positive definite: overlapping pairs,
/// spheres at the wall and overlapping it, open and walled.
#[test]
fn grand_mobilities_are_symmetric_and_positive_definite() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(5);
    for (name, sets, low) in [
        ("rpy_open.json", vec![("rotation", "true".to_string())], 0.0),
        ("rpy_wall.json", vec![("rotation", "true".to_string())], 1.0),
        ("rpy_wall.json", vec![("rotation", "true".to_string())], 0.3),
    ] {
        let g = load(name, &sets);
        let mut x = cluster(&mut rng, 5, low);
        // An overlapping pair and a pair at contact.
        x.push([x[0][0] + 0.5, x[0][1] + 0.2, x[0][2]]);
        x.push([x[1][0], x[1][1] + 2.0, x[1][2]]);
        let m = assemble(&g, &x);
        let scale = m.iter().flatten().fold(0.0f64, |s, v| s.max(v.abs()));
        let mut asym = 0.0f64;
        for (i, row) in m.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                asym = asym.max((v - m[j][i]).abs());
            }
        }
        assert!(
            asym < 2e-6 * scale,
            "{name} from z = {low}: asymmetry {:e}",
            asym / scale
        );
        let sym: Vec<Vec<f64>> = (0..m.len())
            .map(|i| (0..m.len()).map(|j| 0.5 * (m[i][j] + m[j][i])).collect())
            .collect();
        assert!(
            cholesky_min_pivot(&sym).is_some(),
            "{name} from z = {low}: not positive definite"
        );
    }
}

/// Fluctuation-dissipation: the noise's covariance is the grand mobility, element by
/// element within five standard errors; and the drift's mean is kT div M, the divergence
/// by central differences of the f64 twin, within five standard errors.
#[test]
fn noise_covariance_and_drift_match_the_mobility() {
    let Some(gpu) = gpu() else { return };
    let (a, kt) = (1.0, 1.0);
    let x: Vec<V3> = vec![[0.0, 0.0, 1.3], [1.6, 0.4, 1.1], [0.3, 1.9, 2.2]];
    let n = x.len();
    let steps = 3000u64;
    let (dir, g) = mobility_recorder(
        "rpy_wall.json",
        r#"{"rotation": true, "temperature": 1}"#,
        n,
        steps,
        &["noise", "angular_noise", "drift"],
        11,
    );
    let data: BTreeMap<String, HostArray> = [("positions".to_string(), particles(&x))].into();
    let plan = plan_graph(&gpu.caps, &g, types_of(&data), None, true);
    let mut program = compile_cached(&gpu, &g, &plan);
    let out = run_program(&mut program, &data, steps);
    let _ = std::fs::remove_dir_all(&dir);
    let lin = out["noise"].to_ref().data;
    let ang = out["angular_noise"].to_ref().data;
    let drift = out["drift"].to_ref().data;
    // Samples of the 6N noise vector, ordered as the assembled mobility.
    let sample = |s: usize| -> Vec<f64> {
        let mut v = Vec::with_capacity(6 * n);
        for i in 0..n {
            for k in 0..3 {
                v.push(lin[(s * n + i) * 3 + k]);
            }
            for k in 0..3 {
                v.push(ang[(s * n + i) * 3 + k]);
            }
        }
        v
    };
    let m = grand_matrix(&x, |xi, xj, f, t, same| {
        blake(xi, xj, f, t, a, 1.0, 0.0, same)
    });
    let mut cov = vec![vec![0.0; 6 * n]; 6 * n];
    for s in 0..steps as usize {
        let v = sample(s);
        for p in 0..6 * n {
            for q in 0..6 * n {
                cov[p][q] += v[p] * v[q] / steps as f64;
            }
        }
    }
    for p in 0..6 * n {
        for q in 0..6 * n {
            let se = ((m[p][p] * m[q][q] + m[p][q] * m[p][q]) / steps as f64).sqrt();
            assert!(
                (cov[p][q] - m[p][q]).abs() < 5.0 * se,
                "noise covariance [{p}][{q}] = {:e}, M = {:e} (standard error {se:e})",
                cov[p][q],
                m[p][q]
            );
        }
    }
    // kT div M by central differences of the twin: (div M)_ia = sum_j,b dM_ia,jb / dx_jb.
    let delta = 1e-5;
    let mut div = vec![[0.0; 3]; n];
    for i in 0..n {
        for j in 0..n {
            for b in 0..3 {
                let mut f = [0.0; 3];
                f[b] = 1.0;
                let at = |d: f64| {
                    let mut y = x.clone();
                    y[j][b] += d;
                    blake(y[i], y[j], f, [0.0; 3], a, 1.0, 0.0, i == j).0
                };
                let (up, down) = (at(delta), at(-delta));
                for c in 0..3 {
                    div[i][c] += kt * (up[c] - down[c]) / (2.0 * delta);
                }
            }
        }
    }
    for i in 0..n {
        for c in 0..3 {
            let samples: Vec<f64> = (0..steps as usize)
                .map(|s| drift[(s * n + i) * 3 + c])
                .collect();
            let mean = samples.iter().sum::<f64>() / steps as f64;
            let var = samples.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / steps as f64;
            let se = (var / steps as f64).sqrt();
            assert!(
                (mean - div[i][c]).abs() < 5.0 * se + 1e-4 * div[i][c].abs(),
                "drift of {i} along {c}: {mean:e} against kT div M {:e} (standard error {se:e})",
                div[i][c]
            );
        }
    }
    // Near the wall the perpendicular drift points away from it.
    assert!(div[1][2] > 0.0);
}

/// A particle whose centre is below the wall is an error naming it.
#[test]
fn particles_below_the_wall_are_refused() {
    let Some(gpu) = gpu() else { return };
    let g = load("rpy_wall.json", &[("wall_height", "1".into())]);
    let x = [[0.0, 0.0, 2.0], [1.0, 0.0, 0.5]];
    let data: BTreeMap<String, HostArray> = [
        ("positions".to_string(), particles(&x)),
        ("forces".to_string(), particles(&[[0.0; 3]; 2])),
    ]
    .into();
    let plan = plan_graph(&gpu.caps, &g, types_of(&data), Some(&["velocities"]), true);
    let mut program = compile_cached(&gpu, &g, &plan);
    let err = program.upload(&data).unwrap_err().to_string();
    assert!(
        err.contains("positions") && err.contains("row 1") && err.contains("below the wall"),
        "{err}"
    );
}
