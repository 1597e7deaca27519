//! `brownian_step_2d` and `abp_move_2d` against their f64 references (the same Philox
//! draws), the clipping bound, and the paper's diffusion bias: each component's variance
//! is 0.995007 D dt (S1 eq. 1, noise sqrt(D dt), clipped at 3).

use mesoflow::nodes::disks::minimum_image;
use mesoflow::nodes::disks::step::clipped_variance;
use mesoflow::value::HostArray;

use crate::util::{Rng, flat_particles, gpu, random_points, run_node_and_reference};

/// Largest |gpu - ref| as a minimum image in the box (a value wrapped on one side of a
/// face and not on the other is the same point).
fn max_periodic_error(got: &HostArray, want: &[f64], l: [f64; 2]) -> f64 {
    got.data
        .to_f64()
        .iter()
        .zip(want)
        .enumerate()
        .map(|(i, (a, b))| minimum_image(a - b, l[i % 2]).abs())
        .fold(0.0, f64::max)
}

#[test]
fn brownian_step_matches_its_reference_and_stays_in_the_box() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(3);
    let l = [10.0, 8.0];
    let n = 4099;
    let x = flat_particles(&random_points(&mut rng, n, &l), 2);
    let v = flat_particles(&random_points(&mut rng, n, &[40.0, 40.0]), 2);
    let params = r#"{"seed": 5, "stream": 2, "dt": 0.01, "diffusion": 4.0, "box": [10, 8]}"#;
    let (out, refs) = run_node_and_reference("brownian_step_2d", params, &[("x", x), ("v", v)]);
    // |v dt| <= 0.2, noise <= 3 x 0.2: positions of magnitude 5, f32 rounding ~1e-6.
    let err = max_periodic_error(&out["out"], &refs[0].data, l);
    assert!(err < 1e-5, "error {err:e}");
    for (i, y) in out["out"].data.to_f64().iter().enumerate() {
        let half = 0.5 * l[i % 2];
        assert!(
            (-half..=half).contains(y),
            "element {i} = {y} outside the box"
        );
    }
}

/// One step from the origin with no force, open box: each displacement component is
/// clip(xi) sqrt(D dt), never beyond 3 sqrt(D dt), with variance 0.995007 D dt. 2^21
/// particles give 2^22 components: the variance's standard error sqrt((m4 - m2^2) / N)
/// is about 6.5e-4, so the measured value is within 4 standard errors of 0.995007 and
/// more than 6 away from the unclipped 1.
#[test]
fn clipped_noise_has_the_papers_variance() {
    if gpu().is_none() {
        return;
    }
    let n = 1usize << 21;
    let x = flat_particles(&vec![0.0; 2 * n], 2);
    let (d, dt) = (0.01f64, 0.01f64);
    let params = format!(r#"{{"seed": 9, "dt": {dt}, "diffusion": {d}}}"#);
    let (out, _) = run_node_and_reference("brownian_step_2d", &params, &[("x", x)]);
    let y = out["out"].data.to_f64();
    let amp = (d * dt).sqrt();
    let max = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(
        max <= 3.0 * amp * (1.0 + 1e-6),
        "largest step {max} > 3 sqrt(D dt)"
    );
    let clipped = y
        .iter()
        .filter(|v| v.abs() >= 3.0 * amp * (1.0 - 1e-6))
        .count();
    // P(|xi| > 3) = 0.0027: about 11320 of 2^22 components land on the bound.
    assert!(
        (10_800..11_900).contains(&clipped),
        "{clipped} clipped components"
    );
    let m2 = y.iter().map(|v| v * v).sum::<f64>() / y.len() as f64 / (amp * amp);
    let m4 = y.iter().map(|v| v.powi(4)).sum::<f64>() / y.len() as f64 / amp.powi(4);
    let se = ((m4 - m2 * m2) / y.len() as f64).sqrt();
    let want = clipped_variance(3.0);
    assert!(
        (m2 - want).abs() < 4.0 * se,
        "variance {m2} x D dt, want {want} (standard error {se:e})"
    );
    assert!(
        (m2 - 1.0).abs() > 6.0 * se,
        "variance {m2}: the clipping is not seen"
    );
}

#[test]
fn abp_move_matches_its_reference() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(4);
    let l = [12.0, 12.0];
    let n = 1000;
    let x = flat_particles(&random_points(&mut rng, n, &l), 2);
    let angle: Vec<f64> = (0..n).map(|_| rng.uniform(-10.0, 10.0)).collect();
    let angle = flat_particles(&angle, 1);
    let (out, refs) = run_node_and_reference(
        "abp_move_2d",
        r#"{"speed": 1.5, "dt": 0.1, "box": [12, 12]}"#,
        &[("x", x.clone()), ("angle", angle.clone())],
    );
    let err = max_periodic_error(&out["out"], &refs[0].data, l);
    assert!(err < 2e-6, "error {err:e}");
    // Every particle moved by speed dt = 0.15.
    let (a, b) = (x.data.to_f64(), out["out"].data.to_f64());
    for i in 0..n {
        let step = [0, 1].map(|d| minimum_image(b[2 * i + d] - a[2 * i + d], l[d]));
        let len = step[0].hypot(step[1]);
        assert!((len - 0.15).abs() < 1e-5, "particle {i} moved {len}");
    }
}
