//! graphs/pse.json and graphs/rpy_open.json against physics: the periodic RPY mobility
//! by an f64 Ewald sum written here (Hasimoto's split at its own xi: a real-space lattice
//! sum of the near field, from a Simpson quadrature of its radial integral, plus a direct
//! Fourier sum of the far field), itself checked against Hasimoto's self-mobility;
//! independence of the split; overlapping pairs; symmetry and positive definiteness;
//! fluctuation-dissipation; open-boundary RPY against the closed form.

use std::f64::consts::PI;

use crate::util::mobility::{
    M3, axis_mobilities, cholesky_min_pivot, eval, hasimoto, mobility_plan, noise_statistics,
    random_positions,
};
use crate::util::{Rng, compile_cached, gpu, load_error, load_with, particles, vectors};

/// Free-space RPY (eta = 1) as f I + g r^ r^, written here from the closed forms.
fn rpy_fg(r: f64, a: f64) -> (f64, f64) {
    if r >= 2.0 * a {
        let c = 1.0 / (8.0 * PI * r);
        (
            c * (1.0 + 2.0 * a * a / (3.0 * r * r)),
            c * (1.0 - 2.0 * a * a / (r * r)),
        )
    } else {
        let c = 1.0 / (6.0 * PI * a);
        (c * (1.0 - 9.0 * r / (32.0 * a)), c * 3.0 * r / (32.0 * a))
    }
}

/// Hasimoto's splitting function.
fn split_h(k: f64, xi: f64) -> f64 {
    let q = k * k / (4.0 * xi * xi);
    (1.0 + q) * (-q).exp()
}

fn sinc(x: f64) -> f64 {
    if x.abs() < 1e-8 { 1.0 } else { x.sin() / x }
}

/// The near field (f, g) at r: RPY minus the free-space far part, the latter
/// 1/(2 pi^2) int dk sinc^2(ka) H(k) [(j0 - j1/x) I + j2 r^ r^] by Simpson's rule.
fn near(r: f64, a: f64, xi: f64) -> (f64, f64) {
    let k_max = 2.0 * xi * 40f64.sqrt();
    let steps = 4000;
    let dk = k_max / steps as f64;
    let (mut fi, mut gi) = (0.0, 0.0);
    for s in 0..=steps {
        let k = s as f64 * dk;
        let w = if s == 0 || s == steps {
            1.0
        } else if s % 2 == 1 {
            4.0
        } else {
            2.0
        };
        let x = k * r;
        let (iso, rr) = if x < 1e-3 {
            (2.0 / 3.0 - 2.0 * x * x / 15.0, x * x / 15.0)
        } else {
            let (sn, cs) = x.sin_cos();
            let j0 = sn / x;
            let j1 = sn / (x * x) - cs / x;
            let j2 = (3.0 / (x * x) - 1.0) * sn / x - 3.0 * cs / (x * x);
            (j0 - j1 / x, j2)
        };
        let s2 = sinc(k * a).powi(2) * split_h(k, xi) * w * dk / 3.0 / (2.0 * PI * PI);
        fi += s2 * iso;
        gi += s2 * rr;
    }
    let (f, g) = rpy_fg(r, a);
    (f - fi, g - gi)
}

fn tensor(f: f64, g: f64, r: [f64; 3]) -> M3 {
    let d2: f64 = r.iter().map(|x| x * x).sum();
    let mut m = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] =
                if i == j { f } else { 0.0 } + if d2 > 0.0 { g * r[i] * r[j] / d2 } else { 0.0 };
        }
    }
    m
}

