//! graphs/poisson.json against physics: an f64 Ewald sum of Gaussian charges written here
//! (real-space lattice sum with erf, Fourier sum, the uniform background), itself checked
//! against the free-space pair closed form erf(r / 2a) / (4 pi eps r) (digest 13.3 #23);
//! random neutral and non-neutral systems; a pair in a large box against the closed form
//! (with the leading periodic correction of a dipole); independence of the split (and
//! unsplit); a rock-salt crystal's Madelung energy; the near-field pair kernel against a
//! brute-force f64 sum; pruning of the field work when only potentials are asked for.

use std::collections::BTreeMap;
use std::f64::consts::PI;

use mesoflow::graph::Graph;
use mesoflow::value::HostArray;

use crate::util::{
    Rng, flat_particles, gpu, load_with, particles, plan_graph, run_cached, types_of,
};

/// Free-space potential of a unit Gaussian charge (standard deviation a) averaged over
/// another's cloud, at distance r: erf(r / 2a) / (4 pi eps r), and its r-derivative.
fn pair_closed_form(r: f64, a: f64, eps: f64) -> (f64, f64) {
    let c = 2.0 * a;
    let e = libm::erf(r / c);
    let phi = e / (4.0 * PI * eps * r);
    let dphi =
        (2.0 / (PI.sqrt() * c) * (-(r / c).powi(2)).exp() / r - e / (r * r)) / (4.0 * PI * eps);
    (phi, dphi)
}

/// Potentials (N), fields (N x 3) and energy of Gaussian charges of width `a` in a periodic
/// box, the k = 0 mode of the potential zero, each charge's own cloud included, by Ewald
/// summation in f64 at an Ewald width g (the real-space part uses erf(r/2a) - erf(r/2g)).
struct Ewald {
    potentials: Vec<f64>,
    fields: Vec<[f64; 3]>,
    energy: f64,
}

fn ewald(pos: &[[f64; 3]], q: &[f64], a: f64, eps: f64, l: [f64; 3]) -> Ewald {
    let n = pos.len();
    let lmin = l.iter().cloned().fold(f64::INFINITY, f64::min);
    let g = (lmin / 10.0).max(1.5 * a);
    let volume = l[0] * l[1] * l[2];
    let mut potentials = vec![0.0; n];
    let mut fields = vec![[0.0; 3]; n];
    // Real space: images within 12 g (erfc(6) ~ 2e-17).
    let reach = 12.0 * g;
    let images: [i64; 3] = [0, 1, 2].map(|d| (reach / l[d]).ceil() as i64 + 1);
    let near = |r: f64| -> (f64, f64) {
        let (p1, d1) = pair_closed_form(r, a, eps);
        let (p2, d2) = pair_closed_form(r, g, eps);
        (p1 - p2, d1 - d2)
    };
    for i in 0..n {
        for j in 0..n {
            for nx in -images[0]..=images[0] {
                for ny in -images[1]..=images[1] {
                    for nz in -images[2]..=images[2] {
                        let r = [
                            pos[i][0] - pos[j][0] + nx as f64 * l[0],
                            pos[i][1] - pos[j][1] + ny as f64 * l[1],
                            pos[i][2] - pos[j][2] + nz as f64 * l[2],
                        ];
                        let d = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
                        if d > reach {
                            continue;
                        }
                        if d < 1e-12 {
                            potentials[i] +=
                                q[j] * (1.0 / a - 1.0 / g) / (4.0 * PI.powf(1.5) * eps);
                            continue;
                        }
                        let (p, dp) = near(d);
                        potentials[i] += q[j] * p;
                        for c in 0..3 {
                            fields[i][c] -= q[j] * dp * r[c] / d;
                        }
                    }
                }
            }
        }
    }
    // Fourier space: exp(-k^2 g^2) / (eps V k^2) per mode, up to |k| g = 6.5.
    let kmax = 6.5 / g;
    let m: [i64; 3] = [0, 1, 2].map(|d| (kmax * l[d] / (2.0 * PI)).ceil() as i64);
    for mx in -m[0]..=m[0] {
        for my in -m[1]..=m[1] {
            for mz in -m[2]..=m[2] {
                if mx == 0 && my == 0 && mz == 0 {
                    continue;
                }
                let k = [
                    2.0 * PI * mx as f64 / l[0],
                    2.0 * PI * my as f64 / l[1],
                    2.0 * PI * mz as f64 / l[2],
                ];
                let k2 = k[0] * k[0] + k[1] * k[1] + k[2] * k[2];
                if k2.sqrt() > kmax {
                    continue;
                }
                let w = (-k2 * g * g).exp() / (eps * volume * k2);
                // S(k) = sum_j q_j exp(-i k x_j).
                let (mut sr, mut si) = (0.0, 0.0);
                for j in 0..n {
                    let ph = k[0] * pos[j][0] + k[1] * pos[j][1] + k[2] * pos[j][2];
                    sr += q[j] * ph.cos();
                    si -= q[j] * ph.sin();
                }
                for i in 0..n {
                    let ph = k[0] * pos[i][0] + k[1] * pos[i][1] + k[2] * pos[i][2];
                    let (c, s) = (ph.cos(), ph.sin());
                    // Re[exp(i k x_i) S] and its gradient's negative Im part.
                    potentials[i] += w * (c * sr - s * si);
                    let im = s * sr + c * si;
                    for d in 0..3 {
                        fields[i][d] += w * k[d] * im;
                    }
                }
            }
        }
    }
    // The real-space kernel's mean, (g^2 - a^2) / eps per unit charge over the box.
    let total: f64 = q.iter().sum();
    for p in potentials.iter_mut() {
        *p -= total * (g * g - a * a) / (eps * volume);
    }
    let energy = 0.5 * q.iter().zip(&potentials).map(|(q, p)| q * p).sum::<f64>();
    Ewald {
        potentials,
        fields,
        energy,
    }
}

