//! Viscosity: SRD's from Poiseuille flow between plates and from Kolmogorov flow against
//! kinetic theory, MPCD-BC's against the source's measured value.

use crate::util::mpcd::{run_graph_file, run_mpcd};
use crate::util::{gpu, scalar};

/// SRD kinematic viscosity in 3D from kinetic theory (kinetic + collisional parts; Kikuchi
/// et al. J. Chem. Phys. 119, 6388 (2003); Gompper et al., Adv. Polym. Sci. 221 (2009),
/// Table 1), with gamma = M - 1 + e^-M for Poisson-distributed cell occupancies.
fn srd_viscosity_3d(
    m_per_cell: f64,
    kt: f64,
    mass: f64,
    dt: f64,
    a: f64,
    angle_deg: f64,
) -> (f64, f64) {
    let g = m_per_cell - 1.0 + (-m_per_cell).exp();
    let al = angle_deg.to_radians();
    let kinetic = kt * dt / (2.0 * mass)
        * (5.0 * m_per_cell / (g * (2.0 - al.cos() - (2.0 * al).cos())) - 1.0);
    let collisional = a * a / (18.0 * dt) * (g / m_per_cell) * (1.0 - al.cos());
    (kinetic, collisional)
}

#[test]
fn srd_formula_spot_value() {
    // The digest's spot value (B.4): M = 10, 130 degrees, dt = 0.1: 0.0486 + 0.8214.
    let (k, c) = srd_viscosity_3d(10.0, 1.0, 1.0, 0.1, 1.0, 130.0);
    assert!(
        (k - 0.0486).abs() < 5e-5 && (c - 0.8214).abs() < 5e-5,
        "{k} {c}"
    );
}

/// SRD kinematic viscosity in 2D (same sources): rotations by +-angle.
fn srd_viscosity_2d(
    m_per_cell: f64,
    kt: f64,
    mass: f64,
    dt: f64,
    a: f64,
    angle_deg: f64,
) -> (f64, f64) {
    let g = m_per_cell - 1.0 + (-m_per_cell).exp();
    let al = angle_deg.to_radians();
    let kinetic = kt * dt / (2.0 * mass) * (m_per_cell / (g * al.sin().powi(2)) - 1.0);
    let collisional = a * a / (12.0 * dt) * (g / m_per_cell) * (1.0 - al.cos());
    (kinetic, collisional)
}

/// Runs a Poiseuille flow between plates (the last axis, gap `h`) with body force `force`
/// along x and checks the profile and the viscosity from its curvature against kinetic
/// theory (`theory` of (M, measured kT)).
fn check_poiseuille(
    graph: &str,
    box_len: &str,
    h: f64,
    force: f64,
    density: f64,
    theory: fn(f64, f64) -> (f64, f64),
) {
    let d = format!("{density}");
    let f = format!("{force}");
    let bins = format!("{}", 2.0 * h);
    let out = run_graph_file(
        graph,
        &[
            ("box", box_len),
            ("walls", "\"plates\""),
            ("force", &f),
            ("density", &d),
            ("profile_bins", &bins),
            ("warmup", "600"),
        ],
        6600,
        1,
        &["velocity_profile", "temperature"],
    );
    let u = out["velocity_profile"].data.to_f64();
    let kt = scalar(&out["temperature"]);
    let nb = u.len();
    let z: Vec<f64> = (0..nb)
        .map(|i| (i as f64 + 0.5) / nb as f64 * h - h / 2.0)
        .collect();
    // Least squares u = c0 + c2 z^2 over every bin (the offset takes the slip).
    let n = nb as f64;
    let sx: f64 = z.iter().map(|z| z * z).sum();
    let sxx: f64 = z.iter().map(|z| z.powi(4)).sum();
    let sy: f64 = u.iter().sum();
    let sxy: f64 = z.iter().zip(&u).map(|(z, u)| z * z * u).sum();
    let c2 = (n * sxy - sx * sy) / (n * sxx - sx * sx);
    let c0 = (sy - c2 * sx) / n;
    let nu = -force / (2.0 * c2);
    // The viscous heating of the unthermostatted run raises kT by ~10-15%; the kinetic
    // part (4-8% of nu here) scales with kT, so the theory takes the measured kT.
    let (kin, coll) = theory(density, kt);
    let nu_theory = kin + coll;
    let slip = c0 + c2 * h * h / 4.0;
    let wall_shear = -2.0 * c2 * h / 2.0;
    let worst = z
        .iter()
        .zip(&u)
        .map(|(z, u)| (u - c0 - c2 * z * z).abs())
        .fold(0.0, f64::max);
    eprintln!(
        "Poiseuille {graph} box {box_len} M = {density}: nu {nu:.4} vs theory {nu_theory:.4} ({kin:.4} + {coll:.4} at kT {kt:.4}): {:+.2}%; u_max {c0:.4}, slip {slip:.4} (slip length {:.3} a), largest residual {worst:.4}",
        100.0 * (nu / nu_theory - 1.0),
        slip / wall_shear
    );
    // Parabolic: residuals of the two-parameter fit within 3% of u_max (measured ~1.5%:
    // thermal noise of the profile; a plug or a kinked profile leaves 10% or more).
    assert!(
        worst < 0.03 * c0,
        "M = {density}: residual {worst} of u_max {c0}: {u:?}"
    );
    // Viscosity within 5% of kinetic theory: seeds scatter by ~1% (1 sigma) at these sizes
    // and the measured values sit 1-3% above theory (walls, a gap of 10-12 cells).
    assert!(
        (nu / nu_theory - 1.0).abs() < 0.05,
        "M = {density}: nu {nu} vs theory {nu_theory}"
    );
    // Nearly no slip (virtual particles): slip length below 0.4 a, measured 0.16-0.23 a;
    // without them it is ~0.8 a (3D, M = 10, measured).
    assert!(slip.abs() < 0.4 * wall_shear, "M = {density}: slip {slip}");
}