/// The periodic RPY pair mobility (eta = 1) at separation r in a cubic box of side l, by
/// Ewald summation with splitting parameter xi: near field over the lattice images
/// within 7 / xi, far field over the wave vectors up to where H < 1e-16.
fn ewald_rpy(r: [f64; 3], l: f64, a: f64, xi: f64) -> M3 {
    let mut m = [[0.0; 3]; 3];
    let reach = 7.0 / xi;
    let images = (reach / l).ceil() as i64 + 1;
    for nx in -images..=images {
        for ny in -images..=images {
            for nz in -images..=images {
                let d = [
                    r[0] + nx as f64 * l,
                    r[1] + ny as f64 * l,
                    r[2] + nz as f64 * l,
                ];
                let dist = d.iter().map(|x| x * x).sum::<f64>().sqrt();
                if dist > reach {
                    continue;
                }
                let (f, g) = near(dist, a, xi);
                let t = tensor(f, g, d);
                for i in 0..3 {
                    for j in 0..3 {
                        m[i][j] += t[i][j];
                    }
                }
            }
        }
    }
    let k_max = 2.0 * xi * 40f64.sqrt();
    let dk = 2.0 * PI / l;
    let kn = (k_max / dk).ceil() as i64;
    let volume = l * l * l;
    for kx in -kn..=kn {
        for ky in -kn..=kn {
            for kz in -kn..=kn {
                if kx == 0 && ky == 0 && kz == 0 {
                    continue;
                }
                let k = [kx as f64 * dk, ky as f64 * dk, kz as f64 * dk];
                let k2: f64 = k.iter().map(|x| x * x).sum();
                if k2 > k_max * k_max {
                    continue;
                }
                let kk = k2.sqrt();
                let phase = (k[0] * r[0] + k[1] * r[1] + k[2] * r[2]).cos();
                let c = phase * sinc(kk * a).powi(2) * split_h(kk, xi) / (k2 * volume);
                for i in 0..3 {
                    for j in 0..3 {
                        let p = if i == j { 1.0 } else { 0.0 } - k[i] * k[j] / k2;
                        m[i][j] += c * p;
                    }
                }
            }
        }
    }
    m
}

#[test]
fn ewald_reference_gives_hasimoto_at_any_split() {
    // The reference itself: its self-mobility is Hasimoto's (whose expansion in a / L
    // stops at x^6, with a coefficient given to 6 digits: 1e-5 is its own accuracy
    // here), and any two splits agree to the quadrature's accuracy.
    let want = hasimoto(1.0, 16.0) / (6.0 * PI);
    let r = [1.3, -0.4, 2.2];
    let (a, b) = (ewald_rpy(r, 16.0, 1.0, 0.5), ewald_rpy(r, 16.0, 1.0, 1.0));
    for xi in [0.5, 1.0] {
        let m = ewald_rpy([0.0; 3], 16.0, 1.0, xi);
        for (i, row) in m.iter().enumerate() {
            assert!(
                (row[i] / want - 1.0).abs() < 1e-5,
                "xi {xi}: {} against {want}",
                row[i]
            );
        }
    }
    for i in 0..3 {
        for j in 0..3 {
            assert!((a[i][j] - b[i][j]).abs() < 1e-9 * want, "pair {i}{j}");
        }
    }
}

#[test]
fn self_mobility_is_hasimoto_whatever_the_split() {
    let Some(gpu) = gpu() else { return };
    let (l, tol) = (16.0, 1e-3);
    let want = hasimoto(1.0, l) / (6.0 * PI);
    let mut rng = Rng::new(5);
    let spots = random_positions(&mut rng, 4, [l; 3]);
    for xi in ["0.4", "0.6", "1.0", "1.6"] {
        let g = load_with(
            "pse.json",
            &[
                ("box", "[16, 16, 16]"),
                ("split", xi),
                ("tolerance", "1e-3"),
            ],
            1,
            0,
        );
        let plan = mobility_plan(&gpu, &g, 1, false, &["velocities"]);
        let mut program = compile_cached(&gpu, &g, &plan);
        let mut worst: f64 = 0.0;
        for x in &spots {
            for a in 0..3 {
                let mut f = [[0.0; 3]];
                f[0][a] = 1.0;
                let v = eval(&mut program, &[*x], &f, None)["velocities"][0];
                worst = worst.max((v[a] / want - 1.0).abs());
                // No coupling between axes for a single sphere.
                for (b, vb) in v.iter().enumerate() {
                    if b != a {
                        assert!(vb.abs() < tol * want, "xi {xi}: cross term {vb}");
                    }
                }
            }
        }
        eprintln!("split {xi}: worst self-mobility error {worst:.2e}");
        assert!(worst < tol, "split {xi}: self-mobility error {worst:e}");
    }
}

