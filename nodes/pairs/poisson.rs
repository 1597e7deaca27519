//! The near field of the Ewald-split Poisson solver for Gaussian charges, in f64 on the
//! host (digest section 6.2, eq. 24.20).
//!
//! Two Gaussian charges of standard deviation a interact through
//! erf(r / (2a)) / (4 pi eps r); the far (Fourier) part of the split with Ewald parameter
//! xi is the same with the width widened to g_t = sqrt(a^2 + 1 / (4 xi^2)), so the near
//! part per unit charges is
//!
//! G(r) = (1 / (4 pi eps r)) [erf(r / (2a)) - erf(r / (2 g_t))],
//!
//! regular at r = 0 with G(0) = (1 / (4 pi^(3/2) eps)) (1/a - 1/g_t). The field at i from
//! j is -q_j G'(r) r^.

use std::f64::consts::PI;

/// Below this r / c, erf(r / c) / r and its derivative come from their Taylor series:
/// the closed form of the derivative, 2 exp(-x^2) / (sqrt(pi) c r) - erf(x) / r^2,
/// cancels like 1 / x^2.
const SERIES_BELOW: f64 = 0.5;

/// erf(r / c) / r, its r-derivative and the derivative over r, accurate in f64 down to
/// r = 0 (the derivative over r is regular there: -4 / (3 sqrt(pi) c^3)).
fn erf_over_r(r: f64, c: f64) -> (f64, f64, f64) {
    let x = r / c;
    let two_over_sqrt_pi = 2.0 / PI.sqrt();
    if x < SERIES_BELOW {
        // erf(x) = 2/sqrt(pi) sum_n (-1)^n x^(2n+1) / (n! (2n+1)); 20 terms reach
        // x^40 / 20! < 1e-30 at x = 0.5. With t_n = (-1)^n x^(2n) / (n! (2n+1)),
        // erf(x) / r = 2/(sqrt(pi) c) sum t_n, its derivative 2/(sqrt(pi) c) sum t_n 2n / r
        // and that over r 2/(sqrt(pi) c^3) sum_{n>=1} (-1)^n 2n x^(2n-2) / (n! (2n+1)).
        let x2 = x * x;
        let (mut value, mut slope, mut slope_over_r) = (0.0, 0.0, 0.0);
        let mut power = 1.0; // (-1)^n x^(2n) / n!
        let mut lower = 0.0; // (-1)^n x^(2n-2) / n! for n >= 1
        for n in 0..20 {
            let k = 2.0 * n as f64 + 1.0;
            value += power / k;
            if n > 0 {
                slope_over_r += lower * 2.0 * n as f64 / k;
                if x > 0.0 {
                    slope += power * 2.0 * n as f64 / (k * x * c);
                }
            }
            lower = -power / (n as f64 + 1.0);
            power *= -x2 / (n as f64 + 1.0);
        }
        (
            two_over_sqrt_pi * value / c,
            two_over_sqrt_pi * slope / c,
            two_over_sqrt_pi * slope_over_r / (c * c * c),
        )
    } else {
        let e = libm::erf(x);
        let slope = two_over_sqrt_pi * (-x * x).exp() / (c * r) - e / (r * r);
        (e / r, slope, slope / r)
    }
}

/// The width of the far part: g_t = sqrt(a^2 + 1 / (4 xi^2)).
pub fn far_width(width: f64, split: f64) -> f64 {
    (width * width + 1.0 / (4.0 * split * split)).sqrt()
}

/// (G(r), G'(r)) of the near field per unit charges.
pub fn near_potential(r: f64, width: f64, split: f64, permittivity: f64) -> (f64, f64) {
    let (g, dg, _) = near_terms(r, width, split, permittivity);
    (g, dg)
}

/// (G(r), G'(r), G'(r) / r) of the near field per unit charges; G'(r) / r is regular at 0,
/// where it is -(1/a^3 - 1/g_t^3) / (24 pi^(3/2) eps).
pub fn near_terms(r: f64, width: f64, split: f64, permittivity: f64) -> (f64, f64, f64) {
    let (narrow, narrow_slope, narrow_over) = erf_over_r(r, 2.0 * width);
    let (wide, wide_slope, wide_over) = erf_over_r(r, 2.0 * far_width(width, split));
    let c = 1.0 / (4.0 * PI * permittivity);
    (
        c * (narrow - wide),
        c * (narrow_slope - wide_slope),
        c * (narrow_over - wide_over),
    )
}