/// The reference sum reproduces the closed form of a pair in a large box (digest 13.3
/// #23: 0.04142006 at r = 1 for a = eps = 1) with the leading correction of a periodic
/// neutral pair, -p^2 / (6 eps V) in the energy.
#[test]
fn the_reference_ewald_sum_matches_the_closed_form() {
    for (r, want) in [
        (0.5, 0.04397871),
        (1.0, 0.04142006),
        (2.0, 0.03353000),
        (4.0, 0.01980131),
        (8.0, 0.00994718),
    ] {
        let (phi, _) = pair_closed_form(r, 1.0, 1.0);
        assert!((phi - want).abs() < 1e-8, "U({r}) = {phi}, want {want}");
    }
    let l: f64 = 48.0;
    for r in [1.0, 4.0] {
        let e = ewald(&[[0.0; 3], [r, 0.0, 0.0]], &[1.0, -1.0], 1.0, 1.0, [l; 3]);
        let self_energy = 2.0 / (8.0 * PI.powf(1.5));
        let (phi, dphi) = pair_closed_form(r, 1.0, 1.0);
        let want = -phi - r * r / (6.0 * l.powi(3));
        let got = e.energy - self_energy;
        // Past the dipole's term, the periodic images differ from the free pair by
        // O((r / L)^4) relative: 1.3e-5 at r = 4, L = 48.
        assert!(
            (got - want).abs() < 3e-5 * want.abs(),
            "r = {r}: {got} vs {want}"
        );
        // The field at the negative charge from the positive one: -dphi along +x, plus
        // the periodic dipole's uniform field M / (3 eps V), M = sum Q x = -r x^.
        let want_e = -dphi - r / (3.0 * l.powi(3));
        let off = (e.fields[1][0] - want_e).abs() / want_e.abs();
        assert!(off < 1e-4, "{} vs {want_e}", e.fields[1][0]);
        // What is left is the images' O((r / L)^4) terms: doubling the box divides it by
        // at least 16 (a wrong dipole term would leave (r / L)^3: 8).
        let far = ewald(
            &[[0.0; 3], [r, 0.0, 0.0]],
            &[1.0, -1.0],
            1.0,
            1.0,
            [2.0 * l; 3],
        );
        let want_far = -dphi - r / (3.0 * (2.0 * l).powi(3));
        let off_far = (far.fields[1][0] - want_far).abs() / want_far.abs();
        assert!(
            off_far < off / 16.0 + 1e-9,
            "r = {r}: {off_far:e} at 2L after {off:e} at L"
        );
    }
}