#[test]
fn pair_mobility_matches_the_ewald_sum_overlapping_or_not() {
    let Some(gpu) = gpu() else { return };
    let (l, tol) = (16.0, 1e-3);
    let m_self = hasimoto(1.0, l) / (6.0 * PI);
    let mut rng = Rng::new(9);
    // Overlapping (0.5 a, 1.3 a), at contact, and apart; random directions.
    let separations = [0.5, 1.3, 2.0, 3.1, 5.5, 7.9];
    let pairs: Vec<([f64; 3], [f64; 3])> = separations
        .iter()
        .map(|&d| {
            let u = [0, 1, 2].map(|_| rng.uniform(-1.0, 1.0));
            let nu = u.iter().map(|x| x * x).sum::<f64>().sqrt();
            let x0 = [0, 1, 2].map(|_| rng.uniform(-0.5, 0.5) * l);
            (x0, [0, 1, 2].map(|c| x0[c] + d * u[c] / nu))
        })
        .collect();
    let references: Vec<M3> = pairs
        .iter()
        .map(|(x0, x1)| ewald_rpy([0, 1, 2].map(|c| x1[c] - x0[c]), l, 1.0, 0.8))
        .collect();
    for xi in ["0.45", "1.2"] {
        let g = load_with(
            "pse.json",
            &[
                ("box", "[16, 16, 16]"),
                ("split", xi),
                ("tolerance", "1e-3"),
            ],
            1,
            0,
        );
        let plan = mobility_plan(&gpu, &g, 2, false, &["velocities"]);
        let mut program = compile_cached(&gpu, &g, &plan);
        let mut worst: f64 = 0.0;
        for ((x0, x1), want) in pairs.iter().zip(&references) {
            for b in 0..3 {
                let mut f = [[0.0; 3]; 2];
                f[0][b] = 1.0;
                let v = &eval(&mut program, &[*x0, *x1], &f, None)["velocities"];
                for a in 0..3 {
                    // Particle 1 moves by M(x1 - x0) F.
                    worst = worst.max((v[1][a] - want[a][b]).abs() / m_self);
                }
            }
        }
        eprintln!("split {xi}: worst pair-mobility error / self {worst:.2e}");
        assert!(worst < tol, "split {xi}: pair error {worst:e}");
    }
}

/// A number or the first of the numbers of a loaded graph's param.
fn param_number(g: &mesoflow::graph::Graph, name: &str) -> f64 {
    match g.params.iter().find(|p| p.name == name).map(|p| &p.value) {
        Some(mesoflow::expr::ParamValue::Number(x)) => *x,
        Some(mesoflow::expr::ParamValue::Numbers(v)) => v[0],
        other => panic!("param {name}: {other:?}"),
    }
}

