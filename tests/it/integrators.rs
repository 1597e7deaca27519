//! The integrator library, graphs/lib/integrators/: each scheme run as a subgraph around
//! the force laws of graphs/lib/forces/ and the mobilities of graphs/lib/mobility/ and
//! graphs/, against f64 references written here, independent of the graphs: closed forms
//! (the trap's exponential relaxation, the undamped and damped oscillators, Hasimoto's
//! periodic self-mobility) and the exact Gaussian law of each scheme's recursion in a
//! harmonic trap (its stationary variance, its autocovariances and so the standard error
//! of a time average). Checked: the order of accuracy at temperature 0, the equilibrium
//! variances (each against its standard error), the mean squared displacement of free
//! particles (free draining and FCM), the mobility's drift term, velocity Verlet's
//! energy, every mobility graph planned inside every Brownian integrator, and the error
//! of a mobility or force law that lacks a port the integrators read.

use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::sync::atomic::{AtomicUsize, Ordering};

use mesoflow::gpu::GpuContext;
use mesoflow::value::HostArray;

use crate::util::mobility::hasimoto;
use crate::util::{
    Rng, flat_particles, gpu, load_for, load_or_plan_error, run_cached, tmpdir, write_graph,
};

/// The Brownian integrators and their deterministic order.
const BROWNIAN: [(&str, f64); 4] = [
    ("euler_maruyama", 1.0),
    ("leimkuhler", 1.0),
    ("midpoint", 2.0),
    ("adams_bashforth", 2.0),
];

/// The viscosity that gives the free mobility (radius 1) mu = 1 / (6 pi eta a) = 1.
const UNIT_MOBILITY_VISCOSITY: f64 = 1.0 / (6.0 * PI);

/// A run of one integrator inside a wrapper graph.
struct Setup<'a> {
    integrator: &'a str,
    /// The integrator node's params: entries of a JSON object, without the braces.
    params: String,
    n: usize,
    /// Declares the inertial inputs (velocities and masses, both optional).
    inertial: bool,
    /// Outputs of the integrator recorded every step: frame t of `NAME_frames` holds the
    /// value after t steps (the step's starting state; the last state is the output).
    record: &'a [&'a str],
}

static WRAPPERS: AtomicUsize = AtomicUsize::new(0);