fn load(sets: &[(&str, String)]) -> Graph {
    let sets: Vec<(&str, &str)> = sets.iter().map(|(k, v)| (*k, v.as_str())).collect();
    load_with("poisson.json", &sets, 1, 0)
}

fn inputs(pos: &[[f64; 3]], q: &[f64]) -> BTreeMap<String, HostArray> {
    let mut m = BTreeMap::new();
    m.insert("positions".to_string(), particles(pos));
    m.insert("charges".to_string(), flat_particles(q, 1));
    m
}

/// Runs poisson.json for the named outputs: (potentials, fields, energy) where asked.
fn solve(g: &Graph, pos: &[[f64; 3]], q: &[f64], outputs: &[&str]) -> BTreeMap<String, Vec<f64>> {
    let gpu = gpu().expect("a GPU");
    let (out, _) = run_cached(&gpu, g, &inputs(pos, q), Some(outputs), 1, true);
    out.into_iter().map(|(k, v)| (k, v.to_ref().data)).collect()
}

fn param(g: &Graph, name: &str) -> String {
    g.params
        .iter()
        .find(|p| p.name == name)
        .map(|p| p.value.to_string())
        .unwrap_or_default()
}

/// The largest error over the charges relative to the largest reference magnitude.
fn rel_err(got: &[f64], want: &[f64]) -> f64 {
    let scale = want.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    got.iter()
        .zip(want)
        .fold(0.0f64, |m, (g, w)| m.max((g - w).abs()))
        / scale
}

fn random_system(rng: &mut Rng, n: usize, l: [f64; 3], neutral: bool) -> (Vec<[f64; 3]>, Vec<f64>) {
    let pos: Vec<[f64; 3]> = (0..n)
        .map(|_| [0, 1, 2].map(|d| rng.uniform(-0.5, 0.5) * l[d]))
        .collect();
    let mut q: Vec<f64> = (0..n).map(|_| rng.uniform(-1.0, 1.0)).collect();
    if neutral {
        let mean = q.iter().sum::<f64>() / n as f64;
        q.iter_mut().for_each(|x| *x -= mean);
    }
    (pos, q)
}

fn check_against_ewald(
    sets: &[(&str, String)],
    l: [f64; 3],
    a: f64,
    n: usize,
    neutral: bool,
    seed: u64,
    tol: f64,
) {
    if gpu().is_none() {
        return;
    }
    let g = load(sets);
    let mut rng = Rng::new(seed);
    let (pos, q) = random_system(&mut rng, n, l, neutral);
    let out = solve(&g, &pos, &q, &["potentials", "fields", "forces", "energy"]);
    let want = ewald(&pos, &q, a, 1.0, l);
    let e_pot = rel_err(&out["potentials"], &want.potentials);
    let flat: Vec<f64> = want.fields.iter().flatten().cloned().collect();
    let e_field = rel_err(&out["fields"], &flat);
    let forces: Vec<f64> = want
        .fields
        .iter()
        .zip(&q)
        .flat_map(|(e, q)| e.map(|x| q * x))
        .collect();
    let e_force = rel_err(&out["forces"], &forces);
    let energy = out["energy"][0];
    // The energy relative to the sum of |Q_i phi_i| / 2 (the self energies dominate it).
    let scale: f64 = 0.5
        * q.iter()
            .zip(&want.potentials)
            .map(|(q, p)| (q * p).abs())
            .sum::<f64>();
    let e_energy = (energy - want.energy).abs() / scale;
    eprintln!(
        "poisson {sets:?} box {l:?}: split {} grid {} support {} cutoff {}: potentials {e_pot:.2e} fields {e_field:.2e} forces {e_force:.2e} energy {e_energy:.2e}",
        param(&g, "split"),
        param(&g, "grid"),
        param(&g, "support"),
        param(&g, "cutoff")
    );
    for (what, e) in [
        ("potentials", e_pot),
        ("fields", e_field),
        ("forces", e_force),
        ("energy", e_energy),
    ] {
        assert!(
            e <= tol,
            "{what}: relative error {e:.3e} over {tol:e} ({sets:?}, box {l:?})"
        );
    }
}

