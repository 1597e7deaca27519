//! The mobility graphs (graphs/fcm.json, pse.json, rpy_open.json): their plans, one-step
//! evaluation, the mobility axis by axis and noise statistics; Hasimoto's periodic
//! self-mobility and the periodic FCM mobility by an f64 Fourier sum, written here
//! independently of the engine; positions and the linear algebra the checks need.

use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

use mesoflow::exec::Program;
use mesoflow::gpu::GpuContext;
use mesoflow::graph::Graph;
use mesoflow::plan::Plan;
use mesoflow::value::{HostArray, ValueType};

use super::{
    Rng, compile_cached, load_for, particles, plan_graph, random_points, run_program, tmpdir,
    vectors, write_graph,
};

/// A 3x3 matrix, row-major.
pub type M3 = [[f64; 3]; 3];

/// The plan of a mobility graph for `n` particles (with torques or not) and these
/// outputs.
pub fn mobility_plan(gpu: &GpuContext, g: &Graph, n: u32, torques: bool, outputs: &[&str]) -> Plan {
    let p3 = ValueType::Particles { n, k: 3 };
    let mut inputs: BTreeMap<String, ValueType> =
        [("positions".to_string(), p3), ("forces".to_string(), p3)]
            .into_iter()
            .collect();
    if torques {
        inputs.insert("torques".into(), p3);
    }
    plan_graph(&gpu.caps, g, inputs, Some(outputs), true)
}

/// Outputs of a compiled mobility graph for these inputs, one evaluation.
pub fn eval(
    program: &mut Program,
    positions: &[[f64; 3]],
    forces: &[[f64; 3]],
    torques: Option<&[[f64; 3]]>,
) -> BTreeMap<String, Vec<[f64; 3]>> {
    let mut data: BTreeMap<String, HostArray> = [
        ("positions".to_string(), particles(positions)),
        ("forces".to_string(), particles(forces)),
    ]
    .into_iter()
    .collect();
    if let Some(t) = torques {
        data.insert("torques".into(), particles(t));
    }
    run_program(program, &data, 1)
        .into_iter()
        .map(|(k, v)| (k, vectors(&v)))
        .collect()
}

/// The mobility of two particles at `x` axis by axis, one unit force at a time:
/// `m[i][j][a]` is particle i's velocity along a per unit force on particle j along a.
pub fn axis_mobilities(program: &mut Program, x: &[[f64; 3]]) -> [[[f64; 3]; 2]; 2] {
    let mut m = [[[0.0; 3]; 2]; 2];
    for j in 0..2 {
        for a in 0..3 {
            let mut f = vec![[0.0; 3]; 2];
            f[j][a] = 1.0;
            let v = &eval(program, x, &f, None)["velocities"];
            for i in 0..2 {
                m[i][j][a] = v[i][a];
            }
        }
    }
    m
}

