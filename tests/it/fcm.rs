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
fn cache() -> std::sync::MutexGuard<'static, KernelCache> {
    static CACHE: OnceLock<Mutex<KernelCache>> = OnceLock::new();
    CACHE
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|p| p.into_inner())
}

/// `graphs/<name>` loaded with these `--set` values (JSON literals) and seed.
fn load_with(name: &str, sets: &[(&str, &str)], seed: u64) -> Graph {
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

fn particles(rows: &[[f64; 3]]) -> HostArray {
    HostArray::f32(
        ValueType::Particles {
            n: rows.len() as u32,
            k: 3,
        },
        rows.iter().flatten().map(|&x| x as f32).collect(),
    )
}

fn rows(a: &HostArray) -> Vec<[f64; 3]> {
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

fn compile<'a>(gpu: &'a GpuContext, g: &'a Graph, plan: &'a Plan) -> Program<'a> {
    Program::compile(gpu, g, plan, &mut cache()).unwrap_or_else(|e| panic!("{e}"))
}

/// Outputs of a compiled fcm.json for these inputs, one evaluation.
fn eval(
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
fn hasimoto(a: f64, l: f64) -> f64 {
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
        (1e-4, 16.0),
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
        assert!(worst <= tol, "tolerance {tol:e}, L = {l}: {worst:e}");
    }
}
