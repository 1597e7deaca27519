//! graphs/dpstokes.json, the doubly periodic Stokes mobility, against the physics: the
//! open-space self-mobility of FCM's Gaussian far from everything, the Rotne-Prager-Blake
//! (Swan and Brady 2007) self-mobilities above a wall, symmetry about a slit's mid-plane,
//! periodic copies, the symmetric positive definite mobility matrix, and the errors that
//! name a particle out of its domain.

use std::collections::BTreeMap;
use std::f64::consts::PI;

use mesoflow::graph::Graph;
use mesoflow::value::HostArray;

use crate::util::{compile_cached, gpu, load_with, plan_graph, run_program, types_of};

type V3 = [f64; 3];

fn particles(v: &[V3]) -> HostArray {
    crate::util::flat_particles(&v.iter().flatten().copied().collect::<Vec<_>>(), 3)
}

fn load(sets: &[(&str, String)]) -> Graph {
    let sets: Vec<(&str, &str)> = sets.iter().map(|(k, v)| (*k, v.as_str())).collect();
    load_with("dpstokes.json", &sets, 1, 0)
}

/// The mobility matrix (3N x 3N) of `g` at positions `x`, column by column.
fn mobility(g: &Graph, x: &[V3]) -> Vec<Vec<f64>> {
    let gpu = gpu().expect("a GPU");
    let n = x.len();
    let mut data: BTreeMap<String, HostArray> = BTreeMap::new();
    data.insert("positions".into(), particles(x));
    data.insert("forces".into(), particles(&vec![[0.0; 3]; n]));
    let plan = plan_graph(&gpu.caps, g, types_of(&data), Some(&["velocities"]), true);
    let mut program = compile_cached(&gpu, g, &plan);
    let mut m = vec![vec![0.0; 3 * n]; 3 * n];
    for col in 0..3 * n {
        let mut f = vec![[0.0; 3]; n];
        f[col / 3][col % 3] = 1.0;
        data.insert("forces".into(), particles(&f));
        let out = run_program(&mut program, &data, 1);
        let u = out["velocities"].data.to_f64();
        for (row, v) in u.iter().enumerate() {
            m[row][col] = *v;
        }
    }
    m
}