/// The self term G(0) = (1 / (4 pi^(3/2) eps)) (1/a - 1/g_t).
pub fn self_potential(width: f64, split: f64, permittivity: f64) -> f64 {
    (1.0 / width - 1.0 / far_width(width, split)) / (4.0 * PI.powf(1.5) * permittivity)
}

/// (G, G') at `points` equally spaced distances from 0 to the cutoff, for the GPU to
/// interpolate (the pair kernel reads G and G'/r: [`near_terms`]).
pub fn near_table(
    width: f64,
    split: f64,
    permittivity: f64,
    cutoff: f64,
    points: usize,
) -> Vec<[f64; 2]> {
    let step = cutoff / (points.max(2) - 1) as f64;
    (0..points.max(2))
        .map(|i| {
            let (g, dg) = near_potential(i as f64 * step, width, split, permittivity);
            [g, dg]
        })
        .collect()
}

/// The smallest r at which both the near potential and the near field have fallen to
/// `tolerance` of their largest values (G(0) and the peak of |G'|), on a scan of
/// min(a, g_t) / 256 steps; refused past half the smallest box length, where the
/// minimum image would no longer hold every neighbour within the cutoff.
pub fn poisson_cutoff(
    width: f64,
    split: f64,
    tolerance: f64,
    lengths: &[f64],
) -> Result<f64, String> {
    for (what, x) in [("width", width), ("split", split), ("tolerance", tolerance)] {
        if !(x.is_finite() && x > 0.0) {
            return Err(format!("{what} must be positive and finite, got {x}"));
        }
    }
    if tolerance >= 1.0 {
        return Err(format!("tolerance must be below 1, got {tolerance}"));
    }
    let half_box = lengths.iter().cloned().fold(f64::INFINITY, f64::min) / 2.0;
    // Permittivity scales G and G' alike: the relative decay does not depend on it.
    let g0 = self_potential(width, split, 1.0);
    let step = width.min(far_width(width, split)) / 256.0;
    let mut peak_field = 0.0f64;
    let mut r = 0.0;
    loop {
        let (g, dg) = near_potential(r, width, split, 1.0);
        peak_field = peak_field.max(dg.abs());
        if r > 0.0 && g.abs() <= tolerance * g0 && dg.abs() <= tolerance * peak_field {
            return Ok(r);
        }
        r += step;
        if r > half_box {
            return Err(format!(
                "the Poisson near field (width {width}, split {split}) needs a cutoff beyond half the smallest box length {half_box} for tolerance {tolerance}: raise the split or enlarge the box"
            ));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The closed form of G and G' straight from erf, for r away from 0.
    fn closed_form(r: f64, a: f64, xi: f64, eps: f64) -> (f64, f64) {
        let g = far_width(a, xi);
        let c = 1.0 / (4.0 * PI * eps);
        let phi = c * (libm::erf(r / (2.0 * a)) - libm::erf(r / (2.0 * g))) / r;
        let gauss = |w: f64| (-(r * r) / (4.0 * w * w)).exp() / (PI.sqrt() * w);
        let dphi = c * (gauss(a) - gauss(g)) / r - phi / r;
        (phi, dphi)
    }

    #[test]
    fn erf_matches_known_values() {
        // Abramowitz and Stegun table 7.1.
        for (x, e) in [
            (0.5, 0.520_499_877_813_046_5),
            (1.0, 0.842_700_792_949_714_9),
            (2.0, 0.995_322_265_018_952_7),
        ] {
            assert!((libm::erf(x) - e).abs() < 1e-15, "erf({x})");
        }
    }

    /// The table (series branch and closed-form branch) against the closed form, with
    /// both sides of the series switch and a finite-difference check of the derivative.
    #[test]
    fn near_potential_matches_closed_form() {
        let (a, xi, eps) = (0.7, 1.3, 2.0);
        for r in [0.05, 0.3, 0.69, 0.71, 1.0, 1.45, 2.0, 3.5] {
            let (phi, dphi) = near_potential(r, a, xi, eps);
            let (want, dwant) = closed_form(r, a, xi, eps);
            assert!(
                (phi - want).abs() <= 1e-12 * want.abs(),
                "G({r}) = {phi}, want {want}"
            );
            assert!(
                (dphi - dwant).abs() <= 1e-8 * dwant.abs(),
                "G'({r}) = {dphi}, want {dwant}"
            );
            let h = 1e-5;
            let fd = (near_potential(r + h, a, xi, eps).0 - near_potential(r - h, a, xi, eps).0)
                / (2.0 * h);
            assert!(
                (dphi - fd).abs() <= 1e-6 * dphi.abs(),
                "G'({r}) = {dphi}, finite difference {fd}"
            );
        }
    }

    /// r -> 0: G tends to the self term (the Taylor self term of digest 6.2,
    /// (1 / (4 pi^(3/2) eps)) (1/a - 1/g_t)) and G' to 0 linearly.
    #[test]
    fn near_potential_at_zero_is_the_self_term() {
        let (a, xi, eps) = (0.7, 1.3, 2.0);
        let g = far_width(a, xi);
        let taylor = (1.0 / a - 1.0 / g) / (4.0 * PI.powf(1.5) * eps);
        assert!((self_potential(a, xi, eps) - taylor).abs() <= 1e-13 * taylor);
        let (phi0, dphi0) = near_potential(0.0, a, xi, eps);
        assert!(
            (phi0 - taylor).abs() <= 1e-13 * taylor,
            "G(0) = {phi0}, want {taylor}"
        );
        assert_eq!(dphi0, 0.0);
        // G'(r) ~ -r (1/a^3 - 1/g^3) / (24 pi^(3/2) eps) near 0.
        let r = 1e-4;
        let slope = -r * (a.powi(-3) - g.powi(-3)) / (24.0 * PI.powf(1.5) * eps);
        let (_, d) = near_potential(r, a, xi, eps);
        assert!(
            (d - slope).abs() <= 1e-6 * slope.abs(),
            "G'({r}) = {d}, want {slope}"
        );
        // G'/r at 0 is that slope's coefficient, and continuous across the series switch.
        let (_, _, over0) = near_terms(0.0, a, xi, eps);
        assert!((over0 - slope / r).abs() <= 1e-6 * over0.abs(), "{over0}");
        for r in [1e-3, 0.3, 0.69, 0.71, 1.45, 2.0, 3.5] {
            let (_, d, over) = near_terms(r, a, xi, eps);
            assert!((over - d / r).abs() <= 1e-12 * over.abs(), "G'/r at {r}");
        }
        let table = near_table(a, xi, eps, 3.0, 301);
        assert_eq!(table[0][0], phi0);
        assert_eq!(table[300], {
            let (p, q) = near_potential(3.0, a, xi, eps);
            [p, q]
        });
    }

    #[test]
    fn cutoff_holds_the_tolerance_and_is_refused_past_half_the_box() {
        let (a, xi, tol) = (1.0, 0.5, 1e-4);
        let rc = poisson_cutoff(a, xi, tol, &[40.0, 40.0, 40.0]).unwrap();
        let g0 = self_potential(a, xi, 1.0);
        let (g, _) = near_potential(rc, a, xi, 1.0);
        assert!(g <= tol * g0);
        // The step before still fails the tolerance: it is the smallest such r.
        let step = a.min(far_width(a, xi)) / 256.0;
        let (before, dbefore) = near_potential(rc - step, a, xi, 1.0);
        let peak = (0..2000)
            .map(|i| near_potential(i as f64 * step, a, xi, 1.0).1.abs())
            .fold(0.0, f64::max);
        assert!(
            before > tol * g0 || dbefore.abs() > tol * peak,
            "cutoff {rc} is not the smallest"
        );
        let err = poisson_cutoff(a, xi, tol, &[40.0, 2.0 * rc - 1.0, 40.0]).unwrap_err();
        assert!(err.contains("half the smallest box length"), "{err}");
        assert!(
            poisson_cutoff(a, 0.0, tol, &[40.0])
                .unwrap_err()
                .contains("split")
        );
    }
}