#[test]
fn poiseuille_flow_between_plates_is_parabolic_with_the_srd_viscosity() {
    if gpu().is_none() {
        return;
    }
    // 3D: plates at z = +-5 (bounce-back, random shift, virtual particles in the cut
    // cells), periodic 8 x 8 in x and y, F = 0.03: u(z) = F/(2 nu m) (H^2/4 - z^2) plus a
    // small slip, u_max ~ 0.45 (Mach ~ 0.35). 6000 steps of dt = 0.1 after 600 of start-up
    // (the slowest shear mode decays in H^2 / (pi^2 nu) ~ 130 steps). About 13 s (M = 5)
    // and 16 s (M = 10) on lavapipe.
    for density in [5.0, 10.0] {
        check_poiseuille("mpcd.json", "[8, 8, 10]", 10.0, 0.03, density, |m, kt| {
            srd_viscosity_3d(m, kt, 1.0, 0.1, 1.0, 130.0)
        });
    }
    // 2D: plates at y = +-6, periodic in x (24 cells), F = 0.02 (u_max ~ 0.3); 11 s.
    check_poiseuille("mpcd2d.json", "[24, 12]", 12.0, 0.02, 10.0, |m, kt| {
        srd_viscosity_2d(m, kt, 1.0, 0.1, 1.0, 130.0)
    });
}

