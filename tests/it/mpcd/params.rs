//! Extreme but finite MPCD params: values the nodes' f32 arithmetic cannot carry (a mean
//! free path of 1e30 box lengths, kT / m of 1e30, a force adding 1e29 v_th a step) are
//! refused at load naming the params the user sets, and units from 1e-30 to 1e30 within
//! the ranges (SI units among them) run and measure the temperature asked.

use crate::util::mpcd::run_mpcd;
use crate::util::{gpu, load_error, scalar};

/// A graph file, its `--set` values and what the load error must say.
type Case<'a> = (&'a str, &'a [(&'a str, &'a str)], &'a [&'a str]);

#[test]
fn extreme_mpcd_params_are_refused_naming_the_params_the_user_sets() {
    let cube = ("box", "[4, 4, 4]");
    let cases: [Case; 9] = [
        (
            "mpcd.json",
            &[cube, ("dt", "1e30")],
            &[
                "node `stream_bin`",
                "mean free path dt x v_th = 1e30 x 1 = 1e30",
                "1024 box lengths",
            ],
        ),
        (
            "mpcd.json",
            &[cube, ("temperature", "1e30")],
            &["temperature / mass = 1e30 / 1 = 1e30 is outside [1e-20, 1e20]"],
        ),
        (
            "mpcd.json",
            &[cube, ("mass", "1e-30")],
            &["temperature / mass = 1 / 1e-30 = 1e30 is outside [1e-20, 1e20]"],
        ),
        (
            "mpcd.json",
            &[cube, ("force", "1e30")],
            &["force / mass = 1e30 / 1", "not below 128 v_th = 128"],
        ),
        (
            "mpcd.json",
            &[cube, ("dt", "1e-9")],
            &["dt x v_th = 1e-9 x 1", "below 2^-20 of the box length 4"],
        ),
        (
            "mpcd.json",
            &[cube, ("walls", "\"plates\""), ("dt", "0.5")],
            &[
                "more than 0.4375",
                "cross the gap between the plates more than 14 times",
            ],
        ),
        (
            "mpcd.json",
            &[("box", "[1e6, 4, 4]")],
            &["1000000 cells of size 1, more than 65536"],
        ),
        // A graph param's own range: the graph param is the problem, the nodes follow.
        (
            "mpcd2d.json",
            &[("temperature", "1e31")],
            &[
                "param `temperature`",
                "1e31 is above the maximum 1e30",
                "follow from it",
            ],
        ),
        // A node param computed from a graph param of another name names the one set.
        (
            "mpcd_solute.json",
            &[cube, ("solute_mass", "1e-25")],
            &[
                "node `stream_solute`",
                "temperature / mass = 1 / 1e-25",
                "(from graph param `solute_mass` = 1e-25)",
            ],
        ),
    ];
    for (file, sets, needles) in cases {
        let e = load_error(file, sets);
        for n in needles {
            assert!(e.contains(n), "{file} {sets:?}: expected `{n}` in: {e}");
        }
    }
}

#[test]
fn units_from_1e_30_to_1e30_within_the_ranges_measure_the_temperature_asked() {
    if gpu().is_none() {
        return;
    }
    // v_th = 1 at kT = m = 1e30 and 1e-30; SI units for water-like particles (kT 4e-21 J,
    // m 1e-26 kg, cells of 1 nm, a 1 ps step: v_th 632 m/s, a mean free path of 0.6 nm).
    let cases: [&[(&str, &str)]; 3] = [
        &[("temperature", "1e30"), ("mass", "1e30")],
        &[("temperature", "1e-30"), ("mass", "1e-30")],
        &[
            ("temperature", "4e-21"),
            ("mass", "1e-26"),
            ("dt", "1e-12"),
            ("cell", "1e-9"),
        ],
    ];
    for sets in cases {
        let kt: f64 = sets[0].1.parse().unwrap();
        let cell: f64 = sets
            .iter()
            .find(|s| s.0 == "cell")
            .map_or(1.0, |s| s.1.parse().unwrap());
        let side = format!("[{0}, {0}, {0}]", 4.0 * cell);
        let mut all = vec![("box", side.as_str())];
        all.extend_from_slice(sets);
        let out = run_mpcd(&all, 5, 3, &["temperature", "momentum", "positions"]);
        let t = scalar(&out["temperature"]);
        // 640 particles: the measured kT within 10% of the one asked.
        assert!(
            (t / kt - 1.0).abs() < 0.1,
            "{sets:?}: measured temperature {t} for kT {kt}"
        );
        let x = crate::util::f32s(&out["positions"]);
        assert!(
            x.iter().all(|c| c.is_finite()) && x.iter().filter(|c| **c == 0.0).count() < 10,
            "{sets:?}: positions {:?}",
            &x[..6]
        );
    }
}