/// The worst self and pair errors of M F, relative to the periodic self-mobility, over the
/// placements where the discretisation's error peaks: on a far-field grid point, at a far
/// cell's corner, its faces and edges (the window's aliasing and truncation peak where a
/// particle sits on a grid point or midway, per axis), at a corner of the near field's
/// cell list; pairs from overlapping to just past the near cutoff. Every tolerance from
/// 1e-2 to 1e-6, boxes of side 12 and 16 at the default split and one larger split. The
/// Lindbo-Tornberg window (the rule before) gave 4.4e-4 at 1e-4 (L = 16).
#[test]
fn mobility_is_within_the_tolerance_at_the_worst_placements() {
    let Some(gpu) = gpu() else { return };
    let mut cases: Vec<(f64, f64, Option<&str>)> = Vec::new();
    for tol in [1e-2, 3e-3, 1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 1e-6] {
        cases.push((16.0, tol, None));
        cases.push((12.0, tol, None));
    }
    for tol in [1e-2, 1e-4, 1e-6] {
        cases.push((16.0, tol, Some("1.3")));
    }
    let mut failures = Vec::new();
    for (l, tol, split) in cases {
        let edge = format!("[{l}, {l}, {l}]");
        let tol_text = tol.to_string();
        let mut sets = vec![("box", edge.as_str()), ("tolerance", tol_text.as_str())];
        if let Some(s) = split {
            sets.push(("split", s));
        }
        let g = load_with("pse.json", &sets, 1, 0);
        let h = l / param_number(&g, "grid");
        let cell = l / param_number(&g, "cells");
        let cutoff = param_number(&g, "cutoff");
        // The reference splits elsewhere than any case.
        let reference = |r: [f64; 3]| ewald_rpy(r, l, 1.0, 0.83);
        let m_self = reference([0.0; 3])[0][0];
        let grid_point = -0.5 * l + 2.5 * h;
        let mut placements: Vec<[f64; 3]> = [
            [0.0, 0.0, 0.0],
            [0.5, 0.5, 0.5],
            [0.5, 0.0, 0.0],
            [0.5, 0.5, 0.0],
        ]
        .iter()
        .map(|o| o.map(|c| grid_point + c * h))
        .collect();
        placements.push([-0.5 * l + cell, -0.5 * l + cell, 0.5 * l - cell]);
        let mut worst_self: f64 = 0.0;
        {
            let plan = mobility_plan(&gpu, &g, 1, false, &["velocities"]);
            let mut program = compile_cached(&gpu, &g, &plan);
            for x in &placements {
                for axis in [0, 2] {
                    let mut f = [[0.0; 3]];
                    f[0][axis] = 1.0;
                    let v = eval(&mut program, &[*x], &f, None)["velocities"][0];
                    for (b, vb) in v.iter().enumerate() {
                        let want = if b == axis { m_self } else { 0.0 };
                        worst_self = worst_self.max((vb - want).abs() / m_self);
                    }
                }
            }
        }
        let mut worst_pair: f64 = 0.0;
        {
            let plan = mobility_plan(&gpu, &g, 2, false, &["velocities"]);
            let mut program = compile_cached(&gpu, &g, &plan);
            let direction = [0.48, 0.6, 0.64];
            let x0 = [grid_point + 0.5 * h; 3];
            for r in [0.6, 1.7, 2.0, 3.3, cutoff - 0.05, cutoff + 0.05] {
                let x1 = [0, 1, 2].map(|c| x0[c] + r * direction[c]);
                let want = reference([0, 1, 2].map(|c| x1[c] - x0[c]));
                for axis in [0, 2] {
                    let mut f = [[0.0; 3]; 2];
                    f[0][axis] = 1.0;
                    let v = &eval(&mut program, &[x0, x1], &f, None)["velocities"];
                    for b in 0..3 {
                        worst_pair = worst_pair.max((v[1][b] - want[b][axis]).abs() / m_self);
                    }
                }
            }
        }
        eprintln!(
            "L {l} tolerance {tol:e} split {}: grid {}, support {}, cutoff {cutoff:.3}: worst self {worst_self:.2e}, pair {worst_pair:.2e}",
            split.unwrap_or("default"),
            param_number(&g, "grid"),
            param_number(&g, "support"),
        );
        if worst_self.max(worst_pair) > tol {
            failures.push(format!(
                "L {l}, tolerance {tol:e}, split {}: self {worst_self:.2e}, pair {worst_pair:.2e}",
                split.unwrap_or("default")
            ));
        }
    }
    assert!(failures.is_empty(), "beyond the tolerance: {failures:#?}");
}

#[test]
fn mobility_matrix_is_symmetric_and_positive_definite() {
    let Some(gpu) = gpu() else { return };
    let mut rng = Rng::new(21);
    let mut x = random_positions(&mut rng, 4, [12.0; 3]);
    // An overlapping pair and a coincident one.
    x[1] = [x[0][0] + 0.7, x[0][1], x[0][2] - 0.4];
    x[3] = x[2];
    let g = load_with(
        "pse.json",
        &[("box", "[12, 12, 12]"), ("tolerance", "1e-3")],
        1,
        0,
    );
    let plan = mobility_plan(&gpu, &g, 4, false, &["velocities"]);
    let mut program = compile_cached(&gpu, &g, &plan);
    let n = x.len();
    let mut m = vec![vec![0.0; 3 * n]; 3 * n];
    for j in 0..n {
        for b in 0..3 {
            let mut f = vec![[0.0; 3]; n];
            f[j][b] = 1.0;
            let v = &eval(&mut program, &x, &f, None)["velocities"];
            for i in 0..n {
                for a in 0..3 {
                    m[3 * i + a][3 * j + b] = v[i][a];
                }
            }
        }
    }
    let scale = m[0][0];
    let mut asym: f64 = 0.0;
    for (i, row) in m.iter().enumerate() {
        for (j, v) in row.iter().enumerate() {
            asym = asym.max((v - m[j][i]).abs() / scale);
        }
    }
    assert!(asym < 1e-4, "asymmetry {asym:e}");
    // Coincident spheres have a singular mobility (they move as one): symmetrise and
    // check positive semi-definiteness with the pair merged, then the rest strictly.
    let keep: Vec<usize> = (0..3 * n).filter(|&i| i < 9).collect();
    let sub: Vec<Vec<f64>> = keep
        .iter()
        .map(|&i| keep.iter().map(|&j| 0.5 * (m[i][j] + m[j][i])).collect())
        .collect();
    let pivot = cholesky_min_pivot(&sub).expect("positive definite");
    assert!(pivot > 1e-3 * scale, "smallest pivot {pivot}");
}