/// Random neutral systems against the Ewald sum, at the default split, in a cubic and an
/// elongated box, at two tolerances.
#[test]
fn random_neutral_systems_match_the_ewald_sum() {
    let s = |t: f64, l: [f64; 3]| vec![("tolerance", format!("{t}")), ("box", format!("{l:?}"))];
    check_against_ewald(&s(1e-3, [16.0; 3]), [16.0; 3], 1.0, 24, true, 3, 1e-3);
    check_against_ewald(&s(1e-4, [16.0; 3]), [16.0; 3], 1.0, 24, true, 4, 1e-4);
    check_against_ewald(
        &s(1e-3, [12.0, 16.0, 20.0]),
        [12.0, 16.0, 20.0],
        1.0,
        20,
        true,
        5,
        1e-3,
    );
}

/// A non-neutral system follows the uniform-background convention at every split: the
/// same potentials split, unsplit and in the reference.
#[test]
fn non_neutral_systems_follow_the_background_convention() {
    let l = [16.0; 3];
    for split in ["0", "0.7"] {
        let sets = vec![
            ("tolerance", "0.001".to_string()),
            ("box", format!("{l:?}")),
            ("split", split.to_string()),
        ];
        check_against_ewald(&sets, l, 1.0, 12, false, 6, 1e-3);
    }
}

/// The split moves work between the grid and the neighbour sums, nothing else: unsplit
/// and two splits agree within the tolerance.
#[test]
fn results_do_not_depend_on_the_split() {
    if gpu().is_none() {
        return;
    }
    let l = [20.0; 3];
    let mut rng = Rng::new(8);
    let (pos, q) = random_system(&mut rng, 16, l, true);
    let runs: Vec<BTreeMap<String, Vec<f64>>> = ["0", "0.5", "1.2"]
        .iter()
        .map(|s| {
            let g = load(&[
                ("box", format!("{l:?}")),
                ("split", s.to_string()),
                ("tolerance", "0.0001".into()),
            ]);
            solve(&g, &pos, &q, &["potentials", "fields", "energy"])
        })
        .collect();
    for other in &runs[1..] {
        for what in ["potentials", "fields", "energy"] {
            let e = rel_err(&other[what], &runs[0][what]);
            assert!(e <= 2e-4, "{what} differ by {e:.3e} between splits");
        }
    }
}

/// Two opposite charges in a large box: the pair energy and the force against
/// erf(r / 2a) / (4 pi eps r) with the periodic dipole's correction (digest 13.3 #23), at
/// distances where the images' further terms, O((r / L)^4), are far below the tolerance;
/// at two tolerances and splits (unsplit and split).
#[test]
fn a_pair_in_a_large_box_matches_the_closed_form() {
    if gpu().is_none() {
        return;
    }
    let l: f64 = 48.0;
    for (tol, split) in [(1e-3, "0"), (1e-3, "0.5"), (1e-4, "0.6")] {
        let g = load(&[
            ("box", format!("[{l}, {l}, {l}]")),
            ("tolerance", format!("{tol}")),
            ("split", split.into()),
        ]);
        for r in [0.5, 2.0, 4.0] {
            let pos = [[-0.3, 0.2, 0.1], [-0.3 + r, 0.2, 0.1]];
            let out = solve(&g, &pos, &[1.0, -1.0], &["energy", "forces"]);
            let (phi, dphi) = pair_closed_form(r, 1.0, 1.0);
            let self_energy = 2.0 / (8.0 * PI.powf(1.5));
            let want = -phi - r * r / (6.0 * l.powi(3));
            let got = out["energy"][0] - self_energy;
            // Force on the negative charge (Q = -1): -E, E = -dphi - r / (3 eps V) along x.
            let want_f = dphi + r / (3.0 * l.powi(3));
            let got_f = out["forces"][3];
            let (e_u, e_f) = (
                (got - want).abs() / phi,
                (got_f - want_f).abs() / dphi.abs(),
            );
            eprintln!(
                "pair at {r}, tolerance {tol} (split {}, grid {}, support {}): energy {e_u:.2e}, force {e_f:.2e}",
                param(&g, "split"),
                param(&g, "grid"),
                param(&g, "support"),
            );
            assert!(
                e_u <= tol,
                "r = {r}: pair energy {got:.8e}, closed form {want:.8e}"
            );
            assert!(
                e_f <= tol,
                "r = {r}: force {got_f:.8e}, closed form {want_f:.8e}"
            );
        }
    }
}