impl Setup<'_> {
    fn json(&self, steps: u64) -> String {
        let n = self.n;
        let mut inputs = format!(r#""positions": {{"type": "particles", "rows": {n}, "cols": 3}}"#);
        let mut wired = r#""positions": "inputs.positions""#.to_string();
        let mut outputs = vec![r#""positions": "step.positions""#.to_string()];
        if self.inertial {
            inputs += &format!(
                r#", "velocities": {{"type": "particles", "rows": {n}, "cols": 3, "optional": true}},
                   "masses": {{"type": "particles", "rows": {n}, "cols": 1, "optional": true}}"#
            );
            wired += r#", "velocities": "inputs.velocities", "masses": "inputs.masses""#;
            outputs.push(r#""velocities": "step.velocities""#.to_string());
        }
        let mut nodes = vec![format!(
            r#"{{"id": "step", "graph": "lib/integrators/{}.json", "params": {{{}}}, "inputs": {{{wired}}}}}"#,
            self.integrator, self.params
        )];
        for r in self.record {
            nodes.push(format!(
                r#"{{"id": "record_{r}", "kind": "record", "params": {{"frames": {steps}}}, "inputs": {{"x": "step.{r}"}}}}"#
            ));
            outputs.push(format!(r#""{r}_frames": "record_{r}.out""#));
        }
        format!(
            r#"{{"mesoflow": 1, "inputs": {{{inputs}}}, "nodes": [{}], "outputs": {{{}}}}}"#,
            nodes.join(",\n  "),
            outputs.join(", ")
        )
    }

    /// Runs `steps` steps with this seed: every output by name.
    fn run(
        &self,
        gpu: &GpuContext,
        inputs: &BTreeMap<String, HostArray>,
        steps: u64,
        seed: u64,
    ) -> BTreeMap<String, HostArray> {
        let k = WRAPPERS.fetch_add(1, Ordering::Relaxed);
        let dir = tmpdir(&format!("integrators-{}-{k}", self.integrator));
        let path = write_graph(&dir, "run.json", &self.json(steps));
        let g = load_for(&path, steps, seed);
        run_cached(gpu, &g, inputs, None, steps, true).0
    }
}

/// The frames of `name` (steps x n x k) followed by the final output: `steps + 1` states.
fn states(out: &BTreeMap<String, HostArray>, name: &str) -> Vec<Vec<f64>> {
    let frames = out[&format!("{name}_frames")].data.to_f64();
    let last = out[name].data.to_f64();
    let mut s: Vec<Vec<f64>> = frames.chunks(last.len()).map(|c| c.to_vec()).collect();
    s.push(last);
    s
}

fn rms(values: impl Iterator<Item = f64>) -> f64 {
    let (mut sum, mut count) = (0.0, 0.0);
    for v in values {
        sum += v * v;
        count += 1.0;
    }
    (sum / count).sqrt()
}

/// Numbers for a message, `digits` significant ones each.
fn list(values: &[f64], digits: usize) -> String {
    let v: Vec<String> = values
        .iter()
        .map(|x| format!("{x:.0$e}", digits - 1))
        .collect();
    format!("[{}]", v.join(", "))
}

/// Observed orders log2(e(dt) / e(dt / 2)) of a sequence of errors at halved steps.
fn orders(errors: &[f64]) -> Vec<f64> {
    errors.windows(2).map(|e| (e[0] / e[1]).log2()).collect()
}

type Mat = Vec<Vec<f64>>;

fn matmul(x: &Mat, y: &Mat) -> Mat {
    (0..x.len())
        .map(|i| {
            (0..y[0].len())
                .map(|j| (0..y.len()).map(|k| x[i][k] * y[k][j]).sum())
                .collect()
        })
        .collect()
}

fn transpose(x: &Mat) -> Mat {
    (0..x[0].len())
        .map(|j| (0..x.len()).map(|i| x[i][j]).collect())
        .collect()
}

/// The exact law of one coordinate under a scheme whose forces are linear in the
/// positions (a harmonic trap) with a constant mobility: y_{n+1} = A y_n + B xi_n, xi_n
/// standard normal and independent, y_0 ~ N(0, P_0), y_n[0] the coordinate (and y_n[1]
/// a velocity or the previous step's noise or position, as the scheme keeps).
struct Linear {
    a: Mat,
    b: Mat,
}

impl Linear {
    /// The covariance after one step: A P A^T + B B^T.
    fn next(&self, p: &Mat) -> Mat {
        let apa = matmul(&matmul(&self.a, p), &transpose(&self.a));
        let bb = matmul(&self.b, &transpose(&self.b));
        (0..apa.len())
            .map(|i| (0..apa.len()).map(|j| apa[i][j] + bb[i][j]).collect())
            .collect()
    }

    /// The stationary covariance (the fixed point of `next`).
    fn stationary(&self) -> Mat {
        let d = self.a.len();
        let mut p = vec![vec![0.0; d]; d];
        for _ in 0..1_000_000 {
            let q = self.next(&p);
            let change = (0..d)
                .flat_map(|i| (0..d).map(move |j| (i, j)))
                .map(|(i, j)| (q[i][j] - p[i][j]).abs())
                .fold(0.0, f64::max);
            p = q;
            if change <= 1e-16 * p[0][0].abs() {
                break;
            }
        }
        p
    }

    /// The expectation and the standard error of the mean of y_n[c]^2 over n in
    /// `from..to` and over `copies` independent copies of the recursion from P_0: for a
    /// Gaussian sequence Cov(y_i^2, y_j^2) = 2 Cov(y_i, y_j)^2, with Cov(y_j, y_i) =
    /// A^(j - i) P_i.
    fn mean_square(&self, p0: &Mat, c: usize, from: usize, to: usize, copies: usize) -> (f64, f64) {
        let mut ps = vec![p0.clone()];
        for n in 1..to {
            let p = self.next(&ps[n - 1]);
            ps.push(p);
        }
        let count = (to - from) as f64;
        let mean = (from..to).map(|n| ps[n][c][c]).sum::<f64>() / count;
        let mut sum = 0.0;
        for (i, p) in ps.iter().enumerate().skip(from) {
            let mut m = p.clone();
            sum += m[c][c].powi(2);
            for _ in i + 1..to {
                m = matmul(&self.a, &m);
                sum += 2.0 * m[c][c].powi(2);
            }
        }
        (mean, (2.0 * sum / (count * count * copies as f64)).sqrt())
    }
}

/// A Brownian scheme's law in the trap, h = k mu dt, s2 = kT mu dt (the variance of one
/// sqrt(kT dt) M^(1/2) W term): the state y, its initial covariance for positions drawn
/// with variance v0 (the schemes' other state as each starts it).
fn brownian_law(integrator: &str, h: f64, s2: f64, v0: f64) -> (Linear, Mat) {
    let s = s2.sqrt();
    let r2 = std::f64::consts::SQRT_2;
    match integrator {
        // x' = (1 - h) x + sqrt(2) s W
        "euler_maruyama" => (
            Linear {
                a: vec![vec![1.0 - h]],
                b: vec![vec![r2 * s]],
            },
            vec![vec![v0]],
        ),
        // q' = (1 - h/2) x + s W1; x' = x - h q' + s (W1 + W2)
        "midpoint" => (
            Linear {
                a: vec![vec![1.0 - h + h * h / 2.0]],
                b: vec![vec![s * (1.0 - h), s]],
            },
            vec![vec![v0]],
        ),
        // y = (x_n, x_(n-1)); x' = x - h (3/2 x_n - 1/2 x_(n-1)) + sqrt(2) s W; first
        // step x_(-1) = x_0.
        "adams_bashforth" => (
            Linear {
                a: vec![vec![1.0 - 1.5 * h, 0.5 * h], vec![1.0, 0.0]],
                b: vec![vec![r2 * s], vec![0.0]],
            },
            vec![vec![v0, v0], vec![v0, v0]],
        ),
        // y = (x_n, W_(n-1)); x' = (1 - h) x + (sqrt(2) s / 2) (W_n + W_(n-1)); W_(-1) = 0.
        "leimkuhler" => (
            Linear {
                a: vec![vec![1.0 - h, r2 * s / 2.0], vec![0.0, 0.0]],
                b: vec![vec![r2 * s / 2.0], vec![1.0]],
            },
            vec![vec![v0, 0.0], vec![0.0, 0.0]],
        ),
        _ => unreachable!(),
    }
}

/// Gronbech-Jensen-Farago in a harmonic trap (one coordinate and its velocity):
/// x' = x + b dt v + (b dt^2 / 2m) (-k x) + (b dt / 2m) beta,
/// v' = a v + (dt / 2m) (a (-k x) + (-k x')) + (b / m) beta, beta ~ N(0, 2 xi kT dt).
fn gjf_law(m: f64, k: f64, xi: f64, kt: f64, dt: f64) -> Linear {
    let g = xi * dt / (2.0 * m);
    let b = 1.0 / (1.0 + g);
    let a = b * (1.0 - g);
    let sd = (2.0 * xi * kt * dt).sqrt();
    let (xx, xv, xb) = (
        1.0 - b * dt * dt * k / (2.0 * m),
        b * dt,
        b * dt / (2.0 * m),
    );
    let h = dt / (2.0 * m);
    Linear {
        a: vec![vec![xx, xv], vec![h * (-a * k - k * xx), a - h * k * xv]],
        b: vec![vec![xb * sd], vec![(b / m - h * k * xb) * sd]],
    }
}

/// Brownian integrators at temperature 0 in a harmonic trap (stiffness k, centre c, the
/// free mobility with mu = 1): x(T) = c + (x0 - c) exp(-k mu T), reached with dt, dt/2
/// and dt/4; the error shrinks at each scheme's order (Euler-Maruyama and Leimkuhler 1,
/// midpoint and Adams-Bashforth 2).
#[test]
fn brownian_integrators_converge_at_their_order_in_a_trap() {
    let Some(gpu) = gpu() else { return };
    let (k, t_end, n): (f64, f64, usize) = (1.0, 2.0, 64);
    let centre = [0.5, -0.25, 1.0];
    let mut rng = Rng::new(7);
    let x0: Vec<f64> = (0..n * 3)
        .map(|i| {
            centre[i % 3]
                + rng.uniform(0.5, 1.5)
                    * if rng.uniform(0.0, 1.0) < 0.5 {
                        -1.0
                    } else {
                        1.0
                    }
        })
        .collect();
    let inputs: BTreeMap<String, HostArray> =
        [("positions".to_string(), flat_particles(&x0, 3))].into();
    let decay = (-k * t_end).exp();
    let exact: Vec<f64> = x0
        .iter()
        .enumerate()
        .map(|(i, x)| centre[i % 3] + (x - centre[i % 3]) * decay)
        .collect();
    let scale = rms(exact.iter().enumerate().map(|(i, x)| x - centre[i % 3]));
    for (integrator, order) in BROWNIAN {
        let errors: Vec<f64> = [0.2, 0.1, 0.05]
            .iter()
            .map(|&dt| {
                let steps = (t_end / dt).round() as u64;
                let setup = Setup {
                    integrator,
                    params: format!(
                        r#""dt": {dt}, "temperature": 0, "forces": "lib/forces/harmonic_trap.json", "forces.stiffness": {k}, "forces.centre": {centre:?}, "mobility.viscosity": {UNIT_MOBILITY_VISCOSITY}"#
                    ),
                    n,
                    inertial: false,
                    record: &[],
                };
                let out = setup.run(&gpu, &inputs, steps, 1);
                let x = out["positions"].data.to_f64();
                rms(x.iter().zip(&exact).map(|(a, b)| a - b)) / scale
            })
            .collect();
        let p = orders(&errors);
        eprintln!(
            "{integrator}: relative errors {} at dt 0.2, 0.1, 0.05: orders {p:.3?} (expected {order})",
            list(&errors, 3)
        );
        for q in &p {
            assert!(
                (q - order).abs() <= 0.15,
                "{integrator}: observed orders {p:?}, expected {order} (errors {errors:?})"
            );
        }
    }
}

/// The undamped oscillator with a mass per particle (the input masses): velocity Verlet
/// against x(t) = c + (x0 - c) cos(w t) + (v0 / w) sin(w t), w = sqrt(k / m_i), second
/// order in positions and velocities.
#[test]
fn velocity_verlet_converges_at_second_order_with_masses() {
    let Some(gpu) = gpu() else { return };
    let (k, t_end, n): (f64, f64, usize) = (1.0, 2.0, 64);
    let centre = [0.5, -0.25, 1.0];
    let mut rng = Rng::new(8);
    let x0: Vec<f64> = (0..n * 3)
        .map(|i| centre[i % 3] + rng.uniform(-1.0, 1.0))
        .collect();
    let v0: Vec<f64> = (0..n * 3).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let m: Vec<f64> = (0..n).map(|_| rng.uniform(0.5, 2.0)).collect();
    let inputs: BTreeMap<String, HostArray> = [
        ("positions".to_string(), flat_particles(&x0, 3)),
        ("velocities".to_string(), flat_particles(&v0, 3)),
        ("masses".to_string(), flat_particles(&m, 1)),
    ]
    .into();
    let (mut ex, mut ev) = (vec![0.0; n * 3], vec![0.0; n * 3]);
    for i in 0..n * 3 {
        let w = (k / m[i / 3]).sqrt();
        let (c, s) = ((w * t_end).cos(), (w * t_end).sin());
        let d = x0[i] - centre[i % 3];
        ex[i] = centre[i % 3] + d * c + v0[i] / w * s;
        ev[i] = -d * w * s + v0[i] * c;
    }
    let errors: Vec<f64> = [0.2, 0.1, 0.05]
        .iter()
        .map(|dt| {
            let setup = Setup {
                integrator: "velocity_verlet",
                params: format!(
                    r#""dt": {dt}, "forces": "lib/forces/harmonic_trap.json", "forces.stiffness": {k}, "forces.centre": {centre:?}"#
                ),
                n,
                inertial: true,
                record: &[],
            };
            let out = setup.run(&gpu, &inputs, (t_end / dt).round() as u64, 1);
            let (x, v) = (out["positions"].data.to_f64(), out["velocities"].data.to_f64());
            rms(x.iter().zip(&ex).chain(v.iter().zip(&ev)).map(|(a, b)| a - b))
        })
        .collect();
    let p = orders(&errors);
    eprintln!(
        "velocity_verlet: errors {} at dt 0.2, 0.1, 0.05: orders {p:.3?}",
        list(&errors, 3)
    );
    for q in &p {
        assert!(
            (q - 2.0).abs() <= 0.15,
            "observed orders {p:?} (errors {errors:?})"
        );
    }
}

/// The damped oscillator m x'' = -k (x - c) - xi x' (the param mass, no masses input):
/// Gronbech-Jensen-Farago at temperature 0 against the closed form, second order; given
/// masses equal to the param give the same run.
#[test]
fn langevin_gjf_converges_at_second_order_with_friction() {
    let Some(gpu) = gpu() else { return };
    let (k, m, xi, t_end, n): (f64, f64, f64, f64, usize) = (1.0, 2.0, 0.5, 4.0, 64);
    let centre = [0.5, -0.25, 1.0];
    let mut rng = Rng::new(9);
    let x0: Vec<f64> = (0..n * 3)
        .map(|i| centre[i % 3] + rng.uniform(-1.0, 1.0))
        .collect();
    let v0: Vec<f64> = (0..n * 3).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let inputs: BTreeMap<String, HostArray> = [
        ("positions".to_string(), flat_particles(&x0, 3)),
        ("velocities".to_string(), flat_particles(&v0, 3)),
    ]
    .into();
    // x - c = e^(-g t / 2) (A cos(w t) + B sin(w t)), g = xi / m, w^2 = k / m - g^2 / 4.
    let g = xi / m;
    let w = (k / m - g * g / 4.0).sqrt();
    let e = (-g * t_end / 2.0).exp();
    let (c, s) = ((w * t_end).cos(), (w * t_end).sin());
    let (mut ex, mut ev) = (vec![0.0; n * 3], vec![0.0; n * 3]);
    for i in 0..n * 3 {
        let a = x0[i] - centre[i % 3];
        let b = (v0[i] + g * a / 2.0) / w;
        let d = e * (a * c + b * s);
        ex[i] = centre[i % 3] + d;
        ev[i] = -g / 2.0 * d + e * w * (-a * s + b * c);
    }
    let params = |dt: f64| {
        format!(
            r#""dt": {dt}, "temperature": 0, "friction": {xi}, "mass": {m}, "forces": "lib/forces/harmonic_trap.json", "forces.stiffness": {k}, "forces.centre": {centre:?}"#
        )
    };
    let setup = |dt: f64| Setup {
        integrator: "langevin_gjf",
        params: params(dt),
        n,
        inertial: true,
        record: &[],
    };
    let mut finest = BTreeMap::new();
    let errors: Vec<f64> = [0.2, 0.1, 0.05]
        .iter()
        .map(|&dt| {
            let out = setup(dt).run(&gpu, &inputs, (t_end / dt).round() as u64, 1);
            let (x, v) = (
                out["positions"].data.to_f64(),
                out["velocities"].data.to_f64(),
            );
            finest = out;
            rms(x
                .iter()
                .zip(&ex)
                .chain(v.iter().zip(&ev))
                .map(|(a, b)| a - b))
        })
        .collect();
    let p = orders(&errors);
    eprintln!(
        "langevin_gjf: errors {} at dt 0.2, 0.1, 0.05: orders {p:.3?}",
        list(&errors, 3)
    );
    for q in &p {
        assert!(
            (q - 2.0).abs() <= 0.15,
            "observed orders {p:?} (errors {errors:?})"
        );
    }
    // The same particles with the input masses, every one m.
    let mut with_masses = inputs.clone();
    with_masses.insert("masses".to_string(), flat_particles(&vec![m; n], 1));
    let out = setup(0.05).run(&gpu, &with_masses, 80, 1);
    for name in ["positions", "velocities"] {
        let (a, b) = (out[name].data.to_f64(), finest[name].data.to_f64());
        let diff = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
        assert!(
            diff <= 1e-6,
            "{name}: masses = m differ from mass = m by {diff}"
        );
    }
}

/// Brownian integrators in a harmonic trap at kT = 1 (k = 1, mu = 1, k mu dt = 0.1): the
/// mean of x^2 over every step and 1500 coordinates (500 independent particles) against
/// the exact law of each scheme's recursion, within 4 standard errors of that law (its
/// autocovariances computed, not estimated). Leimkuhler samples kT / k exactly (positions
/// drawn so that the first step's state is stationary): its mean is held to kT / k.
/// Euler-Maruyama's known bias, kT / (k (1 - h/2)), is 2 standard errors away, and the
/// others' (h^2 / 2 for Adams-Bashforth, h^3 / 8 for the midpoint scheme) below one.
#[test]
fn brownian_integrators_sample_the_trap_at_temperature() {
    let Some(gpu) = gpu() else { return };
    let (k, kt, dt, n, steps): (f64, f64, f64, usize, u64) = (1.0, 1.0, 0.1, 500, 300);
    let h = k * dt;
    let s2 = kt * dt;
    for (integrator, _) in BROWNIAN {
        // Stationary starts: kT / k, and for Leimkuhler the variance whose first step (with
        // W^(-1) = 0) lands on the stationary law.
        let v0 = if integrator == "leimkuhler" {
            kt / k * (1.0 - h / 2.0) / ((1.0 - h) * (1.0 - h))
        } else {
            kt / k
        };
        let mut rng = Rng::new(21);
        let x0: Vec<f64> = (0..n * 3).map(|_| v0.sqrt() * rng.normal()).collect();
        let setup = Setup {
            integrator,
            params: format!(
                r#""dt": {dt}, "temperature": {kt}, "forces": "lib/forces/harmonic_trap.json", "forces.stiffness": {k}, "mobility.viscosity": {UNIT_MOBILITY_VISCOSITY}"#
            ),
            n,
            inertial: false,
            record: &["positions"],
        };
        let out = setup.run(
            &gpu,
            &[("positions".to_string(), flat_particles(&x0, 3))].into(),
            steps,
            5,
        );
        let x = states(&out, "positions");
        let (from, to) = (1usize, steps as usize + 1);
        let measured =
            x[from..to].iter().flatten().map(|v| v * v).sum::<f64>() / ((to - from) * n * 3) as f64;
        let (law, p0) = brownian_law(integrator, h, s2, v0);
        let (want, se) = law.mean_square(&p0, 0, from, to, n * 3);
        // The closed forms of the stationary variances (graph docs) agree with the law.
        let stationary = law.stationary()[0][0];
        let closed = match integrator {
            "euler_maruyama" => kt / (k * (1.0 - h / 2.0)),
            "midpoint" => {
                kt / k * (2.0 - 2.0 * h + h * h) / (2.0 - 2.0 * h + h * h - h * h * h / 4.0)
            }
            "adams_bashforth" => kt / k * (1.0 - h / 2.0) / ((1.0 + h / 2.0) * (1.0 - h)),
            _ => kt / k,
        };
        assert!(
            (stationary / closed - 1.0).abs() < 1e-9,
            "{integrator}: {stationary} vs {closed}"
        );
        if integrator == "leimkuhler" {
            assert!(
                (want / (kt / k) - 1.0).abs() < 1e-9,
                "the law's mean {want}"
            );
        }
        eprintln!(
            "{integrator}: <k x^2> = {:.5} against the scheme's {:.5} (standard error {se:.2e}: {:+.2} sigma; kT = {kt}: {:+.2} sigma)",
            k * measured,
            k * want,
            (measured - want) / se,
            (measured - kt / k) / se
        );
        assert!(
            (measured - want).abs() <= 4.0 * se,
            "{integrator}: <x^2> = {measured}, expected {want} +- {se}"
        );
    }
}

/// Gronbech-Jensen-Farago in a harmonic trap (k = m = xi = kT = 1, dt = 0.1), started from
/// its stationary law: <k x^2> = kT exactly (the law's mean equals kT to rounding) and
/// <m v^2> = kT (1 - (w dt)^2 / 4), the scheme's known velocity bias (a quarter of a
/// standard error here), both within 4 standard errors of the exact law.
#[test]
fn langevin_gjf_samples_kt_per_degree_of_freedom() {
    let Some(gpu) = gpu() else { return };
    let (k, m, xi, kt, dt, n, steps) = (1.0, 1.0, 1.0, 1.0, 0.1, 500usize, 300u64);
    let law = gjf_law(m, k, xi, kt, dt);
    let p = law.stationary();
    assert!(
        (k * p[0][0] / kt - 1.0).abs() < 1e-9,
        "GJF's configurational temperature: {}",
        k * p[0][0]
    );
    let omega_dt2 = k / m * dt * dt;
    assert!(
        (m * p[1][1] / (kt * (1.0 - omega_dt2 / 4.0)) - 1.0).abs() < 1e-9,
        "GJF's kinetic temperature: {}",
        m * p[1][1]
    );
    // (x, v) drawn from the stationary covariance.
    let mut rng = Rng::new(22);
    let (mut x0, mut v0) = (vec![0.0; n * 3], vec![0.0; n * 3]);
    let lxx = p[0][0].sqrt();
    let lvx = p[1][0] / lxx;
    let lvv = (p[1][1] - lvx * lvx).sqrt();
    for i in 0..n * 3 {
        let (z1, z2) = (rng.normal(), rng.normal());
        x0[i] = lxx * z1;
        v0[i] = lvx * z1 + lvv * z2;
    }
    let setup = Setup {
        integrator: "langevin_gjf",
        params: format!(
            r#""dt": {dt}, "temperature": {kt}, "friction": {xi}, "mass": {m}, "forces": "lib/forces/harmonic_trap.json", "forces.stiffness": {k}"#
        ),
        n,
        inertial: true,
        record: &["positions", "velocities"],
    };
    let inputs: BTreeMap<String, HostArray> = [
        ("positions".to_string(), flat_particles(&x0, 3)),
        ("velocities".to_string(), flat_particles(&v0, 3)),
    ]
    .into();
    let out = setup.run(&gpu, &inputs, steps, 6);
    let (from, to) = (1usize, steps as usize + 1);
    for (c, name, factor) in [(0, "positions", k), (1, "velocities", m)] {
        let y = states(&out, name);
        let measured = factor * y[from..to].iter().flatten().map(|v| v * v).sum::<f64>()
            / ((to - from) * n * 3) as f64;
        let (want, se) = law.mean_square(&p, c, from, to, n * 3);
        let (want, se) = (factor * want, factor * se);
        eprintln!(
            "langevin_gjf: {} = {measured:.5} against {want:.5} (standard error {se:.2e}: {:+.2} sigma; kT: {:+.2} sigma)",
            if c == 0 { "<k x^2>" } else { "<m v^2>" },
            (measured - want) / se,
            (measured - kt) / se
        );
        assert!(
            (measured - want).abs() <= 4.0 * se,
            "{name}: {measured} vs {want} +- {se}"
        );
    }
}

/// Velocity Verlet in a harmonic trap (k = m = 1, w dt = 0.1), every particle starting at
/// rest (no velocities input), so all oscillate in phase: the shadow energy
/// (1/2) m v^2 + (1/2) k x^2 (1 - (w dt)^2 / 4) stays constant to f32 rounding, the energy
/// (the graph's total_energy, kinetic plus the force law's potential) fluctuates by
/// (w dt)^2 / 4 of itself, and its drift over 6 periods stays far below that.
#[test]
fn velocity_verlet_conserves_energy() {
    let Some(gpu) = gpu() else { return };
    let (k, dt, n, steps) = (1.0, 0.1, 200usize, 400u64);
    let mut rng = Rng::new(23);
    let x0: Vec<f64> = (0..n * 3).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let setup = Setup {
        integrator: "velocity_verlet",
        params: format!(
            r#""dt": {dt}, "forces": "lib/forces/harmonic_trap.json", "forces.stiffness": {k}"#
        ),
        n,
        inertial: true,
        record: &["positions", "velocities", "total_energy"],
    };
    let out = setup.run(
        &gpu,
        &[("positions".to_string(), flat_particles(&x0, 3))].into(),
        steps,
        1,
    );
    let (x, v) = (states(&out, "positions"), states(&out, "velocities"));
    let eps = k * dt * dt / 4.0;
    let shadow: Vec<f64> = x
        .iter()
        .zip(&v)
        .map(|(x, v)| {
            0.5 * v.iter().map(|a| a * a).sum::<f64>()
                + 0.5 * k * (1.0 - eps) * x.iter().map(|a| a * a).sum::<f64>()
        })
        .collect();
    let shadow_change = shadow
        .iter()
        .map(|s| (s / shadow[0] - 1.0).abs())
        .fold(0.0, f64::max);
    // Frame t of total_energy: after step t + 1.
    let energy = out["total_energy_frames"].data.to_f64();
    let e0 = 0.5 * k * x0.iter().map(|a| a * a).sum::<f64>();
    let (lo, hi) = energy
        .iter()
        .fold((f64::MAX, f64::MIN), |(lo, hi), &e| (lo.min(e), hi.max(e)));
    let swing = (hi - lo) / e0;
    // One period is 2 pi / (w dt) = 63 steps: the mean energy over the first and the last.
    let period = (2.0 * PI / dt).round() as usize;
    let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
    let drift = (mean(&energy[energy.len() - period..]) - mean(&energy[..period])).abs() / e0;
    eprintln!(
        "velocity_verlet: shadow energy changes by {shadow_change:.2e}; energy swings by {swing:.4e} (expected (w dt)^2 / 4 = {eps:.4e}), drifts by {drift:.2e} over {steps} steps"
    );
    assert!(
        shadow_change <= 1e-5,
        "shadow energy changes by {shadow_change}"
    );
    assert!(
        (swing / eps - 1.0).abs() <= 0.05,
        "energy swings by {swing}, expected {eps}"
    );
    assert!(
        drift <= 0.02 * eps,
        "energy drifts by {drift} against a swing of {swing}"
    );
}

/// Free particles (no forces, the free mobility with radius 0.5 bound as mobility.radius):
/// every Brownian integrator's displacements against 2 kT mu dt per step and axis, from
/// the exact covariance of each scheme's increments (independent for Euler-Maruyama,
/// midpoint and Adams-Bashforth; Leimkuhler's are (W_n + W_(n-1)) / 2 with W_(-1) = 0);
/// the mean squared one-step increment and the mean squared displacement over the run,
/// each within 4 standard errors.
#[test]
fn free_particles_diffuse_with_kt_times_the_mobility() {
    let Some(gpu) = gpu() else { return };
    let (kt, dt, radius, n, steps) = (1.5, 0.1, 0.5, 1000usize, 20usize);
    let mu = 1.0 / (6.0 * PI * radius);
    let unit = 2.0 * kt * mu * dt;
    let mut rng = Rng::new(24);
    let x0: Vec<f64> = (0..n * 3).map(|_| rng.uniform(-5.0, 5.0)).collect();
    for (integrator, _) in BROWNIAN {
        let setup = Setup {
            integrator,
            params: format!(r#""dt": {dt}, "temperature": {kt}, "mobility.radius": {radius}"#),
            n,
            inertial: false,
            record: &["positions"],
        };
        let out = setup.run(
            &gpu,
            &[("positions".to_string(), flat_particles(&x0, 3))].into(),
            steps as u64,
            8,
        );
        let x = states(&out, "positions");
        // The increments' covariance in units of 2 kT mu dt.
        let mut c = vec![vec![0.0; steps]; steps];
        for i in 0..steps {
            if integrator == "leimkuhler" {
                c[i][i] = if i == 0 { 0.25 } else { 0.5 };
                if i + 1 < steps {
                    c[i][i + 1] = 0.25;
                    c[i + 1][i] = 0.25;
                }
            } else {
                c[i][i] = 1.0;
            }
        }
        let copies = (n * 3) as f64;
        let s = steps as f64;
        let trace: f64 = (0..steps).map(|i| c[i][i]).sum();
        let total: f64 = c.iter().flatten().sum();
        let squares: f64 = c.iter().flatten().map(|v| v * v).sum();
        let step_mean = x
            .windows(2)
            .flat_map(|w| w[1].iter().zip(&w[0]).map(|(a, b)| (a - b).powi(2)))
            .sum::<f64>()
            / (s * copies)
            / unit;
        let (step_want, step_se) = (trace / s, (2.0 * squares / (s * s * copies)).sqrt());
        let msd = x[steps]
            .iter()
            .zip(&x[0])
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            / copies
            / unit;
        let (msd_want, msd_se) = (total, (2.0 / copies).sqrt() * total);
        eprintln!(
            "{integrator}: one-step <dx^2> / (2 kT mu dt) = {step_mean:.4} against {step_want:.4} +- {step_se:.1e}; MSD / (2 kT mu dt) = {msd:.3} against {msd_want:.3} +- {msd_se:.2}"
        );
        assert!(
            (step_mean - step_want).abs() <= 4.0 * step_se,
            "{integrator}: one-step {step_mean} vs {step_want}"
        );
        assert!(
            (msd - msd_want).abs() <= 4.0 * msd_se,
            "{integrator}: MSD {msd} vs {msd_want}"
        );
    }
}

/// Euler-Maruyama and the midpoint scheme (three FCM evaluations a step, the two noises
/// at q from streams apart) with fcm.json as the mobility, bound as mobility.box and
/// mobility.tolerance: free particles in a periodic box diffuse with kT times the
/// periodic self-mobility, Hasimoto's hasimoto(a, L) / (6 pi eta a), 18 % below the bulk
/// value at a / L = 1/16. Relative standard error of the one-step estimate from the
/// independent particles and the Oseen correlation of pairs, sqrt((2 / n + 13.2 a^2 /
/// L^2) / steps) per axis (graphs/examples/colloids.json; the three axes' mean is held to
/// it too); 4 of them.
#[test]
fn brownian_integrators_with_fcm_diffuse_with_the_periodic_self_mobility() {
    let Some(gpu) = gpu() else { return };
    let (l, n, dt, kt, steps) = (16.0, 64usize, 0.05, 1.5, 100usize);
    let mut rng = Rng::new(25);
    let x0: Vec<f64> = (0..n * 3).map(|_| rng.uniform(-l / 2.0, l / 2.0)).collect();
    let periodic = kt * hasimoto(1.0, l) / (6.0 * PI);
    let bulk = kt / (6.0 * PI);
    let se = ((2.0 / n as f64 + 13.2 / (l * l)) / steps as f64).sqrt();
    for integrator in ["euler_maruyama", "midpoint"] {
        let setup = Setup {
            integrator,
            params: format!(
                r#""dt": {dt}, "temperature": {kt}, "mobility": "fcm.json", "mobility.box": [{l}, {l}, {l}], "mobility.tolerance": 0.01"#
            ),
            n,
            inertial: false,
            record: &["positions"],
        };
        let out = setup.run(
            &gpu,
            &[("positions".to_string(), flat_particles(&x0, 3))].into(),
            steps as u64,
            4,
        );
        let x = states(&out, "positions");
        let measured = x
            .windows(2)
            .flat_map(|w| w[1].iter().zip(&w[0]).map(|(a, b)| (a - b).powi(2)))
            .sum::<f64>()
            / (steps * n * 3) as f64
            / (2.0 * dt);
        eprintln!(
            "{integrator} + fcm.json: D = {measured:.5e} against kT mu_self = {periodic:.5e} ({:+.2} sigma; bulk kT / (6 pi eta a) {bulk:.5e}: {:+.2} sigma)",
            (measured / periodic - 1.0) / se,
            (measured / bulk - 1.0) / se
        );
        assert!(
            (measured / periodic - 1.0).abs() <= 4.0 * se,
            "{integrator}: D = {measured} vs {periodic} (relative standard error {se})"
        );
    }
}

/// Every Brownian integrator adds the mobility's drift output (kT div M), dt of it per
/// step: with a mobility of no noise and a constant drift d (a graph written here, beside
/// the wrapper), free particles move by exactly d T.
#[test]
fn brownian_integrators_add_the_mobility_drift() {
    let Some(gpu) = gpu() else { return };
    let dir = tmpdir("integrators-drift");
    write_graph(
        &dir,
        "drifting.json",
        r#"{"mesoflow": 1,
            "params": {"temperature": {"default": 0}, "noise_scale": {"default": 0}, "stream": {"default": 0, "integer": true},
                       "drift": {"default": [0.25, -0.5, 1.0]}},
            "inputs": {"positions": {"type": "particles", "cols": 3}, "forces": {"type": "particles", "cols": 3}},
            "nodes": [
              {"id": "velocities", "kind": "scale", "params": {"factor": 1}, "inputs": {"x": "inputs.forces"}},
              {"id": "noise", "kind": "constant", "params": {"value": 0}, "inputs": {"like": "inputs.positions"}},
              {"id": "drift", "kind": "offset_components", "params": {"offsets": "$drift"}, "inputs": {"x": "noise.out"}}
            ],
            "outputs": {"velocities": "velocities.out", "noise": "noise.out", "fluctuating_velocities": "velocities.out", "drift": "drift.out"}}"#,
    );
    let (dt, steps, n) = (0.1, 20u64, 16usize);
    let drift = [0.25, -0.5, 1.0];
    let mut rng = Rng::new(26);
    let x0: Vec<f64> = (0..n * 3).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let inputs: BTreeMap<String, HostArray> =
        [("positions".to_string(), flat_particles(&x0, 3))].into();
    for (integrator, _) in BROWNIAN {
        let setup = Setup {
            integrator,
            params: format!(r#""dt": {dt}, "temperature": 1, "mobility": "drifting.json""#),
            n,
            inertial: false,
            record: &[],
        };
        let path = write_graph(&dir, "run.json", &setup.json(steps));
        let g = load_for(&path, steps, 1);
        let out = run_cached(&gpu, &g, &inputs, None, steps, true).0;
        let x = out["positions"].data.to_f64();
        let worst = x
            .iter()
            .zip(&x0)
            .enumerate()
            .map(|(i, (x, x0))| (x - x0 - drift[i % 3] * dt * steps as f64).abs())
            .fold(0.0, f64::max);
        eprintln!("{integrator}: displacement off d T by at most {worst:.2e}");
        assert!(
            worst <= 1e-5,
            "{integrator}: displacement off d T by {worst}"
        );
    }
}

/// Every mobility graph fits the mobility interface: each Brownian integrator loads and
/// plans around each (with a param bound through the integrator), and the integrators
/// plan with their defaults.
#[test]
fn every_mobility_fits_every_brownian_integrator() {
    let dir = tmpdir("integrators-interface");
    let mobilities = [
        "lib/mobility/free.json",
        "fcm.json",
        "pse.json",
        "rpy_open.json",
        "rpy_wall.json",
        "dpstokes.json",
    ];
    for (integrator, _) in BROWNIAN {
        for mobility in mobilities {
            let setup = Setup {
                integrator,
                params: format!(r#""mobility": "{mobility}", "mobility.radius": 0.8"#),
                n: 50,
                inertial: false,
                record: &[],
            };
            let path = write_graph(&dir, "plan.json", &setup.json(1));
            if let Some(e) = load_or_plan_error(&path, BTreeMap::new()) {
                panic!("{integrator} with {mobility}:\n{e}");
            }
        }
    }
}

/// An integrator given a mobility without the drift output or the stream param, or a
/// force law without the energy output, is refused when the file loads, naming what is
/// missing.
#[test]
fn a_mobility_or_force_law_missing_a_port_is_refused_by_name() {
    let dir = tmpdir("integrators-wrong-interface");
    let free =
        std::fs::read_to_string(crate::util::root().join("graphs/lib/mobility/free.json")).unwrap();
    // free.json less its drift output (its last).
    let cut = free.find(",\n    \"drift\": {\"from\"").unwrap();
    let no_drift = format!("{}\n  }}\n}}\n", &free[..cut]);
    write_graph(&dir, "no_drift.json", &no_drift);
    // free.json without its stream param (drawing from stream 1).
    let line = free.find("    \"stream\": {").unwrap();
    let end = line + free[line..].find('\n').unwrap() + 1;
    let no_stream = format!("{}{}", &free[..line], &free[end..]).replace("\"= stream + 0\"", "1");
    write_graph(&dir, "no_stream.json", &no_stream);
    write_graph(
        &dir,
        "no_energy.json",
        r#"{"mesoflow": 1, "inputs": {"positions": {"type": "particles", "cols": 3}},
            "nodes": [{"id": "f", "kind": "scale", "params": {"factor": -1}, "inputs": {"x": "inputs.positions"}}],
            "outputs": {"forces": "f.out"}}"#,
    );
    for (integrator, params, missing) in [
        ("euler_maruyama", r#""mobility": "no_drift.json""#, "drift"),
        ("midpoint", r#""mobility": "no_drift.json""#, "drift"),
        ("leimkuhler", r#""mobility": "no_stream.json""#, "stream"),
        ("euler_maruyama", r#""forces": "no_energy.json""#, "energy"),
        ("velocity_verlet", r#""forces": "no_energy.json""#, "energy"),
    ] {
        let setup = Setup {
            integrator,
            params: params.to_string(),
            n: 10,
            inertial: integrator == "velocity_verlet",
            record: &[],
        };
        let path = write_graph(&dir, "wrong.json", &setup.json(1));
        let e = load_or_plan_error(&path, BTreeMap::new())
            .unwrap_or_else(|| panic!("{integrator} with {params} loaded and planned"));
        eprintln!("{integrator} with {params}: {e}");
        assert!(
            e.contains(&format!("`{missing}`")) && e.lines().count() <= 4,
            "{integrator} with {params}: {e}"
        );
    }
}
