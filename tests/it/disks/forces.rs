//! `nonreciprocal_forces` against the f64 all-pairs sum of S1 eq. 2, both laws, and the
//! zero total force of reciprocal charges.

use mesoflow::value::HostArray;

use crate::util::disks::disk_positions;
use crate::util::{Rng, flat_particles, gpu, rel_max_err, run_node_and_reference};

const BOX: [f64; 2] = [24.0, 20.0];

/// N disks at least 0.9 apart and (alpha, mu) rows: random in [-2, 2], or alpha = mu.
fn system(n: usize, seed: u64, reciprocal: bool) -> (HostArray, HostArray) {
    let mut rng = Rng::new(seed);
    let x = disk_positions(&mut rng, n, BOX, 0.9);
    let q: Vec<f64> = (0..n)
        .flat_map(|_| {
            let a = rng.uniform(-2.0, 2.0);
            let m = if reciprocal {
                a
            } else {
                rng.uniform(-2.0, 2.0)
            };
            [a, m]
        })
        .collect();
    (flat_particles(&x, 2), flat_particles(&q, 2))
}

#[test]
fn nonreciprocal_forces_match_the_f64_sum() {
    if gpu().is_none() {
        return;
    }
    // 300 particles: three tiles of 128, the last one partial, one range of tiles.
    let (x, q) = system(300, 7, false);
    let cases = [
        // r^-2 forces summed over 300 terms in f32: a few ulps of the largest force.
        (r#"{"law": "long", "box": [24, 20]}"#, 2e-5),
        (r#"{"law": "short", "cutoff": 2.5, "box": [24, 20]}"#, 2e-5),
        // Open axes: plain differences.
        (r#"{"law": "long"}"#, 2e-5),
    ];
    check_forces(&x, &q, &cases);
    // 1700 particles: 14 tiles, the last partial, split into 3 ranges of 5, 5 and 4 tiles
    // summed apart and added per particle in range order. They fill a 36 x 30 patch moved
    // across the corner of a 75 x 62 box: pairs wrap, but none is near half the box, where
    // f32 and f64 differences may round to different images.
    let l = [75.0, 62.0];
    let mut rng = Rng::new(8);
    let x: Vec<f64> = disk_positions(&mut rng, 1700, [36.0, 30.0], 0.5)
        .chunks(2)
        .flat_map(|p| {
            let wrap = |v: f64, l: f64| (v + l / 2.0).rem_euclid(l) - l / 2.0;
            [wrap(p[0] + l[0] / 2.0, l[0]), wrap(p[1] + l[1] / 2.0, l[1])]
        })
        .collect();
    let q: Vec<f64> = (0..2 * 1700).map(|_| rng.uniform(-2.0, 2.0)).collect();
    check_forces(
        &flat_particles(&x, 2),
        &flat_particles(&q, 2),
        &[
            (r#"{"law": "long", "box": [75, 62]}"#, 2e-5),
            (r#"{"law": "short", "cutoff": 2.5, "box": [75, 62]}"#, 2e-5),
        ],
    );
}

fn check_forces(x: &HostArray, q: &HostArray, cases: &[(&str, f64)]) {
    for &(params, tol) in cases {
        let (out, refs) = run_node_and_reference(
            "nonreciprocal_forces",
            params,
            &[("positions", x.clone()), ("charges", q.clone())],
        );
        let (err, at) = rel_max_err(&out["forces"], &refs[0]);
        assert!(err < tol, "{params}: relative error {err:e} at {at}");
    }
}

/// Particles in a spatial order (sorted by 8 x 8 blocks of a 64 x 48 box, 3072 of them:
/// 24 tiles of two blocks each) make compact tiles, so most (particle, tile) pairs take
/// the long-range law's one-image path and the tiles at half the box the per-pair minimum
/// image: both against the f64 sum (a shift that broke the one-image path failed this).
#[test]
fn long_range_forces_of_ordered_particles_match_the_f64_sum() {
    if gpu().is_none() {
        return;
    }
    let l = [64.0, 48.0];
    let mut rng = Rng::new(11);
    let mut x: Vec<[f64; 2]> = disk_positions(&mut rng, 3072, l, 0.5)
        .chunks(2)
        .map(|p| [p[0], p[1]])
        .collect();
    let block = |p: &[f64; 2]| {
        (
            ((p[1] + 24.0) / 8.0) as usize,
            ((p[0] + 32.0) / 8.0) as usize,
        )
    };
    x.sort_by_key(block);
    let x: Vec<f64> = x.concat();
    let q: Vec<f64> = (0..3072)
        .flat_map(|_| [rng.uniform(-2.0, 2.0), rng.uniform(-2.0, 2.0)])
        .collect();
    let (out, refs) = run_node_and_reference(
        "nonreciprocal_forces",
        r#"{"law": "long", "box": [64, 48]}"#,
        &[
            ("positions", flat_particles(&x, 2)),
            ("charges", flat_particles(&q, 2)),
        ],
    );
    let (err, at) = rel_max_err(&out["forces"], &refs[0]);
    assert!(err < 5e-5, "relative error {err:e} at {at}");
}

/// The cutoff removes exactly the pairs beyond it: one pair at 2.4 and one at 2.6 apart.
#[test]
fn short_range_forces_stop_at_the_cutoff() {
    if gpu().is_none() {
        return;
    }
    let x = flat_particles(&[0.0, 0.0, 2.4, 0.0, -2.6, 0.0], 2);
    let q = flat_particles(&[1.0, 1.0, 1.0, 1.0, 1.0, 1.0], 2);
    let (out, _) = run_node_and_reference(
        "nonreciprocal_forces",
        r#"{"law": "short", "cutoff": 2.5, "box": [20, 20]}"#,
        &[("positions", x), ("charges", q)],
    );
    let f = out["forces"].data.to_f64();
    // Particle 0 feels only particle 1 at 2.4 (pushed to -x), particle 2 feels nothing.
    let want = -(2.4f64).powi(-6);
    assert!(
        (f[0] - want).abs() < 1e-6 * want.abs(),
        "{} vs {want}",
        f[0]
    );
    assert_eq!(&f[4..6], &[0.0, 0.0], "the particle beyond the cutoff");
}

/// With alpha = mu (charged colloids) action equals reaction and the forces sum to zero
/// up to f32 round-off; with alpha != mu they do not (so the check can fail).
#[test]
fn forces_sum_to_zero_when_alpha_equals_mu() {
    if gpu().is_none() {
        return;
    }
    for law in ["long", "short"] {
        let params = format!(r#"{{"law": "{law}", "cutoff": 0, "box": [24, 20]}}"#);
        let mut ratio = [0.0; 2];
        for (case, reciprocal) in [true, false].into_iter().enumerate() {
            let (x, q) = system(257, 11, reciprocal);
            let (out, _) = run_node_and_reference(
                "nonreciprocal_forces",
                &params,
                &[("positions", x), ("charges", q)],
            );
            let f = out["forces"].data.to_f64();
            let sum = [0, 1].map(|d| f.iter().skip(d).step_by(2).sum::<f64>());
            let total: f64 = f.chunks(2).map(|v| v[0].hypot(v[1])).sum();
            ratio[case] = sum[0].hypot(sum[1]) / total;
        }
        // f32 sums of ~256 terms per particle: relative round-off ~1e-6 per force.
        assert!(
            ratio[0] < 1e-5,
            "{law}: |sum F| / sum |F| = {:e} with alpha = mu",
            ratio[0]
        );
        assert!(
            ratio[1] > 1e-2,
            "{law}: |sum F| / sum |F| = {:e} with alpha != mu",
            ratio[1]
        );
    }
}

/// The force shader is a template (its path choice, `every_lane`, comes before it): both
/// forms validate, the subgroup one with subgroup operations, the other without them.
#[test]
fn forces_shader_validates_with_and_without_subgroups() {
    use mesoflow::gpu::shaders;
    use mesoflow::nodes::disks::forces::every_lane_source;
    let body = shaders::source("disks/forces.wgsl").expect("the force shader resolves");
    let plain = naga::valid::Capabilities::empty();
    let subgroups = naga::valid::Capabilities::SUBGROUP;
    crate::util::validate_wgsl(
        "forces, subgroups",
        &format!("{}{body}", every_lane_source(true)),
        subgroups,
    );
    crate::util::validate_wgsl(
        "forces, no subgroups",
        &format!("{}{body}", every_lane_source(false)),
        plain,
    );
}