/// MPCD-BC in 2D against the source's measured viscosity (S2 Table 2.1, digest V2: A = 0.02,
/// M = 5, tau = 0.2, Hecht thermostat c = 0.3; measured 1.70 = Ihle's analytic value) from
/// Kolmogorov flow: u_x(y) = V sin(k y), nu = F / (V k^2). A smaller box (20 x 60 instead of
/// 60 x 80) and 2e4 steps instead of 5e5: about 75 s on lavapipe (CI stays under 11
/// minutes with it). Measured 2026-12-01 on lavapipe: nu = 1.672 (-1.6%; 1.769 with seed 0
/// from the command line).
#[test]
fn biased_collisions_reproduce_the_measured_2d_viscosity() {
    if gpu().is_none() {
        return;
    }
    let (l, force) = (60.0, 0.00093);
    let out = run_graph_file(
        "mpcd2d.json",
        &[
            ("box", "[20, 60]"),
            ("density", "5"),
            ("dt", "0.2"),
            ("rule", "\"biased\""),
            ("acceptance", "0.02"),
            ("force", "0.00093"),
            ("force_shape", "\"sine\""),
            ("thermostat", "\"monte_carlo\""),
            ("profile_bins", "60"),
            ("warmup", "1500"),
        ],
        21_500,
        1,
        &["velocity_profile", "temperature"],
    );
    let u = out["velocity_profile"].data.to_f64();
    let k = 2.0 * std::f64::consts::PI / l;
    let nb = u.len() as f64;
    let amplitude: f64 = u
        .iter()
        .enumerate()
        .map(|(i, u)| 2.0 * u * (k * ((i as f64 + 0.5) / nb * l - l / 2.0)).sin() / nb)
        .sum();
    let nu = force / (amplitude * k * k);
    let kt = scalar(&out["temperature"]);
    eprintln!("MPCD-BC 2D: V = {amplitude:.5}, nu = {nu:.4} (source: 1.70), kT {kt:.4}");
    // Statistical error of V over ~75 relaxation times of the mode: ~4%; plus the smaller
    // box (the source finds nu rising with the box width up to L = 60): 10% in all.
    assert!((nu / 1.70 - 1.0).abs() < 0.1, "nu {nu}");
    assert!((kt - 1.0).abs() < 0.01, "kT {kt}");
}

#[test]
fn kolmogorov_flow_gives_the_srd_viscosity() {
    if gpu().is_none() {
        return;
    }
    // Periodic box 6 x 6 x 16, force F sin(k z) along x (k = 2 pi / 16): u_x = V sin(k z)
    // with V = F / (nu k^2) ~ 0.3; the Monte-Carlo cell thermostat removes the viscous heat
    // (kT would double over the run without it). 4000 samples after 400 steps (the mode
    // relaxes in 1 / (nu k^2) ~ 75 steps): about 13 s on lavapipe.
    let (l, force) = (16.0, 0.04);
    let out = run_mpcd(
        &[
            ("box", "[6, 6, 16]"),
            ("force", "0.04"),
            ("force_shape", "\"sine\""),
            ("thermostat", "\"monte_carlo\""),
            ("profile_bins", "32"),
            ("warmup", "400"),
        ],
        4400,
        1,
        &["velocity_profile", "temperature"],
    );
    let u = out["velocity_profile"].data.to_f64();
    let kt = scalar(&out["temperature"]);
    let k = 2.0 * std::f64::consts::PI / l;
    let nb = u.len() as f64;
    let z = |i: usize| (i as f64 + 0.5) / nb * l - l / 2.0;
    let sine: f64 = u
        .iter()
        .enumerate()
        .map(|(i, u)| 2.0 * u * (k * z(i)).sin() / nb)
        .sum();
    let cosine: f64 = u
        .iter()
        .enumerate()
        .map(|(i, u)| 2.0 * u * (k * z(i)).cos() / nb)
        .sum();
    let nu = force / (sine * k * k);
    let (kin, coll) = srd_viscosity_3d(10.0, kt, 1.0, 0.1, 1.0, 130.0);
    eprintln!(
        "Kolmogorov: V {sine:.5} (cosine part {cosine:.5}), nu {nu:.4} vs theory {:.4} at kT {kt:.4}: {:+.2}%",
        kin + coll,
        100.0 * (nu / (kin + coll) - 1.0)
    );
    // The profile is the forced mode: no cosine part beyond noise (~1% of V).
    assert!(cosine.abs() < 0.05 * sine, "cosine part {cosine} of {sine}");
    // Statistical error of V ~1% (53 relaxation times of 5760 particles); the finite k a
    // = 0.39 and the thermostat shift nu by at most a few percent (measured -0.7%).
    assert!(
        (nu / (kin + coll) - 1.0).abs() < 0.05,
        "nu {nu} vs {}",
        kin + coll
    );
    assert!((kt - 1.0).abs() < 0.01, "kT {kt}");
}