/// Random positions in the box (centred at the origin).
pub fn random_positions(rng: &mut Rng, n: usize, l: [f64; 3]) -> Vec<[f64; 3]> {
    random_points(rng, n, &l)
        .chunks(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect()
}

/// Hasimoto's periodic self-mobility of a sphere, times 6 pi eta a (cubic box of side L):
/// 1 - 2.837297 x + (4 pi / 3) x^3 - 27.4 x^6, x = a / L (thesis Eq. 21.18), written here
/// from the paper's coefficients.
pub fn hasimoto(a: f64, l: f64) -> f64 {
    let x = a / l;
    1.0 - 2.837_297_479 * x + 4.0 * PI / 3.0 * x.powi(3) - 27.3594 * x.powi(6)
}

fn matmul(a: &M3, b: &M3) -> M3 {
    let mut c = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    c
}

/// The periodic FCM mobility with Gaussian windows in f64, by a direct Fourier sum:
/// the 6x6 block [[tt, tr], [rt, rr]] coupling (force, torque) on particle j to (velocity,
/// angular velocity) of particle i, r = x_i - x_j:
///   M(r) = (1/V) sum_{k != 0} e^{i k.r} D(k) G(k),  G = (I - k k^T / k^2) / (eta k^2),
/// with the forcing (1/2) i k x for torques and the vorticity (1/2) i k x for rotation,
/// each window contributing its Gaussian exp(-sigma^2 k^2 / 2).
pub fn fourier_mobility(
    r: [f64; 3],
    l: [f64; 3],
    eta: f64,
    sigma: f64,
    sigma_t: f64,
) -> [[f64; 6]; 6] {
    let smin = sigma.min(sigma_t);
    // exp(-smin^2 k^2) < 1e-15 beyond.
    let kcut = 5.9 / smin;
    let nmax = l.map(|la| (kcut * la / (2.0 * PI)).ceil() as i64);
    let mut m = [[0.0; 6]; 6];
    for nx in -nmax[0]..=nmax[0] {
        for ny in -nmax[1]..=nmax[1] {
            for nz in -nmax[2]..=nmax[2] {
                if nx == 0 && ny == 0 && nz == 0 {
                    continue;
                }
                let k = [
                    2.0 * PI * nx as f64 / l[0],
                    2.0 * PI * ny as f64 / l[1],
                    2.0 * PI * nz as f64 / l[2],
                ];
                let k2 = k[0] * k[0] + k[1] * k[1] + k[2] * k[2];
                if k2 > kcut * kcut {
                    continue;
                }
                let mut g = [[0.0; 3]; 3];
                for i in 0..3 {
                    for j in 0..3 {
                        let d = if i == j { 1.0 } else { 0.0 };
                        g[i][j] = (d - k[i] * k[j] / k2) / (eta * k2);
                    }
                }
                // K t = k x t.
                let kx = [[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]];
                let phase = k[0] * r[0] + k[1] * r[1] + k[2] * r[2];
                let (s, c) = phase.sin_cos();
                let e_tt = (-sigma * sigma * k2).exp();
                let e_tr = (-0.5 * (sigma * sigma + sigma_t * sigma_t) * k2).exp();
                let e_rr = (-sigma_t * sigma_t * k2).exp();
                let gk = matmul(&g, &kx);
                let kg = matmul(&kx, &g);
                let kgk = matmul(&kx, &gk);
                for i in 0..3 {
                    for j in 0..3 {
                        // Re(e^{ikr} X): c X for real X, -s Y for X = i Y.
                        m[i][j] += c * g[i][j] * e_tt;
                        m[i][3 + j] += -s * 0.5 * gk[i][j] * e_tr;
                        m[3 + i][j] += -s * 0.5 * kg[i][j] * e_tr;
                        m[3 + i][3 + j] += -c * 0.25 * kgk[i][j] * e_rr;
                    }
                }
            }
        }
    }
    let v = l[0] * l[1] * l[2];
    for row in &mut m {
        for x in row.iter_mut() {
            *x /= v;
        }
    }
    m
}

/// Cholesky in f64: the smallest pivot, or `None` when the matrix is not positive
/// definite.
pub fn cholesky_min_pivot(m: &[Vec<f64>]) -> Option<f64> {
    let n = m.len();
    let mut l = vec![vec![0.0; n]; n];
    let mut min_pivot = f64::INFINITY;
    for i in 0..n {
        for j in 0..=i {
            let s: f64 = (0..j).map(|k| l[i][k] * l[j][k]).sum();
            if i == j {
                let d = m[i][i] - s;
                if d <= 0.0 {
                    return None;
                }
                min_pivot = min_pivot.min(d);
                l[i][j] = d.sqrt();
            } else {
                l[i][j] = (m[i][j] - s) / l[j][j];
            }
        }
    }
    Some(min_pivot)
}

/// A graph accumulating noise statistics over the steps of `graphs/<name>` (a mobility
/// graph with a `noise` output): per particle and axis the sum of squares, and the sum
/// over particles squared (the covariance between particles).
fn noise_statistics_graph(dir: &Path, name: &str, n: usize, sets: &str) -> PathBuf {
    // Found in the library (the shipped graphs/): the graph itself lies in a temporary folder.
    let mobility = Path::new(name);
    let json = format!(
        r#"{{"mesoflow": 1,
          "inputs": {{"positions": {{"type": "particles", "rows": {n}, "cols": 3}}}},
          "state": {{"sq": {{"init": "zero.out", "next": "sq_next.out"}},
                    "pair": {{"init": "zero_row.out", "next": "pair_next.out"}}}},
          "nodes": [
            {{"id": "zero", "kind": "constant", "params": {{"value": 0}}, "inputs": {{"like": "inputs.positions"}}}},
            {{"id": "zero_row", "kind": "constant", "params": {{"value": 0, "rows": 1, "cols": 3}}}},
            {{"id": "m", "graph": "{}", "params": {sets}, "inputs": {{"positions": "inputs.positions", "forces": "zero.out"}}}},
            {{"id": "sq", "kind": "multiply", "inputs": {{"a": "m.noise", "b": "m.noise"}}}},
            {{"id": "sq_next", "kind": "add", "inputs": {{"a": "state.sq", "b": "sq.out"}}}},
            {{"id": "sum", "kind": "column_reduce", "params": {{"op": "sum"}}, "inputs": {{"x": "m.noise"}}}},
            {{"id": "sum_sq", "kind": "multiply", "inputs": {{"a": "sum.out", "b": "sum.out"}}}},
            {{"id": "pair_next", "kind": "add", "inputs": {{"a": "state.pair", "b": "sum_sq.out"}}}}
          ],
          "outputs": {{"sq": "state.sq", "pair": "state.pair"}}}}"#,
        mobility.display()
    );
    write_graph(dir, "noise_stats.json", &json)
}

/// Over `steps` fresh draws of the noise of `graphs/<name>` (params `sets`, a JSON
/// object) at positions `x`: per particle and axis the sum of squares, and per axis the
/// sum of squares of the noise summed over the particles.
pub fn noise_statistics(
    gpu: &GpuContext,
    name: &str,
    sets: &str,
    x: &[[f64; 3]],
    steps: u64,
    seed: u64,
) -> (Vec<[f64; 3]>, [f64; 3]) {
    let dir = tmpdir(&format!("noise-{}", name.replace('.', "-")));
    let path = noise_statistics_graph(&dir, name, x.len(), sets);
    let g = load_for(&path, steps, seed);
    let positions = particles(x);
    let plan = plan_graph(
        &gpu.caps,
        &g,
        [("positions".to_string(), positions.ty)].into(),
        None,
        true,
    );
    let mut program = compile_cached(gpu, &g, &plan);
    let out = run_program(
        &mut program,
        &[("positions".to_string(), positions)].into(),
        steps,
    );
    let _ = std::fs::remove_dir_all(&dir);
    (vectors(&out["sq"]), vectors(&out["pair"])[0])
}
