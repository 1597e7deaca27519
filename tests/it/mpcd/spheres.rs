//! Solid spheres (nodes/mpcd/spheres.rs): bounce-back streaming against closed-form
//! trajectories and its f64 reference, the impulse balancing the solvent's momentum
//! change exactly.

use mesoflow::nodes::mpcd::impulse_of;
use mesoflow::value::HostArray;

use crate::util::mpcd::random_particles;
use crate::util::{Rng, gpu, particles, rows, run_node_and_reference, u32s};

/// The impulse words of an output as f64 words.
fn impulses(a: &HostArray, s: usize) -> Vec<[i64; 3]> {
    let w: Vec<f64> = u32s(a).iter().map(|&x| x as f64).collect();
    (0..s).map(|j| impulse_of(&w, j)).collect()
}

/// The fixed-point unit of the impulses at kT = m = 1: v_th / 2^24.
const UNIT: f64 = 1.0 / 16_777_216.0;

fn stream_spheres(
    params: &str,
    x: &[Vec<f64>],
    v: &[Vec<f64>],
    spheres: &[([f64; 3], f64)],
    moving: Option<&[[f64; 3]]>,
) -> (
    std::collections::BTreeMap<String, HostArray>,
    Vec<mesoflow::value::RefArray>,
) {
    let centres: Vec<[f64; 3]> = spheres.iter().map(|s| s.0).collect();
    let radii: Vec<[f64; 1]> = spheres.iter().map(|s| [s.1]).collect();
    let mut inputs = vec![
        ("positions", particles(x)),
        ("velocities", particles(v)),
        ("sphere_positions", particles(&centres)),
        ("sphere_radii", particles(&radii)),
    ];
    if let Some(vs) = moving {
        inputs.push(("sphere_velocities", particles(vs)));
    }
    run_node_and_reference("mpcd_stream_spheres", params, &inputs)
}