/// MPCD-BC in 3D (S2 §3.3: A = 0.01, M = 5, tau = 0.01, Hecht thermostat c = 0.3; the
/// source measured nu = 1.845 with L_z = 80) from Kolmogorov flow in a periodic 8 x 4 x 16
/// box (k = 0.39: the source finds nu lower at large k, flat below k = 0.15), F = 0.02,
/// 19000 samples: about 12 s on lavapipe. Measured 2026-12-06: nu = 1.86 and 1.98 (seeds 1
/// and 2 from the command line); within 15% of the source (noise of the amplitude ~5%).
#[test]
fn biased_collisions_give_the_sources_3d_viscosity() {
    if gpu().is_none() {
        return;
    }
    let (l, force) = (16.0, 0.02);
    let out = run_mpcd(
        &[
            ("box", "[8, 4, 16]"),
            ("density", "5"),
            ("dt", "0.01"),
            ("rule", "\"biased\""),
            ("acceptance", "0.01"),
            ("thermostat", "\"monte_carlo\""),
            ("force", "0.02"),
            ("force_shape", "\"sine\""),
            ("profile_bins", "16"),
            ("warmup", "1000"),
        ],
        20_000,
        1,
        &["velocity_profile", "temperature"],
    );
    let u = out["velocity_profile"].data.to_f64();
    let k = 2.0 * std::f64::consts::PI / l;
    let nb = u.len() as f64;
    // The bins' mean of sin(k z): the amplitude times sinc(k h / 2), h = l / nb.
    let sinc = (k * l / nb / 2.0).sin() / (k * l / nb / 2.0);
    let amplitude: f64 = u
        .iter()
        .enumerate()
        .map(|(i, u)| 2.0 * u * (k * ((i as f64 + 0.5) / nb * l - l / 2.0)).sin() / nb)
        .sum::<f64>()
        / sinc;
    let nu = force / (amplitude * k * k);
    let kt = scalar(&out["temperature"]);
    eprintln!("MPCD-BC 3D: V = {amplitude:.5}, nu = {nu:.4} (source: 1.845), kT {kt:.4}");
    assert!((nu / 1.845 - 1.0).abs() < 0.15, "nu {nu}");
    assert!((kt - 1.0).abs() < 0.01, "kT {kt}");
}

/// Least squares u = c0 + c2 z^2 over bins of width h / nb centred on z = 0: (c0, c2, the
/// largest residual).
fn parabola_fit(u: &[f64], h: f64) -> (f64, f64, f64) {
    let nb = u.len();
    let z: Vec<f64> = (0..nb)
        .map(|i| (i as f64 + 0.5) / nb as f64 * h - h / 2.0)
        .collect();
    let n = nb as f64;
    let sx: f64 = z.iter().map(|z| z * z).sum();
    let sxx: f64 = z.iter().map(|z| z.powi(4)).sum();
    let sy: f64 = u.iter().sum();
    let sxy: f64 = z.iter().zip(u).map(|(z, u)| z * z * u).sum();
    let c2 = (n * sxy - sx * sy) / (n * sxx - sx * sx);
    let c0 = (sy - c2 * sx) / n;
    let worst = z
        .iter()
        .zip(u)
        .map(|(z, u)| (u - c0 - c2 * z * z).abs())
        .fold(0.0, f64::max);
    (c0, c2, worst)
}

/// MPCD-BC Poiseuille flow between plates (S2 Ch. 4 with the biased rule: bounce-back,
/// virtual particles in the cells the plates cut, the wall layers as pair partners) in a
/// gap of 8 cells (8 x 4 x 8, A = 0.01, M = 5, tau = 0.01, F = 0.05, u_max ~ 0.24):
/// parabolic, its curvature giving the viscosity of the bulk fluid (the source's 1.845;
/// the periodic Kolmogorov run above), and a small slip. Measured 2026-12-06 (seeds 1 to
/// 3 from the command line): nu from the curvature 2.20, 1.93, 2.04; slip lengths 0.50,
/// 0.36, 0.40 a (SRD with virtual particles: 0.16-0.23 a); so the mean velocity
/// F L^2 / (12 nu) is exceeded by about 6 b / L (30% here, 3% in the source's gap of 80).
/// About 12 s on lavapipe.
#[test]
fn biased_poiseuille_flow_between_plates_is_parabolic_with_the_bulk_viscosity() {
    if gpu().is_none() {
        return;
    }
    let (h, force) = (8.0, 0.05);
    let out = run_mpcd(
        &[
            ("box", "[8, 4, 8]"),
            ("walls", "\"plates\""),
            ("density", "5"),
            ("dt", "0.01"),
            ("rule", "\"biased\""),
            ("acceptance", "0.01"),
            ("thermostat", "\"monte_carlo\""),
            ("force", "0.05"),
            ("profile_bins", "8"),
            ("warmup", "1000"),
        ],
        20_000,
        1,
        &["velocity_profile", "temperature"],
    );
    let u = out["velocity_profile"].data.to_f64();
    let (c0, c2, worst) = parabola_fit(&u, h);
    let nu = -force / (2.0 * c2);
    let slip = c0 + c2 * h * h / 4.0;
    let slip_length = slip / (-c2 * h);
    let kt = scalar(&out["temperature"]);
    eprintln!(
        "MPCD-BC Poiseuille: nu {nu:.4} (source 1.845), u_max {c0:.4}, slip {slip:.4} (slip length {slip_length:.3} a), residual {worst:.4}, kT {kt:.4}: {u:?}"
    );
    assert!(worst < 0.06 * c0, "residual {worst} of u_max {c0}: {u:?}");
    // Noise of the curvature over 19000 samples of 1280 particles: ~8%.
    assert!((nu / 1.845 - 1.0).abs() < 0.25, "nu {nu}");
    assert!(slip_length.abs() < 0.8, "slip length {slip_length} a");
    assert!((kt - 1.0).abs() < 0.01, "kT {kt}");
}