/// The self-mobility (xx and zz, eta = 1) of FCM's Gaussian (standard deviation sigma) in
/// a fluid periodic in x, y (lengths lx, ly) and unbounded in z, with the in-plane k = 0
/// mode left out (dpstokes.json's open mode): (1 / (lx ly)) sum over k_par != 0 of
/// int dkz / (2 pi) e^{-sigma^2 k^2} (1 - k_a^2 / k^2) / k^2, in f64 (the kz integral by
/// the trapezoid rule on a fine grid; the sum until the Gaussian is below 1e-16).
fn open_doubly_periodic_self(sigma: f64, lx: f64, ly: f64) -> (f64, f64) {
    let kmax = (37.0f64).sqrt() / sigma;
    let (nx, ny) = (
        (kmax * lx / (2.0 * PI)).ceil() as i64,
        (kmax * ly / (2.0 * PI)).ceil() as i64,
    );
    let nz = 4000;
    let dkz = kmax / nz as f64;
    let (mut xx, mut zz) = (0.0, 0.0);
    for i in -nx..=nx {
        for j in -ny..=ny {
            if i == 0 && j == 0 {
                continue;
            }
            let (kx, ky) = (2.0 * PI * i as f64 / lx, 2.0 * PI * j as f64 / ly);
            let q2 = kx * kx + ky * ky;
            if q2 > kmax * kmax {
                continue;
            }
            for m in 0..=nz {
                let kz = m as f64 * dkz;
                let k2 = q2 + kz * kz;
                let w = if m == 0 { 0.5 } else { 1.0 } * 2.0 * dkz / (2.0 * PI);
                let g = (-sigma * sigma * k2).exp() / k2 * w;
                xx += g * (1.0 - kx * kx / k2);
                zz += g * (1.0 - kz * kz / k2);
            }
        }
    }
    (xx / (lx * ly), zz / (lx * ly))
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
fn pulled(program_graph: &Graph, x: V3, f: V3) -> V3 {
    let gpu = gpu().expect("a GPU");
    let mut data: BTreeMap<String, HostArray> = BTreeMap::new();
    data.insert("positions".into(), particles(&[x]));
    data.insert("forces".into(), particles(&[f]));
    let plan = plan_graph(
        &gpu.caps,
        program_graph,
        types_of(&data),
        Some(&["velocities"]),
        true,
    );
    let mut program = compile_cached(&gpu, program_graph, &plan);
    let u = run_program(&mut program, &data, 1)["velocities"]
        .data
        .to_f64();
    [u[0], u[1], u[2]]
}

/// Open z: the self-mobility matches the doubly periodic sum of the Gaussian's Green
/// function (an independent f64 computation), at any height and off-grid placement, and a
/// particle pulled along x moves only along x.
#[test]
fn the_open_mode_matches_the_doubly_periodic_sum() {
    if gpu().is_none() {
        return;
    }
    let (a, l) = (1.0, 16.0);
    let sigma = a / PI.sqrt();
    let (xx, zz) = open_doubly_periodic_self(sigma, l, l);
    let g = load(&[
        ("box", format!("[{l}, {l}]")),
        ("zmin", "-3.0".into()),
        ("zmax", "3.0".into()),
        ("walls", "\"none\"".into()),
    ]);
    for x in [[0.3, -0.2, 0.0], [5.1, 7.9, -2.6], [-8.0, 0.0, 2.99]] {
        let u = pulled(&g, x, [1.0, 0.0, 0.0]);
        assert!(
            (u[0] - xx).abs() < 2e-3 * xx,
            "at {x:?}: xx {} against {xx}",
            u[0]
        );
        assert!(
            u[1].abs().max(u[2].abs()) < 1e-6 * u[0],
            "at {x:?}: off-axis {u:?}"
        );
        let w = pulled(&g, x, [0.0, 0.0, 1.0]);
        assert!(
            (w[2] - zz).abs() < 2e-3 * zz,
            "at {x:?}: zz {} against {zz}",
            w[2]
        );
    }
}

/// Above a bottom wall in a wide box, the self-mobilities approach Rotne-Prager-Blake's
/// closed forms from 1.5 a to 10 a (FCM's Gaussian is not RPB's sphere: a percent near
/// the wall).
#[test]
fn bottom_wall_self_mobilities_approach_rotne_prager_blake() {
    if gpu().is_none() {
        return;
    }
    let a = 1.0;
    let t0 = 1.0 / (6.0 * PI * a);
    let g = load(&[
        ("box", "[128.0, 128.0]".into()),
        ("zmin", "0.0".into()),
        ("zmax", "10.0".into()),
        ("walls", "\"bottom\"".into()),
    ]);
    for h in [1.5, 2.0, 4.0, 10.0] {
        let (par, perp) = blake_self(a, h);
        let u = pulled(&g, [0.3, -0.2, h], [1.0, 0.0, 0.0]);
        let w = pulled(&g, [0.3, -0.2, h], [0.0, 0.0, 1.0]);
        eprintln!(
            "h {h}: par {:.5} ({par:.5}) perp {:.5} ({perp:.5})",
            u[0] / t0,
            w[2] / t0
        );
        assert!(
            (u[0] / t0 - par).abs() < 0.02 * par,
            "h {h}: parallel {} against {par}",
            u[0] / t0
        );
        assert!(
            (w[2] / t0 - perp).abs() < 0.02 * perp,
            "h {h}: perpendicular {} against {perp}",
            w[2] / t0
        );
        assert!(
            u[1].abs().max(u[2].abs()) < 1e-6 * u[0],
            "h {h}: off-axis {u:?}"
        );
    }
}