#[test]
fn sphere_bounce_back_matches_closed_form_trajectories() {
    if gpu().is_none() {
        return;
    }
    // Box 16, dt 2.5 (a long step, so each case is one hit worked out by hand).
    let params = r#"{"box": [16, 16, 16], "dt": 2.5}"#;
    let spheres = [([0.0, 0.0, 0.0], 1.0), ([-7.0, 4.0, 0.0], 1.0)];
    let x = vec![
        // Head-on: hits x = -1 at t = 2, back at -1 for 0.5: ends at -1.5, v = -1.
        vec![-3.0, 0.0, 0.0],
        // A chord whose ends are both outside (the end-point test misses it): from
        // (-2, 0.5, 0) at v_x = 1.6 it meets the surface at x = -sqrt(0.75) at
        // t = (2 - sqrt(0.75)) / 1.6, then goes back: ends at -sqrt(0.75) - 1.6 (2.5 - t).
        vec![-2.0, 0.5, 0.0],
        // Across the periodic face: the image of the sphere at (-7, 4) sits at (9, 4);
        // from x = 7.5 at v_x = 1 the surface x = 8 is reached at t = 0.5, then back
        // for 2: ends at 6, v = -1.
        vec![7.5, 4.0, 0.0],
        // A miss: passes at distance 1.5 from the centre.
        vec![-3.0, 1.5, 0.0],
    ];
    let v = vec![
        vec![1.0, 0.0, 0.0],
        vec![1.6, 0.0, 0.0],
        vec![1.0, 0.0, 0.0],
        vec![1.0, 0.0, 0.0],
    ];
    let s75 = 0.75f64.sqrt();
    let t1 = (2.0 - s75) / 1.6;
    let want_x = [
        [-1.5, 0.0, 0.0],
        [-s75 - 1.6 * (2.5 - t1), 0.5, 0.0],
        [6.0, 4.0, 0.0],
        [-0.5, 1.5, 0.0],
    ];
    let want_v = [
        [-1.0, 0.0, 0.0],
        [-1.6, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
    ];
    let (out, _) = stream_spheres(params, &x, &v, &spheres, None);
    let (xs, vs) = (rows(&out["positions"], 3), rows(&out["velocities"], 3));
    for p in 0..x.len() {
        for a in 0..3 {
            assert!(
                (xs[p][a] - want_x[p][a]).abs() < 1e-5 && (vs[p][a] - want_v[p][a]).abs() < 1e-6,
                "particle {p}: x {:?} v {:?}, want {:?} {:?}",
                xs[p],
                vs[p],
                want_x[p],
                want_v[p]
            );
        }
    }
    // Impulses 2 m v per bounce: sphere 0 from particles 0 and 1 (2 + 3.2 along x),
    // sphere 1 from particle 2 (2).
    let q = impulses(&out["impulse"], 2);
    let want = [[5.2, 0.0, 0.0], [2.0, 0.0, 0.0]];
    for j in 0..2 {
        for a in 0..3 {
            assert!(
                (q[j][a] as f64 * UNIT - want[j][a]).abs() < 1e-6,
                "sphere {j}: impulse {:?}, want {:?}",
                q[j],
                want[j]
            );
        }
    }

    // A moving sphere (V = (-1, 0, 0)): the gap of 2 closes at relative speed 2, so the
    // hit is at t = 1 at x = -2; v' = 2V - v = -3 for the remaining 1.5: ends at -6.5;
    // the sphere receives 2 (v - V) = 4.
    let (out, _) = stream_spheres(
        params,
        &[vec![-3.0, 0.0, 0.0]],
        &[vec![1.0, 0.0, 0.0]],
        &[([0.0, 0.0, 0.0], 1.0)],
        Some(&[[-1.0, 0.0, 0.0]]),
    );
    let (xs, vs) = (rows(&out["positions"], 3), rows(&out["velocities"], 3));
    assert!(
        (xs[0][0] + 6.5).abs() < 1e-5 && (vs[0][0] + 3.0).abs() < 1e-6,
        "moving sphere: x {:?} v {:?}",
        xs[0],
        vs[0]
    );
    assert!((impulses(&out["impulse"], 1)[0][0] as f64 * UNIT - 4.0).abs() < 1e-6);
}

/// Random solvent around fixed and moving spheres, one near a periodic face and one near
/// a plate: every particle and impulse against the f64 reference, and the solvent's
/// momentum change against the impulses.
#[test]
fn sphere_streaming_matches_its_reference_and_balances_momentum() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(26);
    let l = [8.0, 8.0, 8.0];
    let n = 3000;
    let spheres = [
        ([0.5, -0.3, 0.2], 1.5),
        ([-3.6, 3.2, -1.0], 1.0),
        ([2.0, 2.0, -2.6], 1.2),
    ];
    let moving = [[0.3, -0.2, 0.1], [0.0, 0.0, 0.0], [-0.4, 0.1, 0.0]];
    for (walls, force, with_v) in [
        ("none", 0.0, false),
        ("plates", 0.0, true),
        ("none", 0.2, true),
    ] {
        let (x, v) = random_particles(&mut rng, n, &l);
        let params =
            format!(r#"{{"box": [8, 8, 8], "walls": "{walls}", "dt": 0.4, "force": {force}}}"#);
        let (out, r) = stream_spheres(&params, &x, &v, &spheres, with_v.then_some(&moving[..]));
        let (xs, vs) = (rows(&out["positions"], 3), rows(&out["velocities"], 3));
        let mut bounced = 0;
        for p in 0..n {
            let vr = &r[1].data[3 * p..3 * p + 3];
            let xr = &r[0].data[3 * p..3 * p + 3];
            // Unbounced, v gains force dt along x (mass 1).
            let gain = [force * 0.4, 0.0, 0.0];
            if (0..3).any(|a| (vr[a] - v[p][a] - gain[a]).abs() > 1e-3) {
                bounced += 1;
            }
            for a in 0..3 {
                // Positions on periodic axes compared as the nearest image.
                let mut dx = xs[p][a] - xr[a];
                dx -= l[a] * (dx / l[a]).round();
                assert!(
                    dx.abs() < 1e-4 && (vs[p][a] - vr[a]).abs() < 1e-4,
                    "{walls}, force {force}: particle {p} x {:?} v {:?}, reference {xr:?} {vr:?}",
                    xs[p],
                    vs[p]
                );
            }
        }
        assert!(bounced > 30, "{walls}: only {bounced} particles bounced");
        let got = impulses(&out["impulse"], spheres.len());
        let want: Vec<f64> = r[2].data.clone();
        let want = (0..spheres.len())
            .map(|j| impulse_of(&want, j))
            .collect::<Vec<_>>();
        for j in 0..spheres.len() {
            for a in 0..3 {
                // f32 against f64 velocities, about 1e-6 of each bounce's 2 |v - V|.
                let tol = 2e-4 / UNIT;
                assert!(
                    ((got[j][a] - want[j][a]) as f64).abs() < tol,
                    "{walls}: sphere {j} impulse {:?}, reference {:?}",
                    got[j],
                    want[j]
                );
            }
        }
        if force == 0.0 && walls == "none" {
            // Momentum: the solvent's loss is the spheres' gain, to f32 rounding of the
            // velocities (the impulses are exact sums of each bounce rounded to 2^-24).
            for a in 0..3 {
                let lost: f64 = (0..n).map(|p| v[p][a] as f32 as f64 - vs[p][a]).sum();
                let gained: f64 = got.iter().map(|q| q[a] as f64 * UNIT).sum();
                assert!(
                    (lost - gained).abs() < 1e-4,
                    "axis {a}: solvent lost {lost}, spheres gained {gained}"
                );
            }
        }
    }
}

/// A solvent drawn uniformly, then moved out of two spheres (one across a periodic face):
/// none left inside, the others untouched, every particle as the f64 reference draws it,
/// and about the share of the volume the spheres fill redrawn.
#[test]
fn sphere_exclusion_leaves_no_particle_inside_and_keeps_the_others() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(8);
    let l = [8.0, 8.0, 8.0];
    let n = 6000;
    let (x, _) = random_particles(&mut rng, n, &l);
    let spheres = [([0.5, -0.3, 0.2], 2.0), ([-3.6, 3.2, -1.0], 1.5)];
    let centres: Vec<[f64; 3]> = spheres.iter().map(|s| s.0).collect();
    let radii: Vec<[f64; 1]> = spheres.iter().map(|s| [s.1]).collect();
    let (out, r) = run_node_and_reference(
        "mpcd_sphere_exclude",
        r#"{"box": [8, 8, 8], "seed": 3, "stream": 8}"#,
        &[
            ("positions", particles(&x)),
            ("sphere_positions", particles(&centres)),
            ("sphere_radii", particles(&radii)),
        ],
    );
    let xs = rows(&out["positions"], 3);
    let inside = |p: &[f64]| {
        spheres.iter().any(|(c, rad)| {
            let d2: f64 = (0..3)
                .map(|a| {
                    let d = p[a] - c[a];
                    (d - l[a] * (d / l[a]).round()).powi(2)
                })
                .sum();
            d2 < rad * rad
        })
    };
    let mut moved = 0;
    for p in 0..n {
        let x32: Vec<f64> = x[p].iter().map(|&c| c as f32 as f64).collect();
        assert!(
            !inside(&xs[p]),
            "particle {p} at {:?} is inside a sphere",
            xs[p]
        );
        if inside(&x32) {
            moved += 1;
        } else {
            assert_eq!(xs[p], x32, "particle {p} outside the spheres was moved");
        }
        for a in 0..3 {
            assert!(
                (xs[p][a] - r[0].data[3 * p + a]).abs() < 1e-6,
                "particle {p}: {:?}, reference {:?}",
                xs[p],
                &r[0].data[3 * p..3 * p + 3]
            );
        }
    }
    // The spheres fill 4/3 pi (8 + 3.375) = 47.6 of 512: about 558 of 6000 drawn inside
    // (binomial sd 23).
    let want = n as f64 * 4.0 / 3.0 * std::f64::consts::PI * (8.0 + 3.375) / 512.0;
    assert!(
        (moved as f64 - want).abs() < 5.0 * want.sqrt(),
        "{moved} particles were inside, expected about {want:.0}"
    );
}