/// The source's Poiseuille runs (S2 §4.4, digest V10): plates 80 cells apart, 40 cells
/// along the flow and 20 across, M = 5, A = 0.01, Hecht c = 0.3; (a) tau = 0.01, F = 1.5e-4
/// (nu = 1.845): mean velocity 0.0436 (analytic 0.0434); (b) tau = 0.005, F = 2.5e-4
/// (nu = 3.317): 0.0406 (0.0402). 320000 particles; the flow relaxes in
/// H^2 / (pi^2 nu) = 35000 and 39000 steps: 200000 steps of warm-up, 300000 averaged
/// (the source: 5e6). The mean velocity is the mean momentum / N m. Measured on an H100
/// (2026-12-06, BENCHMARKS.md, `bash benches/gpu.sh poiseuille` runs the same): (a)
/// 0.04237 (-2.8 %), (b) 0.03720 (-8.4 %), the curvature giving nu = 1.929 and 3.623: our
/// biased rule's bulk viscosity is 4.5 % and 9 % above the source's (Kolmogorov flow
/// agrees), so (a) is held to 3 % and (b) to 10 %, and nu to 10 %. For the GPU: about
/// 45 s each.
#[test]
#[ignore]
fn biased_poiseuille_flow_has_the_sources_mean_velocity() {
    if gpu().is_none() {
        return;
    }
    for (dt, force, want, nu_source, tolerance) in [
        ("0.01", "1.5e-4", 0.0436, 1.845, 0.03),
        ("0.005", "2.5e-4", 0.0406, 3.317, 0.10),
    ] {
        let out = run_mpcd(
            &[
                ("box", "[40, 20, 80]"),
                ("walls", "\"plates\""),
                ("density", "5"),
                ("dt", dt),
                ("rule", "\"biased\""),
                ("acceptance", "0.01"),
                ("thermostat", "\"monte_carlo\""),
                ("force", force),
                ("profile_bins", "80"),
                ("warmup", "200000"),
            ],
            500_000,
            1,
            &["velocity_profile", "momentum", "temperature"],
        );
        let n = 5.0 * 40.0 * 20.0 * 80.0;
        let mean = out["momentum"].data.to_f64()[0] / n;
        let u = out["velocity_profile"].data.to_f64();
        let (c0, c2, _) = parabola_fit(&u, 80.0);
        let f: f64 = force.parse().expect("number");
        let nu = -f / (2.0 * c2);
        eprintln!(
            "V10 dt {dt}: mean velocity {mean:.5} (source {want}), nu from the curvature {nu:.4}, u_max {c0:.5}, slip {:.5}, kT {:.4}",
            c0 + c2 * 1600.0,
            scalar(&out["temperature"])
        );
        assert!(
            (mean / want - 1.0).abs() < tolerance,
            "dt {dt}: mean velocity {mean}"
        );
        assert!((nu / nu_source - 1.0).abs() < 0.10, "dt {dt}: nu {nu}");
    }
}