/// A rock-salt crystal of narrow charges: the energy per ion pair, less the self energies
/// 2 Q^2 / (8 pi^(3/2) eps a), is the Madelung energy -1.747565 Q^2 / (4 pi eps d)
/// (digest 13.3 #27 says "per ion": the Madelung constant gives the potential at an ion,
/// -M Q / (4 pi eps d), so the energy per ion is half of it).
#[test]
fn a_rock_salt_crystal_has_the_madelung_energy() {
    if gpu().is_none() {
        return;
    }
    let (d, a, cells) = (2.0, 0.25, 2usize);
    let side = 2.0 * d * cells as f64;
    let shift = [0.37, -0.21, 0.13];
    let mut pos = Vec::new();
    let mut q = Vec::new();
    let per = 2 * cells;
    for i in 0..per {
        for j in 0..per {
            for k in 0..per {
                pos.push([i, j, k].map(|x| x as f64 * d - side / 2.0).map(|x| x));
                let p = pos.last_mut().unwrap();
                for c in 0..3 {
                    p[c] += shift[c];
                }
                q.push(if (i + j + k) % 2 == 0 { 1.0 } else { -1.0 });
            }
        }
    }
    let tol = 1e-4;
    let g = load(&[
        ("box", format!("[{side}, {side}, {side}]")),
        ("width", format!("{a}")),
        ("tolerance", format!("{tol}")),
    ]);
    let out = solve(&g, &pos, &q, &["energy"]);
    let n = q.len() as f64;
    let self_energy = 1.0 / (8.0 * PI.powf(1.5) * a);
    let madelung = -1.747565 / (4.0 * PI * d);
    let got = 2.0 * (out["energy"][0] / n - self_energy);
    eprintln!(
        "rock salt: {got:.7e} per ion pair, Madelung {madelung:.7e} (split {}, grid {})",
        param(&g, "split"),
        param(&g, "grid")
    );
    assert!(
        (got - madelung).abs() <= 2.0 * tol * self_energy,
        "energy per ion pair less self {got:.7e}, Madelung {madelung:.7e}"
    );
}

