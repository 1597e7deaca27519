//! graphs/fcm.json and graphs/bd_fcm.json against physics: Hasimoto's periodic
//! self-mobility, an f64 direct Fourier sum of the Gaussian-regularised Stokes Green
//! function (pairs, rotation, elongated boxes), symmetry and positive definiteness of the
//! assembled mobility, fluctuation-dissipation, translational invariance, hard cases.
//! The f64 references here are written independently of the engine.

use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::sync::{Mutex, OnceLock};

use mesoflow::exec::{Profile, Program, RunOptions};
use mesoflow::expr::ParamValue;
use mesoflow::gpu::{GpuContext, KernelCache};
use mesoflow::graph::{self, Graph, LoadOptions};
use mesoflow::plan::{Plan, PlanOptions};
use mesoflow::value::{HostArray, ValueType};

use crate::util::{Rng, gpu, registry, root};

/// One kernel cache for the module: the cases share their pipelines (lavapipe compiles
/// slowly), whatever the seed or the particle positions.
pub(crate) fn cache() -> std::sync::MutexGuard<'static, KernelCache> {
    static CACHE: OnceLock<Mutex<KernelCache>> = OnceLock::new();
    CACHE
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|p| p.into_inner())
}

/// `graphs/<name>` loaded with these `--set` values (JSON literals) and seed.
pub(crate) fn load_with(name: &str, sets: &[(&str, &str)], seed: u64) -> Graph {
    let overrides = sets
        .iter()
        .map(|(k, v)| {
            let json: serde_json::Value = serde_json::from_str(v).unwrap();
            (k.to_string(), ParamValue::from_json(&json).unwrap())
        })
        .collect();
    let opts = LoadOptions {
        overrides,
        steps: 1,
        seed,
    };
    graph::load(&root().join("graphs").join(name), registry(), &opts)
        .unwrap_or_else(|e| panic!("{e}"))
}

pub(crate) fn particles(rows: &[[f64; 3]]) -> HostArray {
    HostArray::f32(
        ValueType::Particles {
            n: rows.len() as u32,
            k: 3,
        },
        rows.iter().flatten().map(|&x| x as f32).collect(),
    )
}

pub(crate) fn rows(a: &HostArray) -> Vec<[f64; 3]> {
    a.data
        .to_f64()
        .chunks(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect()
}

/// The plan of fcm.json for `n` particles (with torques or not) and these outputs.
fn fcm_plan(gpu: &GpuContext, g: &Graph, n: u32, torques: bool, outputs: &[&str]) -> Plan {
    let p3 = ValueType::Particles { n, k: 3 };
    let mut inputs: BTreeMap<String, ValueType> =
        [("positions".to_string(), p3), ("forces".to_string(), p3)]
            .into_iter()
            .collect();
    if torques {
        inputs.insert("torques".into(), p3);
    }
    let opts = PlanOptions {
        outputs: Some(outputs.iter().map(|s| s.to_string()).collect()),
        inputs,
        fuse: true,
    };
    mesoflow::plan::plan(g, &opts, &gpu.caps).unwrap_or_else(|e| panic!("{e}"))
}

pub(crate) fn compile<'a>(gpu: &'a GpuContext, g: &'a Graph, plan: &'a Plan) -> Program<'a> {
    Program::compile(gpu, g, plan, &mut cache()).unwrap_or_else(|e| panic!("{e}"))
}

/// Outputs of a compiled fcm.json for these inputs, one evaluation.
pub(crate) fn eval(
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
    program.upload(&data).unwrap();
    program
        .run(&RunOptions {
            steps: 1,
            profile: Profile::Off,
            progress: false,
        })
        .unwrap_or_else(|e| panic!("{e}"));
    program
        .read_outputs()
        .unwrap()
        .into_iter()
        .map(|(k, v)| (k, rows(&v)))
        .collect()
}

/// Hasimoto's periodic self-mobility of a sphere, times 6 pi eta a (cubic box of side L):
/// 1 - 2.837297 x + (4 pi / 3) x^3 - 27.4 x^6, x = a / L (thesis Eq. 21.18), written here
/// from the paper's coefficients.
pub(crate) fn hasimoto(a: f64, l: f64) -> f64 {
    let x = a / l;
    1.0 - 2.837_297_479 * x + 4.0 * PI / 3.0 * x.powi(3) - 27.3594 * x.powi(6)
}

