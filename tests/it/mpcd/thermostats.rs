//! Cell thermostats: the temperature held under viscous heating, and the velocity
//! distributions that Monte-Carlo scaling and cell rescaling leave.

use crate::util::mpcd::run_mpcd;
use crate::util::{gpu, scalar};

#[test]
fn cell_thermostats_hold_the_temperature_under_viscous_heating() {
    if gpu().is_none() {
        return;
    }
    // Kolmogorov flow (sine force) in a periodic box heats the fluid: ~+0.4 kT over the
    // run without a thermostat, which the test checks first (so the other checks can fail).
    let base = [
        ("box", "[6, 6, 6]"),
        ("force", "0.2"),
        ("force_shape", "\"sine\""),
        ("warmup", "100"),
        ("temperature", "1.2"),
    ];
    let t = |thermostat: &str| {
        let mut sets = base.to_vec();
        sets.push(("thermostat", thermostat));
        scalar(&run_mpcd(&sets, 400, 1, &["temperature"])["temperature"])
    };
    let free = t("\"none\"");
    eprintln!("thermostat none: kT {free}");
    assert!(
        free > 1.2 * 1.1,
        "no thermostat: kT {free} should have risen"
    );
    for thermostat in ["\"rescale\"", "\"monte_carlo\""] {
        let kt = t(thermostat);
        eprintln!("thermostat {thermostat}: kT {kt} (target 1.2)");
        // Measured before each collision from velocities relative to the cell means
        // (d (N - occupied cells) degrees of freedom), averaged over 300 steps of 2160
        // particles: its own noise is ~0.1%; 1% is the requirement.
        assert!(
            (kt / 1.2 - 1.0).abs() < 0.01,
            "{thermostat}: kT {kt} (target 1.2, free {free})"
        );
    }
}

#[test]
fn monte_carlo_thermostat_keeps_maxwell_boltzmann_and_cell_rescaling_flattens_it() {
    if gpu().is_none() {
        return;
    }
    // Digest V12/V13 (S2 Figs. 2.1, 2.2): Hecht's Monte-Carlo cell scaling keeps every
    // velocity component Gaussian (excess kurtosis 0), while rescaling each cell's relative
    // velocities to exactly d (n - 1) kT puts them on a sphere of D = d (n - 1) dimensions,
    // whose components have excess kurtosis -6 / (D + 2) (measured -0.36 at M = 10, with the
    // cell means mixed in; -0.03 for the Monte-Carlo scaling).
    let excess = |thermostat: &str| {
        let out = run_mpcd(
            &[("box", "[10, 10, 10]"), ("thermostat", thermostat)],
            200,
            2,
            &["velocities"],
        );
        let v = out["velocities"].data.to_f64();
        let n = v.len() as f64;
        let m2 = v.iter().map(|x| x * x).sum::<f64>() / n;
        let m4 = v.iter().map(|x| x.powi(4)).sum::<f64>() / n;
        m4 / (m2 * m2) - 3.0
    };
    let (mc, rescale) = (excess("\"monte_carlo\""), excess("\"rescale\""));
    eprintln!("excess kurtosis: monte_carlo {mc:.4}, rescale {rescale:.4}");
    // 3 x 10^4 components: standard error sqrt(24 / N) = 0.028; 0.1 is 3.5 sigma.
    assert!(
        mc.abs() < 0.1,
        "Monte-Carlo thermostat: excess kurtosis {mc}"
    );
    assert!(rescale < -0.1, "cell rescaling: excess kurtosis {rescale}");
}