/// The launch lines of a plan's text ("  3. id (kind)"), without the graph's doc.
fn launches(g: &Graph, plan: &mesoflow::plan::Plan) -> String {
    mesoflow::plan::to_text(g, plan)
        .lines()
        .filter(|l| {
            let t = l.trim_start();
            t.split_once(". ")
                .is_some_and(|(n, _)| n.parse::<u32>().is_ok())
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// Asking for potentials alone runs no field work: no field Green function, no field
/// interpolation, no near-field field sum.
#[test]
fn potentials_alone_run_no_field_work() {
    let caps = mesoflow::gpu::DeviceCaps::baseline();
    let g = load(&[("box", "[16, 16, 16]".into()), ("split", "0.7".into())]);
    let pos = [[0.0; 3], [1.0, 0.0, 0.0]];
    let types = types_of(&inputs(&pos, &[1.0, -1.0]));
    let plan = plan_graph(&caps, &g, types.clone(), Some(&["potentials"]), true);
    let text = launches(&g, &plan);
    for absent in [
        "field_spectrum",
        "electric_field",
        "far_fields",
        "near_fields",
    ] {
        assert!(
            !text.contains(absent),
            "{absent} planned for potentials alone:\n{text}"
        );
    }
    assert!(text.contains("near_potentials"), "{text}");
    let plan = plan_graph(&caps, &g, types, Some(&["forces"]), true);
    let text = launches(&g, &plan);
    assert!(
        text.contains("far_fields") && !text.contains("far_potentials"),
        "{text}"
    );
}

/// Unsplit, the near field is left out and the grid resolves the charges themselves.
#[test]
fn unsplit_runs_without_a_near_field() {
    let caps = mesoflow::gpu::DeviceCaps::baseline();
    let g = load(&[("box", "[16, 16, 16]".into()), ("split", "0".into())]);
    let types = types_of(&inputs(&[[0.0; 3]], &[1.0]));
    let text = launches(&g, &plan_graph(&caps, &g, types, None, true));
    assert!(
        !text.contains("near_potentials") && !text.contains("near_fields"),
        "{text}"
    );
    assert_eq!(param(&g, "cutoff"), "0");
}

/// Bad params are named: a negative width, a split whose near field passes half the
/// box.
#[test]
fn bad_poisson_params_are_named() {
    let e = crate::util::load_error("poisson.json", &[("width", "-1")]);
    assert!(e.contains("width"), "{e}");
    let e = crate::util::load_error("poisson.json", &[("box", "[8, 8, 8]"), ("split", "0.05")]);
    assert!(e.contains("half the smallest box length"), "{e}");
}

/// A neutral system of charged soft spheres on a jittered lattice: positions, velocities
/// and charges for md_charged.json.
pub fn charged_lattice(
    per_side: usize,
    spacing: f64,
    seed: u64,
) -> (Vec<[f64; 3]>, Vec<[f64; 3]>, Vec<f64>) {
    let mut rng = Rng::new(seed);
    let side = spacing * per_side as f64;
    let mut x = Vec::new();
    let mut v = Vec::new();
    let mut q = Vec::new();
    for i in 0..per_side {
        for j in 0..per_side {
            for k in 0..per_side {
                x.push(
                    [i, j, k]
                        .map(|c| (c as f64 + 0.5) * spacing - side / 2.0 + rng.uniform(-0.2, 0.2)),
                );
                v.push([0, 1, 2].map(|_| rng.uniform(-1.0, 1.0)));
                q.push(if (i + j + k) % 2 == 0 { 1.0 } else { -1.0 });
            }
        }
    }
    // No net momentum.
    let n = v.len() as f64;
    let mean: [f64; 3] = [0, 1, 2].map(|c| v.iter().map(|r| r[c]).sum::<f64>() / n);
    for r in v.iter_mut() {
        for c in 0..3 {
            r[c] -= mean[c];
        }
    }
    (x, v, q)
}

/// md_charged.json conserves energy: velocity Verlet with the Poisson forces and the WCA
/// repulsion, the total energy's drift and fluctuation over the run small against the
/// kinetic energy, and of second order in dt (half the step, a quarter of the error).
#[test]
fn molecular_dynamics_conserves_energy() {
    let Some(gpu) = gpu() else { return };
    let (x, v, q) = charged_lattice(4, 2.5, 12);
    let mut data = inputs(&x, &q);
    data.insert("velocities".into(), particles(&v));
    let kinetic: f64 = 0.5 * v.iter().flatten().map(|c| c * c).sum::<f64>();
    let mut spread = Vec::new();
    for (dt, steps) in [(0.02, 200u64), (0.01, 400)] {
        let g = load_with(
            "md_charged.json",
            &[
                ("box", "[10, 10, 10]"),
                ("dt", &format!("{dt}")),
                ("width", "0.5"),
                ("wca_sigma", "1.2"),
            ],
            steps,
            0,
        );
        let (out, _) = run_cached(
            &gpu,
            &g,
            &data,
            Some(&["energies", "kinetic_energy"]),
            steps,
            true,
        );
        let e = out["energies"].to_ref().data;
        let (lo, hi) = e
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            });
        let drift = (e[e.len() - 1] - e[0]).abs();
        eprintln!(
            "md dt {dt}: energy {:.6} .. {:.6} (spread {:.3e}, drift {:.3e}) kinetic {:.4} (initial {kinetic:.4})",
            lo,
            hi,
            hi - lo,
            drift,
            out["kinetic_energy"].to_ref().data[0]
        );
        assert!(
            hi - lo < 2e-3 * kinetic,
            "dt {dt}: energy spread {:.3e}",
            hi - lo
        );
        spread.push(hi - lo);
    }
    assert!(spread[1] < 0.5 * spread[0], "second order: {spread:?}");
}