/// Covariance of the noise over many steps against the mobility: for two overlapping
/// particles the near field's Lanczos square root and the far field's Fourier noise
/// together give M.
#[test]
fn noise_covariance_is_the_mobility() {
    let Some(gpu) = gpu() else { return };
    let x = vec![[0.3, -1.1, 2.0], [1.4, -0.6, 2.5]];
    let sets = r#"{"box": [10, 10, 10], "tolerance": 0.001}"#;
    let g = load_with("pse.json", &[("box", "[10, 10, 10]")], 1, 0);
    let plan = mobility_plan(&gpu, &g, 2, false, &["velocities"]);
    let mut program = compile_cached(&gpu, &g, &plan);
    let m = axis_mobilities(&mut program, &x);
    drop(program);
    let steps = 4000u64;
    let (sq, pair) = noise_statistics(&gpu, "pse.json", sets, &x, steps, 17);
    let s = steps as f64;
    // A variance from s normal samples has relative standard deviation sqrt(2 / s)
    // (2.2 % here); 5 of them is the bound.
    let bound = 5.0 * (2.0 / s).sqrt();
    for a in 0..3 {
        for i in 0..2 {
            let ratio = sq[i][a] / s / m[i][i][a];
            eprintln!("particle {i} axis {a}: variance / M = {ratio}");
            assert!(
                (ratio - 1.0).abs() <= bound,
                "particle {i} axis {a}: {ratio}"
            );
        }
        let want = m[0][0][a] + m[1][1][a] + m[0][1][a] + m[1][0][a];
        let ratio = pair[a] / s / want;
        eprintln!("axis {a}: variance of the sum / M = {ratio}");
        assert!((ratio - 1.0).abs() <= bound, "axis {a}: {ratio}");
    }
}

/// The near field's W is drawn per particle in input order and gathered into the cell
/// list's order, which is not fixed (bin_sort ranks by atomics): a cell list of other
/// cells, which orders the particles differently, gives each particle the same draw,
/// so the same noise up to the Lanczos tolerance and rounding; another seed other noise.
#[test]
fn noise_follows_the_particles_not_the_cell_order() {
    let Some(gpu) = gpu() else { return };
    let (l, n) = (16.0, 150usize);
    let mut rng = Rng::new(23);
    let x = random_positions(&mut rng, n, [l; 3]);
    let f = vec![[0.0; 3]; n];
    let run = |cells: &str, seed: u64| {
        let mut sets = vec![("box", "[16, 16, 16]"), ("lanczos_tolerance", "1e-5")];
        if !cells.is_empty() {
            sets.push(("cells", cells));
        }
        let g = load_with("pse.json", &sets, 1, seed);
        let plan = mobility_plan(&gpu, &g, n as u32, false, &["noise"]);
        let mut program = compile_cached(&gpu, &g, &plan);
        eval(&mut program, &x, &f, None)["noise"].clone()
    };
    // The default cells (2 per axis here: the cutoff is about 5.8) and one cell.
    let (a, b, c) = (run("", 3), run("[1, 1, 1]", 3), run("", 4));
    let biggest = a.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(biggest > 0.0);
    let worst = a
        .iter()
        .flatten()
        .zip(b.iter().flatten())
        .fold(0.0f64, |m, (p, q)| m.max((p - q).abs()));
    eprintln!(
        "noise with other cells: largest difference {:.2e} of {biggest:.2e}",
        worst
    );
    assert!(
        worst <= 1e-3 * biggest,
        "the noise depends on the cell order: {worst:e} of {biggest:e}"
    );
    let differs = (0..n).filter(|&i| a[i] != c[i]).count();
    assert_eq!(differs, n, "seed 4 repeated seed 3's noise");
}