/// 3x3 matrix helpers (row-major).
type M3 = [[f64; 3]; 3];

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
fn fourier_mobility(r: [f64; 3], l: [f64; 3], eta: f64, sigma: f64, sigma_t: f64) -> [[f64; 6]; 6] {
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

/// Random positions in the box (centred at the origin).
fn random_positions(rng: &mut Rng, n: usize, l: [f64; 3]) -> Vec<[f64; 3]> {
    (0..n)
        .map(|_| [0, 1, 2].map(|a| rng.uniform(-0.5 * l[a], 0.5 * l[a])))
        .collect()
}

#[test]
fn fourier_sum_reference_matches_hasimoto_and_free_rotation() {
    // The reference itself. A Gaussian of width a / sqrt(pi) in a periodic cube has
    // Hasimoto's self-mobility up to the blob's own finite-size term, about
    // -0.14 (a/L)^3 (measured: -2.6e-4 at L = 8 a, -4.4e-5 at 16 a, -5.7e-6 at 32 a, in
    // units of 1 / (6 pi eta a)); the torque Gaussian has the free rotational mobility
    // 1 / (8 pi eta a^3) less the back-flow term (4 pi / 3) (a/L)^3.
    let a = 1.0;
    let sigma = a / PI.sqrt();
    let sigma_t = a / (6.0 * PI.sqrt()).cbrt();
    for (l, blob) in [(8.0, 3e-4), (16.0, 5e-5)] {
        let m = fourier_mobility([0.0; 3], [l; 3], 1.0, sigma, sigma_t);
        let tt = m[0][0] * 6.0 * PI * a;
        assert!(
            (tt - hasimoto(a, l)).abs() < blob,
            "L = {l}: {tt} vs {}",
            hasimoto(a, l)
        );
        let rr = m[3][3] * 8.0 * PI * a.powi(3);
        let want = 1.0 - 4.0 * PI / 3.0 * (a / l).powi(3);
        assert!((rr - want).abs() < 1e-4, "L = {l}: rotation {rr} vs {want}");
        // No self coupling of translation and rotation, no cross terms.
        assert!(m[0][4].abs() < 1e-12 && m[4][0].abs() < 1e-12 && m[0][1].abs() < 1e-12);
    }
}

/// Self-mobility at random positions against Hasimoto (for L >= 16 a, where the Gaussian
/// blob's own finite-size term is below 6e-5 relative) and against the exact periodic
/// Gaussian mobility (the Fourier sum) at every L.
#[test]
fn self_mobility_matches_hasimoto_within_the_tolerance() {
    let Some(gpu) = gpu() else { return };
    let mut rng = Rng::new(61);
    let sigma = 1.0 / PI.sqrt();
    for (tol, l) in [
        (1e-2, 16.0),
        (1e-3, 8.0),
        (1e-3, 16.0),
        (1e-3, 32.0),
        (1e-4, 32.0),
    ] {
        let g = load_with(
            "fcm.json",
            &[
                ("box", &format!("[{l}, {l}, {l}]")),
                ("tolerance", &tol.to_string()),
            ],
            0,
        );
        let plan = fcm_plan(&gpu, &g, 1, false, &["velocities"]);
        let mut fcm = compile(&gpu, &g, &plan);
        let want = hasimoto(1.0, l) / (6.0 * PI);
        let exact = fourier_mobility([0.0; 3], [l; 3], 1.0, sigma, sigma)[0][0];
        let (mut worst, mut worst_exact): (f64, f64) = (0.0, 0.0);
        for _ in 0..6 {
            let x = random_positions(&mut rng, 1, [l; 3]);
            for axis in 0..3 {
                let mut f = [0.0; 3];
                f[axis] = 1.0;
                let v = &eval(&mut fcm, &x, &[f], None)["velocities"][0];
                worst = worst.max((v[axis] / want - 1.0).abs());
                worst_exact = worst_exact.max((v[axis] / exact - 1.0).abs());
            }
        }
        eprintln!(
            "self mobility tol {tol:e} L {l}: worst relative error {worst:e} (Hasimoto), {worst_exact:e} (Fourier sum)"
        );
        assert!(
            worst_exact <= tol,
            "tolerance {tol:e}, L = {l}: {worst_exact:e}"
        );
        if l >= 16.0 {
            assert!(
                worst <= tol,
                "tolerance {tol:e}, L = {l}: {worst:e} against Hasimoto"
            );
        }
    }
}

/// The grand mobility of `x` (6N x 6N: forces then torques per particle, velocities then
/// angular velocities), one column per unit force or torque.
fn grand_mobility(program: &mut Program, x: &[[f64; 3]]) -> Vec<Vec<f64>> {
    let n = x.len();
    let mut m = vec![vec![0.0; 6 * n]; 6 * n];
    for j in 0..n {
        for c in 0..6 {
            let mut f = vec![[0.0; 3]; n];
            let mut t = vec![[0.0; 3]; n];
            if c < 3 {
                f[j][c] = 1.0;
            } else {
                t[j][c - 3] = 1.0;
            }
            let out = eval(program, x, &f, Some(&t));
            for i in 0..n {
                for a in 0..3 {
                    m[6 * i + a][6 * j + c] = out["velocities"][i][a];
                    m[6 * i + 3 + a][6 * j + c] = out["angular_velocities"][i][a];
                }
            }
        }
    }
    m
}

/// Cholesky in f64: `None` when the matrix is not positive definite.
pub(crate) fn cholesky_min_pivot(m: &[Vec<f64>]) -> Option<f64> {
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

#[test]
fn pair_mobility_and_rotation_match_the_fourier_sum() {
    let Some(gpu) = gpu() else { return };
    let (l, tol) = (12.0, 1e-3);
    let g = load_with(
        "fcm.json",
        &[
            ("box", &format!("[{l}, {l}, {l}]")),
            ("tolerance", &tol.to_string()),
            ("rotation", "true"),
        ],
        0,
    );
    let plan = fcm_plan(&gpu, &g, 2, true, &["velocities", "angular_velocities"]);
    let mut fcm = compile(&gpu, &g, &plan);
    let sigma = 1.0 / PI.sqrt();
    let sigma_t = 1.0 / (6.0 * PI.sqrt()).cbrt();
    let (mt, mr) = (1.0 / (6.0 * PI), 1.0 / (8.0 * PI));
    let scale = |i: usize, j: usize| match (i < 3, j < 3) {
        (true, true) => mt,
        (false, false) => mr,
        _ => (mt * mr).sqrt(),
    };
    let mut rng = Rng::new(7);
    let mut worst: f64 = 0.0;
    // Coincident, overlapping, touching and apart; the second particle may wrap.
    for r in [0.0, 0.7, 2.0, 3.5, 5.5] {
        let x0 = random_positions(&mut rng, 1, [l; 3])[0];
        let dir = {
            let d = [0, 1, 2].map(|_| rng.uniform(-1.0, 1.0));
            let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            d.map(|c| c / n)
        };
        let x1 = [0, 1, 2].map(|a| x0[a] + r * dir[a]);
        let m = grand_mobility(&mut fcm, &[x0, x1]);
        let want = fourier_mobility(
            [0, 1, 2].map(|a| x1[a] - x0[a]),
            [l; 3],
            1.0,
            sigma,
            sigma_t,
        );
        let own = fourier_mobility([0.0; 3], [l; 3], 1.0, sigma, sigma_t);
        for i in 0..6 {
            for j in 0..6 {
                // Block (1, 0): particle 1's response to particle 0; block (0, 0): self.
                let pair = (m[6 + i][j] - want[i][j]).abs() / scale(i, j);
                let selfm = (m[i][j] - own[i][j]).abs() / scale(i, j);
                worst = worst.max(pair).max(selfm);
                assert!(
                    pair <= tol && selfm <= tol,
                    "r = {r}: entry ({i}, {j}): pair {} vs {} ({pair:e}), self {} vs {} ({selfm:e})",
                    m[6 + i][j],
                    want[i][j],
                    m[i][j],
                    own[i][j]
                );
            }
        }
    }
    eprintln!("pair mobility: worst error {worst:e} of the self mobilities");
}

#[test]
fn grand_mobility_is_symmetric_and_positive_definite() {
    let Some(gpu) = gpu() else { return };
    let l = 10.0;
    let g = load_with(
        "fcm.json",
        &[
            ("box", &format!("[{l}, {l}, {l}]")),
            ("tolerance", "0.01"),
            ("rotation", "true"),
        ],
        0,
    );
    let mut rng = Rng::new(3);
    // Random particles, one pair overlapping (0.4 a apart) and one across a box face.
    let mut x = random_positions(&mut rng, 3, [l; 3]);
    x.push([x[0][0] + 0.4, x[0][1], x[0][2] - 0.1]);
    x.push([0.5 * l - 0.2, 0.1, -0.3]);
    x.push([-0.5 * l + 0.3, 0.2, -0.4]);
    let plan = fcm_plan(
        &gpu,
        &g,
        x.len() as u32,
        true,
        &["velocities", "angular_velocities"],
    );
    let mut fcm = compile(&gpu, &g, &plan);
    let m = grand_mobility(&mut fcm, &x);
    let biggest = m.iter().flatten().fold(0.0f64, |a, b| a.max(b.abs()));
    let asym = (0..m.len())
        .flat_map(|i| (0..i).map(move |j| (i, j)))
        .map(|(i, j)| (m[i][j] - m[j][i]).abs())
        .fold(0.0f64, f64::max);
    assert!(asym <= 1e-5 * biggest, "asymmetry {asym:e} of {biggest:e}");
    let sym: Vec<Vec<f64>> = (0..m.len())
        .map(|i| (0..m.len()).map(|j| 0.5 * (m[i][j] + m[j][i])).collect())
        .collect();
    let pivot = cholesky_min_pivot(&sym).expect("the grand mobility is positive definite");
    eprintln!(
        "grand mobility: asymmetry {asym:e} of {biggest:e}, smallest Cholesky pivot {pivot:e}"
    );
}

#[test]
fn fluctuating_velocities_add_the_same_noise() {
    let Some(gpu) = gpu() else { return };
    let l = 12.0;
    let sets = [("box", "[12, 12, 12]"), ("noise_scale", "0.7")];
    let outputs = ["velocities", "noise", "fluctuating_velocities"];
    let mut rng = Rng::new(19);
    let x = random_positions(&mut rng, 20, [l; 3]);
    let f: Vec<[f64; 3]> = (0..20)
        .map(|_| [0, 1, 2].map(|_| rng.uniform(-1.0, 1.0)))
        .collect();
    let run = |seed: u64| {
        let g = load_with("fcm.json", &sets, seed);
        let plan = fcm_plan(&gpu, &g, 20, false, &outputs);
        let mut fcm = compile(&gpu, &g, &plan);
        eval(&mut fcm, &x, &f, None)
    };
    let a = run(5);
    let b = run(5);
    let c = run(6);
    let biggest = a["noise"]
        .iter()
        .flatten()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(biggest > 0.0);
    for i in 0..20 {
        for k in 0..3 {
            let combined = a["velocities"][i][k] + 0.7 * a["noise"][i][k];
            assert!(
                (a["fluctuating_velocities"][i][k] - combined).abs() <= 1e-5 * biggest,
                "particle {i} axis {k}: {} vs {combined}",
                a["fluctuating_velocities"][i][k]
            );
            // The same seed draws the same noise; another seed other noise.
            assert_eq!(a["noise"][i][k], b["noise"][i][k]);
        }
    }
    let differs = (0..20).filter(|&i| a["noise"][i] != c["noise"][i]).count();
    assert_eq!(differs, 20, "seed 6 repeated seed 5's noise");
}

/// A graph accumulating noise statistics over the steps of `graphs/<name>` (a mobility
/// graph with a `noise` output): per particle and axis the sum of squares, and the sum
/// over particles squared (the covariance between particles).
fn noise_statistics_graph(
    dir: &std::path::Path,
    name: &str,
    n: usize,
    sets: &str,
) -> std::path::PathBuf {
    let mobility = root().join("graphs").join(name);
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
    crate::util::write_graph(dir, "noise_stats.json", &json)
}

/// Over `steps` fresh draws of the noise of `graphs/<name>` (params `sets`, a JSON
/// object) at positions `x`: per particle and axis the sum of squares, and per axis the
/// sum of squares of the noise summed over the particles.
pub(crate) fn noise_statistics(
    gpu: &GpuContext,
    name: &str,
    sets: &str,
    x: &[[f64; 3]],
    steps: u64,
    seed: u64,
) -> (Vec<[f64; 3]>, [f64; 3]) {
    let dir = crate::util::tmpdir(&format!("noise-{}", name.replace('.', "-")));
    let path = noise_statistics_graph(&dir, name, x.len(), sets);
    let g = graph::load(
        &path,
        registry(),
        &LoadOptions {
            steps,
            seed,
            ..Default::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let opts = PlanOptions {
        outputs: None,
        inputs: [(
            "positions".to_string(),
            ValueType::Particles {
                n: x.len() as u32,
                k: 3,
            },
        )]
        .into_iter()
        .collect(),
        fuse: true,
    };
    let plan = mesoflow::plan::plan(&g, &opts, &gpu.caps).unwrap_or_else(|e| panic!("{e}"));
    let mut program = compile(gpu, &g, &plan);
    program
        .upload(
            &[("positions".to_string(), particles(x))]
                .into_iter()
                .collect(),
        )
        .unwrap();
    program
        .run(&RunOptions {
            steps,
            profile: Profile::Off,
            progress: false,
        })
        .unwrap_or_else(|e| panic!("{e}"));
    let out: BTreeMap<String, HostArray> = program.read_outputs().unwrap().into_iter().collect();
    let _ = std::fs::remove_dir_all(&dir);
    (rows(&out["sq"]), rows(&out["pair"])[0])
}

/// Fluctuation-dissipation: over many steps (fresh draws each) the noise M^(1/2) W has
/// covariance M, for a single particle's variance and between two close particles.
#[test]
fn noise_covariance_is_the_mobility() {
    let Some(gpu) = gpu() else { return };
    let sets = r#"{"box": [8, 8, 8], "tolerance": 0.01}"#;
    let x = vec![[0.3, -1.1, 2.0], [1.6, -0.6, 2.4]];
    // M from the deterministic path of the same graph.
    let g = load_with(
        "fcm.json",
        &[("box", "[8, 8, 8]"), ("tolerance", "0.01")],
        0,
    );
    let plan = fcm_plan(&gpu, &g, 2, false, &["velocities"]);
    let mut fcm = compile(&gpu, &g, &plan);
    let mut m = [[[0.0; 3]; 2]; 2]; // m[i][j][a]: particle i's velocity along a per unit force on j along a
    for j in 0..2 {
        for a in 0..3 {
            let mut f = vec![[0.0; 3]; 2];
            f[j][a] = 1.0;
            let v = &eval(&mut fcm, &x, &f, None)["velocities"];
            for i in 0..2 {
                m[i][j][a] = v[i][a];
            }
        }
    }
    drop(fcm);
    let steps = 12_000u64;
    let (sq, pair) = noise_statistics(&gpu, "fcm.json", sets, &x, steps, 11);
    let s = steps as f64;
    // A variance estimated from s normal samples has relative standard deviation sqrt(2/s)
    // (1.3 % here); 5 of them is the bound.
    let bound = 5.0 * (2.0 / s).sqrt();
    for a in 0..3 {
        for i in 0..2 {
            let var = sq[i][a] / s;
            let want = m[i][i][a];
            eprintln!("particle {i} axis {a}: variance / M = {}", var / want);
            assert!(
                (var / want - 1.0).abs() <= bound,
                "particle {i} axis {a}: variance {var} vs M {want}"
            );
        }
        // var(n0 + n1) = M00 + M11 + 2 M01: the covariance between the particles.
        let var = pair[a] / s;
        let want = m[0][0][a] + m[1][1][a] + m[0][1][a] + m[1][0][a];
        eprintln!("axis {a}: variance of the sum / M = {}", var / want);
        assert!(
            (var / want - 1.0).abs() <= bound,
            "axis {a}: variance of the sum {var} vs {want}"
        );
    }
}

/// Free Brownian particles in bd_fcm.json: the mean squared displacement per axis grows as
/// 2 kT M_self t (M_self is Hasimoto's, whatever the other particles do).
#[test]
fn free_particles_diffuse_with_the_self_mobility() {
    let Some(gpu) = gpu() else { return };
    let (l, n, dt, kt) = (16.0, 64usize, 0.05, 1.5);
    let steps = 240u64;
    let g = graph::load(
        &root().join("graphs/bd_fcm.json"),
        registry(),
        &LoadOptions {
            overrides: [
                ("box", ParamValue::Numbers(vec![l; 3])),
                ("tolerance", ParamValue::Number(1e-2)),
                ("dt", ParamValue::Number(dt)),
                ("temperature", ParamValue::Number(kt)),
                ("save_every", ParamValue::Number(1.0)),
            ]
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect(),
            steps,
            seed: 4,
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let mut rng = Rng::new(23);
    let x0 = random_positions(&mut rng, n, [l; 3]);
    let opts = PlanOptions {
        outputs: None,
        inputs: [(
            "positions".to_string(),
            ValueType::Particles { n: n as u32, k: 3 },
        )]
        .into_iter()
        .collect(),
        fuse: true,
    };
    let plan = mesoflow::plan::plan(&g, &opts, &gpu.caps).unwrap_or_else(|e| panic!("{e}"));
    let mut program = compile(&gpu, &g, &plan);
    program
        .upload(
            &[("positions".to_string(), particles(&x0))]
                .into_iter()
                .collect(),
        )
        .unwrap();
    program
        .run(&RunOptions {
            steps,
            profile: Profile::Off,
            progress: false,
        })
        .unwrap_or_else(|e| panic!("{e}"));
    let out: BTreeMap<String, HostArray> = program.read_outputs().unwrap().into_iter().collect();
    assert_eq!(
        out["trajectory"].ty,
        ValueType::Frames {
            frames: steps as u32,
            n: n as u32,
            k: 3
        }
    );
    let traj = out["trajectory"].data.to_f64();
    let frame = |t: usize, i: usize, a: usize| -> f64 {
        if t == 0 {
            x0[i][a]
        } else {
            traj[((t - 1) * n + i) * 3 + a]
        }
    };
    // The last frame is the final state.
    let last = rows(&out["positions"]);
    assert_eq!(last[5][1], frame(steps as usize, 5, 1));
    let mobility = hasimoto(1.0, l) / (6.0 * PI);
    for lag in [1usize, 8, 40] {
        let mut sum = 0.0;
        let mut count = 0.0;
        for t in 0..=(steps as usize - lag) {
            for i in 0..n {
                for a in 0..3 {
                    let d = frame(t + lag, i, a) - frame(t, i, a);
                    sum += d * d;
                    count += 1.0;
                }
            }
        }
        let msd = sum / count;
        let want = 2.0 * kt * mobility * dt * lag as f64;
        // Independent samples: n * 3 per window of `lag` steps (hydrodynamic correlations
        // between particles are weak at this density); 5 standard deviations.
        let independent = (n * 3) as f64 * (steps as f64 / lag as f64);
        let bound = 5.0 * (2.0 / independent).sqrt();
        eprintln!("MSD lag {lag}: {msd:e} vs 2 kT M t = {want:e} (bound {bound:e})");
        assert!(
            (msd / want - 1.0).abs() <= bound,
            "lag {lag}: MSD {msd} vs {want}"
        );
    }
}

/// Moving every particle by the same vector moves nothing else: velocities agree within
/// the tolerance (exactly up to rounding for whole cells).
#[test]
fn velocities_do_not_depend_on_where_the_grid_is() {
    let Some(gpu) = gpu() else { return };
    let (l, n, tol) = (12.0, 16usize, 1e-3);
    let g = load_with(
        "fcm.json",
        &[("box", "[12, 12, 12]"), ("tolerance", "0.001")],
        0,
    );
    let plan = fcm_plan(&gpu, &g, n as u32, false, &["velocities"]);
    let mut fcm = compile(&gpu, &g, &plan);
    let h = l / 18.0; // the planner's grid for L = 12 a at 1e-3
    assert_eq!(
        g.params
            .iter()
            .find(|p| p.name == "grid")
            .map(|p| p.value.clone()),
        Some(ParamValue::Numbers(vec![18.0; 3]))
    );
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

/// The README's main job (graphs/examples/colloids.json) measures the self-diffusion
/// coefficient from its own initial positions (kept in state: random nodes draw afresh
/// every step) and reports kT times Hasimoto's self-mobility as theory.
#[test]
fn colloids_demo_measures_the_self_diffusion() {
    let Some(gpu) = gpu() else { return };
    let (n, side, steps) = (1000usize, 24.0, 200u64);
    let g = graph::load(
        &root().join("graphs/examples/colloids.json"),
        registry(),
        &LoadOptions {
            overrides: [
                ("n", ParamValue::Number(n as f64)),
                ("side", ParamValue::Number(side)),
                ("tolerance", ParamValue::Number(1e-2)),
            ]
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect(),
            steps,
            seed: 3,
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let out = crate::util::run_graph(&gpu, &g, &BTreeMap::new(), None, steps, true);
    let theory = out["theory"].data.to_f64()[0];
    let want = hasimoto(1.0, side) / (6.0 * PI);
    assert!((theory - want).abs() <= 1e-6 * want, "{theory} vs {want}");
    // Relative standard errors per axis: independent particles plus the Oseen correlation
    // of pairs (graphs/examples/colloids.json's doc); steps are independent samples for
    // the per-step estimate. 5 standard deviations.
    let var = 2.0 / n as f64 + 13.2 / (side * side);
    for (name, bound) in [
        ("diffusion", 5.0 * (var / steps as f64).sqrt()),
        ("diffusion_msd", 5.0 * var.sqrt()),
    ] {
        let d = out[name].data.to_f64();
        eprintln!("colloids: {name} = {d:?}, theory {theory:e}, bound {bound:e} per axis");
        for (a, &da) in d.iter().enumerate() {
            assert!(
                (da / theory - 1.0).abs() <= bound,
                "{name} axis {a}: {da:e} vs {theory:e}"
            );
        }
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
            9,
        );
        let plan = fcm_plan(&gpu, &g, n as u32, true, &outputs);
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
        let mut fcm = compile(&gpu, &g, &plan);
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

/// Particles on cell faces and box faces, coincident particles, an elongated box.
#[test]
fn hard_placements_and_shapes() {
    let Some(gpu) = gpu() else { return };
    let sigma = 1.0 / PI.sqrt();
    // Elongated box: 8 times longer than wide, against the f64 Fourier sum.
    let lengths = [48.0, 6.0, 6.0];
    let g = load_with(
        "fcm.json",
        &[("box", "[48, 6, 6]"), ("tolerance", "0.001")],
        0,
    );
    let plan = fcm_plan(&gpu, &g, 1, false, &["velocities"]);
    let mut fcm = compile(&gpu, &g, &plan);
    let exact = fourier_mobility([0.0; 3], lengths, 1.0, sigma, sigma);
    for axis in 0..3 {
        let mut f = [0.0; 3];
        f[axis] = 1.0;
        let v = &eval(&mut fcm, &[[3.3, -1.2, 0.4]], &[f], None)["velocities"][0];
        let e = (v[axis] / exact[axis][axis] - 1.0).abs();
        assert!(
            e <= 1e-3,
            "elongated box, axis {axis}: {} vs {} ({e:e})",
            v[axis],
            exact[axis][axis]
        );
    }
    drop(fcm);

    let l = 12.0;
    let g = load_with("fcm.json", &[("box", "[12, 12, 12]")], 0);
    let plan = fcm_plan(&gpu, &g, 2, false, &["velocities"]);
    let mut fcm = compile(&gpu, &g, &plan);
    let h = l / 18.0;
    let f = [[1.0, -0.5, 0.25], [0.0, 0.0, 0.0]];
    // On a cell face, a cell edge and a cell corner of the grid; at the box face the same
    // point seen from both sides.
    let face = eval(
        &mut fcm,
        &[[-6.0 + 7.0 * h, 0.3, 0.1], [5.0, 5.0, 5.0]],
        &f,
        None,
    );
    let corner = eval(
        &mut fcm,
        &[
            [-6.0 + 7.0 * h, -6.0 + 2.0 * h, -6.0 + 11.0 * h],
            [5.0, 5.0, 5.0],
        ],
        &f,
        None,
    );
    let plus = eval(&mut fcm, &[[6.0, 1.0, -2.0], [0.0, 0.0, 0.0]], &f, None);
    let minus = eval(&mut fcm, &[[-6.0, 1.0, -2.0], [0.0, 0.0, 0.0]], &f, None);
    let m0 = hasimoto(1.0, l) / (6.0 * PI);
    for (name, out) in [
        ("cell face", &face),
        ("cell corner", &corner),
        ("box face", &plus),
    ] {
        let v = out["velocities"][0];
        assert!(
            v.iter().all(|c| c.is_finite()) && (v[0] / m0 - 1.0).abs() < 2e-3,
            "{name}: {v:?} for M0 {m0}"
        );
    }
    for a in 0..3 {
        for i in 0..2 {
            assert!(
                (plus["velocities"][i][a] - minus["velocities"][i][a]).abs() <= 1e-6 * m0,
                "x = +L/2 and -L/2 differ"
            );
        }
    }
    // Coincident particles: both move as one, each with the self mobility.
    let both = eval(
        &mut fcm,
        &[[1.1, 2.2, -3.3], [1.1, 2.2, -3.3]],
        &[[1.0, 0.0, 0.0], [0.0; 3]],
        None,
    );
    let v = &both["velocities"];
    assert!((v[0][0] - v[1][0]).abs() <= 1e-6 * m0, "{v:?}");
    assert!((v[1][0] / m0 - 1.0).abs() < 2e-3, "{v:?}");
}

#[test]
fn bad_settings_get_clear_errors() {
    let load_err = |sets: &[(&str, &str)]| -> String {
        let overrides = sets
            .iter()
            .map(|(k, v)| {
                let json: serde_json::Value = serde_json::from_str(v).unwrap();
                (k.to_string(), ParamValue::from_json(&json).unwrap())
            })
            .collect();
        match graph::load(
            &root().join("graphs/fcm.json"),
            registry(),
            &LoadOptions {
                overrides,
                ..Default::default()
            },
        ) {
            Ok(_) => panic!("{sets:?} loaded"),
            Err(e) => e.to_string(),
        }
    };
    // Tighter than f32 can hold.
    let e = load_err(&[("tolerance", "1e-7")]);
    assert!(
        e.contains("tolerance") && e.contains("1e-6") || e.contains("0.000001"),
        "{e}"
    );
    // Viscosity zero: the Green function's node says so.
    let e = load_err(&[("viscosity", "0")]);
    assert!(e.contains("viscosity") && e.contains("flow"), "{e}");
    // Rotation with a window that ties the radius to the cell.
    let e = load_err(&[("rotation", "true"), ("kernel", "\"peskin4\"")]);
    assert!(e.contains("rotation") && e.contains("gaussian"), "{e}");
    // A box too thin for the window.
    let e = load_err(&[("box", "[24, 24, 3]")]);
    assert!(e.contains("support"), "{e}");

    // Torques without the rotation grid: the torque window says it is too coarse.
    let g = load_with("fcm.json", &[], 0);
    let caps = mesoflow::gpu::DeviceCaps::baseline();
    let p3 = ValueType::Particles { n: 4, k: 3 };
    let opts = PlanOptions {
        outputs: Some(vec!["velocities".into()]),
        inputs: [("positions", p3), ("forces", p3), ("torques", p3)]
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect(),
        fuse: true,
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

/// The noise spectrum is the half spectrum of a real field (its inverse transform and
/// forward transform give it back), and each step draws anew (step 1 against the f64
/// reference at step 1).
#[test]
fn fourier_noise_is_hermitian_and_fresh_every_step() {
    let Some(gpu) = gpu() else { return };
    let params =
        r#"{"box": [2, 1.5, 1], "grid": [8, 6, 5], "viscosity": 0.8, "noise": 0.3, "seed": 9}"#;
    let json = format!(
        r#"{{"mesoflow": 1, "nodes": [
            {{"id": "n", "kind": "stokes_noise", "params": {params}}},
            {{"id": "i", "kind": "irfft", "inputs": {{"x": "n.out"}}}},
            {{"id": "f", "kind": "rfft", "inputs": {{"x": "i.out"}}}}],
          "outputs": {{"noise": "n.out", "back": "f.out"}}}}"#
    );
    let dir = crate::util::tmpdir("fcm-noise");
    let g = crate::util::load(&crate::util::write_graph(&dir, "g.json", &json));
    let out = crate::util::run_graph(&gpu, &g, &BTreeMap::new(), None, 2, true);
    let noise = out["noise"].data.to_f64();
    let back = out["back"].data.to_f64();
    let norm = noise.iter().map(|x| x * x).sum::<f64>().sqrt();
    let diff = noise
        .iter()
        .zip(&back)
        .map(|(a, b)| (a - b) * (a - b))
        .sum::<f64>()
        .sqrt();
    assert!(diff <= 1e-5 * norm, "not Hermitian: {diff:e} of {norm:e}");
    // After 2 steps the output holds step 1's draw.
    let kind = registry().get("stokes_noise").unwrap();
    let raw: BTreeMap<String, serde_json::Value> = serde_json::from_str(params).unwrap();
    let raw = raw
        .into_iter()
        .map(|(k, v)| (k, ParamValue::from_json(&v).unwrap()))
        .collect();
    let node = kind
        .build(&mesoflow::node::check_params(&kind.params(), &raw).unwrap())
        .unwrap();
    let ty = out["noise"].ty;
    let mut want = vec![mesoflow::value::RefArray::new(
        ty,
        vec![0.0; ty.words() as usize],
    )];
    node.cpu_reference(&[], &mut want, mesoflow::node::RefCtx { step: 1 });
    let (e, at) = crate::util::rel_max_err(&out["noise"], &want[0]);
    assert!(e <= 2e-6, "step 1: {e:e} at {at}");
    let mut step0 = want.clone();
    node.cpu_reference(&[], &mut step0, mesoflow::node::RefCtx { step: 0 });
    let (e, _) = crate::util::rel_max_err(&out["noise"], &step0[0]);
    assert!(e > 0.1, "step 1 repeated step 0's draw");
}