/// `mpcd_virial` against its f64 reference: random velocity changes of particles in the
/// cells of an 8 x 6 x 4 grid; the exact sum within the f32 rounding of each particle's
/// dv, the pressure alike.
#[test]
fn the_collisional_pressure_node_matches_its_reference() {
    if gpu().is_none() {
        return;
    }
    let mut rng = crate::util::Rng::new(23);
    let n = 3000;
    let before: Vec<Vec<f64>> = (0..n)
        .map(|_| (0..3).map(|_| rng.uniform(-2.0, 2.0)).collect())
        .collect();
    let after: Vec<Vec<f64>> = before
        .iter()
        .map(|v| v.iter().map(|c| c + rng.uniform(-0.3, 0.3)).collect())
        .collect();
    let cells: Vec<u32> = (0..n).map(|_| rng.uniform(0.0, 192.0) as u32).collect();
    let (out, refs) = crate::util::run_node_and_reference(
        "mpcd_virial",
        r#"{"box": [8, 6, 4], "rule": "biased", "dt": 0.02, "temperature": 1, "mass": 2}"#,
        &[
            ("before", crate::util::particles(&before)),
            ("after", crate::util::particles(&after)),
            ("cell", crate::util::indices(&cells)),
        ],
    );
    let sums = crate::util::u32s(&out["sums"]);
    let total = (sums[1] as u64 | ((sums[2] as u64) << 32)) as i64;
    let want = refs[0].data[1] as u64 | ((refs[0].data[2] as u64) << 32);
    let want = want as i64;
    assert_eq!(sums[0], 1, "one sample");
    assert!(
        (total - want).abs() <= 3 * n as i64,
        "sum {total}, reference {want}"
    );
    let p = scalar(&out["pressure"]);
    assert!(
        want != 0 && (p / refs[1].data[0] - 1.0).abs() < 1e-5,
        "pressure {p}, reference {}",
        refs[1].data[0]
    );
}

/// The non-ideal pressure of MPCD-BC in 3D against the source's equation of state (S2
/// Eq. 1.3 with the 1/13 weights of the collision types, digest B.4 and V21): its share
/// P_n / (P_n + M kT) is 37.1% at A = 0.01, tau = 0.02 and 10.6% at A = 0.005, tau = 0.05
/// (M = 5; the source: "about 37%" and "about 10%"), measured as the momentum the pair
/// collisions move between cells (mpcd.json's collisional_pressure) in a periodic 8^3
/// box over 1000 steps, within 3 points (the digest's tolerance; tanh(x) < x makes the
/// measured share a little lower). Measured 2026-12-06: 36.1% and 10.4%. SRD moves no
/// momentum between cells: zero up to the f32 rounding. About 5 s on lavapipe.
#[test]
fn biased_collisions_have_the_sources_non_ideal_pressure() {
    if gpu().is_none() {
        return;
    }
    for (a, dt, want) in [("0.01", "0.02", 0.371), ("0.005", "0.05", 0.106)] {
        let out = run_mpcd(
            &[
                ("box", "[8, 8, 8]"),
                ("density", "5"),
                ("dt", dt),
                ("rule", "\"biased\""),
                ("acceptance", a),
                ("thermostat", "\"monte_carlo\""),
                ("warmup", "100"),
            ],
            1100,
            1,
            &["collisional_pressure", "temperature"],
        );
        let p = scalar(&out["collisional_pressure"]);
        let kt = scalar(&out["temperature"]);
        let share = p / (p + 5.0 * kt);
        eprintln!(
            "MPCD-BC A = {a}, tau = {dt}: P_n = {p:.4}, share {:.2}% (source {:.1}%)",
            100.0 * share,
            100.0 * want
        );
        assert!(
            (share - want).abs() < 0.03,
            "A = {a}, tau = {dt}: share {share}"
        );
    }
    let out = run_mpcd(
        &[("box", "[8, 8, 8]"), ("density", "5")],
        50,
        1,
        &["collisional_pressure"],
    );
    // Only the f32 rounding of each cell's new velocities: below 1e-4 of the ideal 5.
    let p = scalar(&out["collisional_pressure"]);
    assert!(p.abs() < 5e-4, "SRD: {p}");
}