#[test]
fn open_boundary_rpy_matches_the_closed_form() {
    let Some(gpu) = gpu() else { return };
    let mut rng = Rng::new(2);
    let mut x = random_positions(&mut rng, 40, [10.0; 3]);
    x[1] = [x[0][0] + 0.9, x[0][1], x[0][2]];
    let f: Vec<[f64; 3]> = (0..x.len())
        .map(|_| [0, 1, 2].map(|_| rng.uniform(-1.0, 1.0)))
        .collect();
    let g = load_with(
        "rpy_open.json",
        &[("radius", "0.8"), ("viscosity", "2.0")],
        1,
        0,
    );
    let plan = mobility_plan(&gpu, &g, x.len() as u32, false, &["velocities"]);
    let mut program = compile_cached(&gpu, &g, &plan);
    let v = &eval(&mut program, &x, &f, None)["velocities"];
    let x32 = vectors(&particles(&x));
    let f32_ = vectors(&particles(&f));
    let mut worst: f64 = 0.0;
    let mut scale: f64 = 0.0;
    for i in 0..x.len() {
        let mut want = [0.0; 3];
        for j in 0..x.len() {
            let r = [0, 1, 2].map(|c| x32[i][c] - x32[j][c]);
            let d = r.iter().map(|q| q * q).sum::<f64>().sqrt();
            let (ff, gg) = rpy_fg(d, 0.8);
            let t = tensor(ff / 2.0, gg / 2.0, r);
            for a in 0..3 {
                want[a] += (0..3).map(|b| t[a][b] * f32_[j][b]).sum::<f64>();
            }
        }
        for a in 0..3 {
            worst = worst.max((v[i][a] - want[a]).abs());
            scale = scale.max(want[a].abs());
        }
    }
    assert!(worst < 1e-5 * scale, "rpy_open error {:e}", worst / scale);
}

/// rpy_open.json's Lanczos noise has the covariance of the closed-form RPY tensor, for an
/// overlapping pair (the overlap form) along the line of centres and across it.
#[test]
fn open_boundary_noise_covariance_is_the_rpy_tensor() {
    let Some(gpu) = gpu() else { return };
    let a = 1.0;
    let x = vec![[0.0, 0.0, 0.0], [1.5, 0.0, 0.0]];
    let steps = 3000u64;
    let (sq, pair) = noise_statistics(
        &gpu,
        "rpy_open.json",
        r#"{"radius": 1.0, "tolerance": 1e-3}"#,
        &x,
        steps,
        23,
    );
    let (f, g) = rpy_fg(1.5, a);
    let self_m = 1.0 / (6.0 * PI * a);
    // Along x (the line of centres) the pair couples by f + g, across it by f.
    let coupling = [f + g, f, f];
    let s = steps as f64;
    // A variance from s normal samples has relative standard deviation sqrt(2 / s)
    // (2.6 % here); 5 of them is the bound.
    let bound = 5.0 * (2.0 / s).sqrt();
    for ax in 0..3 {
        for (i, row) in sq.iter().enumerate() {
            let ratio = row[ax] / s / self_m;
            assert!(
                (ratio - 1.0).abs() <= bound,
                "particle {i} axis {ax}: {ratio}"
            );
        }
        let ratio = pair[ax] / s / (2.0 * self_m + 2.0 * coupling[ax]);
        assert!(
            (ratio - 1.0).abs() <= bound,
            "axis {ax}: variance of the sum / M = {ratio}"
        );
    }
}

#[test]
fn bad_settings_get_clear_errors() {
    // A split so small that the near field reaches past half the box.
    let e = load_error("pse.json", &[("box", "[8, 8, 8]"), ("split", "0.3")]);
    assert!(e.contains("exceeds half the periodic box"), "{e}");
    // A split so large that the far grid explodes.
    let e = load_error("pse.json", &[("box", "[64, 64, 64]"), ("split", "200")]);
    assert!(e.contains("lower the split"), "{e}");
}
