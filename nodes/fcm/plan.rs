//! The FCM planner, on the host in f64: from the hydrodynamic radius, the tolerance, the
//! window and the box to the grid and the window's parameters (UAMMD thesis section 20.1
//! and the digest's section 3.4), and the references FCM is checked against.
//!
//! Radius relations (how each window's width ties to the hydrodynamic radius a):
//! - Gaussian: sigma = a / sqrt(pi), exactly (the self-convolved Gaussian gives the
//!   Stokes drag 6 pi eta a); the cell size is h = a / (sqrt(pi) g_u(tol)) with the
//!   empirical upsampling g_u(tol) = min(0.55 - 0.11 log10(3 tol), 1.65), and the support
//!   follows from the tolerance on the actual grid. The radius stays exactly a whatever
//!   grid the FFT-friendly rounding gives.
//! - Peskin 3, 4, 6 point: a = 1.00 h, 1.31 h, 1.5195 h (measured, thesis section 21.2);
//!   the tolerance does not apply, and the radius follows the actual cell size.
//! - ES: support w = ceil(-log10 tol) + 2 cells, beta = 2.3 w, and a / h the hydrodynamic
//!   radius of the continuous window, computed ([`window_radius_cells`]): 1.09, 1.24 and
//!   1.37 for w = 4, 5, 6. (UAMMD's heuristic, beta = 3.6 w on ceil((2 - log10 tol) / 2)
//!   cells with its fitted radius, gave self-mobilities 20 to 50 % off here: its
//!   windows of 2 or 3 cells are narrower than the radius fit assumes.) The radius
//!   follows the actual cell size.

use crate::expr::fmt_number;
use crate::nodes::fft::next_friendly;
use crate::nodes::fft::plan::{cells_per_axis, checked_grid};

/// Empirical upsampling of the Gaussian window (thesis Eq. 21.21).
pub fn gaussian_upsampling(tolerance: f64) -> f64 {
    (0.55 - 0.11 * (3.0 * tolerance).log10()).min(1.65)
}

/// ES support in cells for FCM at a tolerance: ceil(-log10 tol) + 2 (4, 5 and 6 cells at
/// 1e-2, 1e-3 and 1e-4). One cell more than the NUFFT rule of the spread node: FCM ties
/// the grid to the radius, and what limits it is translational invariance, measured at
/// about 3e-3, 7e-4 and 2e-4 of the self-mobility for supports 4, 5 and 6 (beta = 2.3 w).
pub fn es_support(tolerance: f64) -> u32 {
    ((-tolerance.log10()).ceil().max(0.0) as u32 + 2).max(3)
}

/// ES shape parameter for a support: Barnett's 2.3 per cell.
pub fn es_beta(support: u32) -> f64 {
    2.3 * support as f64
}

/// The hydrodynamic radius of a separable window in units of its cell, a / h: the
/// free-space self-mobility of the continuous window, mu = (2/3) int d^3k |phi^(k)|^2 /
/// ((2 pi)^3 eta k^2), as a = 1 / (6 pi eta mu). With 1/k^2 = int_0^inf exp(-t k^2) dt the
/// 3-D integral is one over t of the cube of a 1-D one, so it costs milliseconds in f64.
/// For the Gaussian of standard deviation s cells it is sqrt(pi) s (checked in the tests).
pub fn window_radius_cells(phi: impl Fn(f64) -> f64, half_width: f64) -> f64 {
    use std::f64::consts::PI;
    // phi^(k) = int phi(x) cos(k x) dx by Simpson over the support (phi is even).
    let nx = 2000;
    let dx = 2.0 * half_width / nx as f64;
    let samples: Vec<(f64, f64)> = (0..=nx)
        .map(|i| {
            let x = -half_width + i as f64 * dx;
            let w = if i == 0 || i == nx {
                1.0
            } else if i % 2 == 1 {
                4.0
            } else {
                2.0
            };
            (x, w * phi(x) * dx / 3.0)
        })
        .collect();
    let norm: f64 = samples.iter().map(|s| s.1).sum();
    let (kmax, nk) = (80.0, 8000);
    let dk = kmax / nk as f64;
    let spectrum: Vec<f64> = (0..=nk)
        .map(|j| {
            let k = j as f64 * dk;
            let f: f64 = samples.iter().map(|&(x, w)| w * (k * x).cos()).sum::<f64>() / norm;
            f * f
        })
        .collect();
    // I(t) = int_-inf^inf phi^2 exp(-t k^2) dk (trapezoid on k >= 0, doubled).
    let line = |t: f64| -> f64 {
        let mut s = 0.0;
        for (j, p) in spectrum.iter().enumerate() {
            let k = j as f64 * dk;
            let w = if j == 0 || j == nk { 0.5 } else { 1.0 };
            s += w * p * (-t * k * k).exp();
        }
        2.0 * s * dk
    };
    // t on a log grid from 1e-6 to 1e4 (trapezoid in log t), plus the tail where phi^ = 1:
    // I = sqrt(pi / t), int_T^inf I^3 dt = 2 pi^(3/2) / sqrt(T).
    let (t0, t1, nt) = (1e-6f64, 1e4f64, 3000);
    let step = (t1 / t0).ln() / nt as f64;
    let mut integral = line(t0).powi(3) * t0; // t < t0, where I is flat
    let mut prev = line(t0).powi(3) * t0;
    for i in 1..=nt {
        let t = t0 * (step * i as f64).exp();
        let cur = line(t).powi(3) * t;
        integral += 0.5 * (prev + cur) * step;
        prev = cur;
    }
    integral += 2.0 * PI.powf(1.5) / t1.sqrt();
    let mu = (2.0 / 3.0) * integral / (2.0 * PI).powi(3);
    1.0 / (6.0 * PI * mu)
}

/// a / h of FCM's ES window at a tolerance (support and beta from the rules above).
pub fn es_radius_per_cell(tolerance: f64) -> f64 {
    let w = es_support(tolerance);
    let window = crate::nodes::spread::window::Window::es(es_beta(w), w);
    window_radius_cells(|x| window.phi(x, 1.0), w as f64 / 2.0)
}

/// Radius per cell size, a / h, of a window on the actual grid.
pub fn radius_per_cell(kernel: &str, tolerance: f64) -> Result<f64, String> {
    Ok(match kernel {
        "gaussian" => std::f64::consts::PI.sqrt() * gaussian_upsampling(tolerance),
        "peskin3" => 1.0,
        "peskin4" => 1.31,
        "peskin6" => 1.5195,
        "es" => es_radius_per_cell(tolerance),
        other => {
            return Err(format!(
                "unknown kernel `{other}` (kernels: gaussian, es, peskin3, peskin4, peskin6)"
            ));
        }
    })
}

/// FFT-friendly cells per axis: the next friendly size from L / h truncated, as UAMMD
/// does (so the grids of its benchmarks are the same here), or rounded up where
/// truncating would make the cells more than 1 % coarser than h (small boxes).
pub fn grid(
    lengths: &[f64],
    radius: f64,
    tolerance: f64,
    kernel: &str,
) -> Result<Vec<u32>, String> {
    grid_for(lengths, radius, tolerance, kernel, false)
}

/// The cells the torque Gaussian's standard deviation must span at a tolerance:
/// g_u(tol / 10). Rotation has no 1/k^2 to damp the aliased high modes as translation
/// has, so at the force's g_u(tol) the angular velocity of one sphere is off by about
/// 3 tol (measured at tol 1e-3, L = 32 a); a tenth of the tolerance brings it under tol.
pub fn rotation_upsampling(tolerance: f64) -> f64 {
    gaussian_upsampling(tolerance / 10.0)
}

/// [`grid`], and with `rotation` fine enough for the torque Gaussian too: its standard
/// deviation, a / (6 sqrt(pi))^(1/3), must span [`rotation_upsampling`] cells (about
/// 1.4 times finer per axis than the forces need). Only the Gaussian kernel has a torque
/// window of its own: the others tie the radius to the cell, and the torque Gaussian of
/// that radius would always be narrower than the cells resolve.
pub fn grid_for(
    lengths: &[f64],
    radius: f64,
    tolerance: f64,
    kernel: &str,
    rotation: bool,
) -> Result<Vec<u32>, String> {
    if !(radius > 0.0 && radius.is_finite()) {
        return Err(format!(
            "the radius must be positive and finite, got {radius}"
        ));
    }
    check_tolerance(tolerance)?;
    let h = radius / radius_per_cell(kernel, tolerance)?;
    // The torque Gaussian's spacing is a bound (the guard `min_width_cells` checks it),
    // so its cell count rounds up; the force grid rounds down as UAMMD's does.
    let h_rotation = if rotation {
        if kernel != "gaussian" {
            return Err(format!(
                "rotation (torques and angular velocities) needs the gaussian kernel, not `{kernel}`: its window ties the radius to the cell size, and the torque Gaussian of that radius is narrower than the cells resolve"
            ));
        }
        Some(torque_width(radius) / rotation_upsampling(tolerance))
    } else {
        None
    };
    lengths
        .iter()
        .map(|&l| {
            if !(l > 0.0 && l.is_finite()) {
                return Err(format!("box lengths must be positive and finite, got {l}"));
            }
            // Bounded before any conversion to u32 (1e30 / h saturates it).
            let what = format!(
                "a box length of {} for radius {}",
                fmt_number(l),
                fmt_number(radius)
            );
            cells_per_axis(&what, (l / h).floor().max(1.0))?;
            // Down as UAMMD rounds (its benchmark grids), unless that coarsens the cells
            // by more than 1 % (small boxes: 8.8 cells would become 8).
            let mut n = (l / h).floor().max(1.0);
            if l / next_friendly(n as u32) as f64 > 1.01 * h {
                n = (l / h).ceil();
            }
            if let Some(hr) = h_rotation {
                n = n.max((l / hr).ceil());
            }
            let friendly = next_friendly(cells_per_axis(&what, n)?);
            if kernel == "gaussian" {
                // A slightly finer grid keeps the Gaussian's radius (it is not tied to
                // the cell) and, with the same support, its accuracy.
                let sigma = gaussian_width(radius);
                let support = |cells: u32| gaussian_support(tolerance, sigma * cells as f64 / l);
                let fast = fast_fft_size(friendly);
                if fast as f64 <= FAST_SIZE_STRETCH * friendly as f64
                    && support(fast) == support(friendly)
                {
                    return Ok(fast);
                }
            }
            Ok(friendly)
        })
        .collect::<Result<Vec<u32>, String>>()
        .and_then(|cells| checked_grid("the FCM grid", cells))
}

/// A planner's tolerance: in (0, 1), so that its logarithms and the support rules built
/// on them stay finite.
pub fn check_tolerance(tolerance: f64) -> Result<(), String> {
    if tolerance > 0.0 && tolerance < 1.0 {
        Ok(())
    } else {
        Err(format!(
            "the tolerance must lie strictly between 0 and 1, got {tolerance}"
        ))
    }
}

/// How much finer than the FFT-friendly size a fast size may make the grid.
pub const FAST_SIZE_STRETCH: f64 = 1.04;

/// The smallest size >= n of the form 2^a or 3 * 2^a. Transforms of these sizes move
/// about 2.2 TB/s on an H100 against 1.2-1.6 TB/s for sizes with factors 5, 7 or 3^k
/// (BENCHMARKS.md: 192^3 in 0.46 ms, 189^3 in 0.80 ms), so FCM's Gaussian grid takes
/// one when it is at most [`FAST_SIZE_STRETCH`] times the friendly size and the window's
/// support stays the same.
pub fn fast_fft_size(n: u32) -> u32 {
    let n = n.max(1);
    n.next_power_of_two()
        .min(3 * n.div_ceil(3).next_power_of_two())
}

/// Complementary error function, relative error below 1.2e-7 (Numerical Recipes'
/// Chebyshev fit); enough for support rules, which round up to whole cells.
pub fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = -z * z - 1.265_512_23
        + t * (1.000_023_68
            + t * (0.374_091_96
                + t * (0.096_784_18
                    + t * (-0.186_288_06
                        + t * (0.278_868_07
                            + t * (-1.135_203_98
                                + t * (1.488_515_87 + t * (-0.822_152_23 + t * 0.170_872_77))))))));
    let r = t * poly.exp();
    if x >= 0.0 { r } else { 2.0 - r }
}

/// The x >= 0 with erfc(x) = y, for 0 < y <= 1 (bisection).
pub fn erfc_inverse(y: f64) -> f64 {
    let (mut lo, mut hi) = (0.0, 10.0);
    for _ in 0..80 {
        let mid = 0.5 * (lo + hi);
        if erfc(mid) > y {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Support in cells of an FCM Gaussian whose standard deviation spans `sigma_cells`
/// cells: the window is cut where the particle's nearest support edge, (S - 1) / 2
/// cells away, leaves a tail of at most 2 tol per axis, S = ceil(1 + 2 sqrt(2)
/// (sigma / h) erfc^-1(2 tol)), at least 3. On the nominal grids (sigma = g_u h) this
/// is UAMMD's support at tolerances 1e-2 and 1e-4 (5 and 8 cells) and one more at 1e-3
/// (7, not 6): with 6 the worst self-mobility error over random positions was 1.4e-3
/// (5.6e-4 with 7; L = 16 a). It scales with sigma / h, so a finer grid (rotation, or set
/// by hand) cuts the window at the same number of standard deviations.
pub fn gaussian_support(tolerance: f64, sigma_cells: f64) -> u32 {
    let s = 1.0 + 2.0 * std::f64::consts::SQRT_2 * sigma_cells * erfc_inverse(2.0 * tolerance);
    // Round down what is a cell above a whole number only by rounding error.
    ((s - 1e-9).ceil() as u32).max(3)
}

/// The hydrodynamic radius the window has on the actual grid (cubic cells for the
/// tied windows; the geometric mean cell size otherwise).
pub fn effective_radius(
    lengths: &[f64],
    cells: &[u32],
    radius: f64,
    tolerance: f64,
    kernel: &str,
) -> Result<f64, String> {
    if kernel == "gaussian" {
        return Ok(radius);
    }
    let h = lengths
        .iter()
        .zip(cells)
        .map(|(l, &n)| (l / n as f64).ln())
        .sum::<f64>()
        / lengths.len() as f64;
    Ok(h.exp() * radius_per_cell(kernel, tolerance)?)
}

/// The standard deviation of FCM's force Gaussian, a / sqrt(pi): the mobility of an
/// isolated sphere is then 1 / (6 pi eta a).
pub fn gaussian_width(radius: f64) -> f64 {
    radius / std::f64::consts::PI.sqrt()
}

/// The standard deviation of FCM's torque Gaussian, a / (6 sqrt(pi))^(1/3): the
/// rotational mobility of an isolated sphere is then 1 / (8 pi eta a^3) (thesis Eq. 20.9).
pub fn torque_width(radius: f64) -> f64 {
    radius / (6.0 * std::f64::consts::PI.sqrt()).cbrt()
}

/// Cells per axis of the Morton order FCM sorts particles in (see graphs/fcm.json): eight
/// grid cells each, so that particles served together touch overlapping supports; at most
/// 1024 per axis (30-bit keys). Eight rather than four: up to 256^3 grid cells the keys
/// then take 15 bits, two passes of the 8-bit radix sort instead of three.
pub fn sort_cells(grid_cells: f64) -> f64 {
    (grid_cells / 8.0).ceil().clamp(1.0, 1024.0)
}

/// Hasimoto's self-mobility of a sphere in a cubic periodic box, times 6 pi eta a
/// (thesis Eq. 21.18): 1 - b x + (4 pi / 3) x^3 - c x^6 with x = a / L.
pub fn hasimoto(radius: f64, length: f64) -> f64 {
    let x = radius / length;
    let b = 2.837_297_479_480_619_5;
    let c = 16.0 * std::f64::consts::PI.powi(2) / 45.0 + 630.0 * 0.19457f64.powi(2);
    1.0 - b * x + 4.0 * std::f64::consts::PI / 3.0 * x.powi(3) - c * x.powi(6)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The digest's Hasimoto values (section 13.2, item 8).
    #[test]
    fn hasimoto_values() {
        for (x, want) in [
            (8.0, 0.65341468),
            (16.0, 0.82368993),
            (32.0, 0.91146226),
            (64.0, 0.95568321),
            (128.0, 0.97783561),
        ] {
            assert!(
                (hasimoto(1.0, x) - want).abs() < 2e-8,
                "a/L = 1/{x}: {}",
                hasimoto(1.0, x)
            );
        }
    }

    /// The Gaussian rule against the digest's table (section 1.5): a/h per tolerance.
    #[test]
    fn gaussian_radius_per_cell() {
        for (tol, a_h) in [
            (1e-2, 1.2718),
            (1e-3, 1.4667),
            (1e-4, 1.6617),
            (1e-5, 1.8567),
        ] {
            assert!(
                (radius_per_cell("gaussian", tol).unwrap() - a_h).abs() < 1e-4,
                "{tol}"
            );
        }
    }

    #[test]
    fn erfc_and_its_inverse() {
        for (x, want) in [
            (0.0, 1.0),
            (0.5, 0.479_500_122),
            (1.0, 0.157_299_207),
            (2.0, 4.677_734_981e-3),
            (3.0, 2.209_049_700e-5),
            (-1.0, 1.842_700_793),
        ] {
            assert!(
                (erfc(x) / want - 1.0).abs() < 2e-7,
                "erfc({x}) = {}",
                erfc(x)
            );
        }
        for y in [0.5, 1e-2, 1e-5, 1e-9] {
            assert!((erfc(erfc_inverse(y)) / y - 1.0).abs() < 1e-6, "{y}");
        }
    }

    /// The FCM Gaussian support on the nominal grids (sigma = g_u h).
    #[test]
    fn fcm_gaussian_supports() {
        for (tol, s) in [(1e-2, 5), (1e-3, 7), (1e-4, 8), (1e-5, 10)] {
            assert_eq!(
                gaussian_support(tol, gaussian_upsampling(tol)),
                s,
                "tolerance {tol}"
            );
        }
        // Twice as many cells per sigma, about twice the support.
        assert_eq!(gaussian_support(1e-3, 2.0 * gaussian_upsampling(1e-3)), 12);
    }

    /// The radius integral: sqrt(pi) sigma for a Gaussian; the ES values the self-mobility
    /// measured on the GPU implies (1.094, 1.235, 1.365 for supports 4, 5, 6 at L = 16 a).
    #[test]
    fn window_radii() {
        let s = 0.9;
        let g = window_radius_cells(|x| (-0.5 * x * x / (s * s)).exp(), 9.0);
        assert!(
            (g / (std::f64::consts::PI.sqrt() * s) - 1.0).abs() < 1e-4,
            "{g}"
        );
        for (tol, want) in [(1e-2, 1.094), (1e-3, 1.235), (1e-4, 1.365)] {
            let r = es_radius_per_cell(tol);
            assert!((r / want - 1.0).abs() < 1e-2, "{tol}: {r} vs {want}");
        }
    }

    /// UAMMD's grids for the benchmark boxes (a = 1, Gaussian), and where a fast
    /// FFT size within 4 % with the same support replaces them (189 -> 192, 375 -> 384 at
    /// 1e-3; 162 -> 192 would be 19 % finer).
    #[test]
    fn grids_match_uammd_or_a_fast_size() {
        for (l, tol, uammd, n) in [
            (64.0, 1e-2, 81, 81),
            (127.0, 1e-2, 162, 162),
            (264.0, 1e-2, 336, 336),
            (65.0, 1e-3, 96, 96),
            (129.0, 1e-3, 189, 192),
            (256.0, 1e-3, 375, 384),
            (65.0, 1e-4, 108, 108),
            (130.0, 1e-4, 216, 216),
            (260.0, 1e-4, 432, 432),
        ] {
            assert_eq!(
                grid(&[l], 1.0, tol, "gaussian").unwrap(),
                vec![n],
                "L = {l}, tolerance {tol}"
            );
            let sigma_cells = |cells: u32| gaussian_width(1.0) * cells as f64 / l;
            assert_eq!(
                gaussian_support(tol, sigma_cells(n)),
                gaussian_support(tol, sigma_cells(uammd)),
                "L = {l}"
            );
        }
        assert_eq!(
            [1, 2, 3, 5, 7, 13, 25, 96, 97, 189, 375, 385].map(fast_fft_size),
            [1, 2, 3, 6, 8, 16, 32, 96, 128, 192, 384, 512]
        );
        assert!(
            grid(&[1e5], 1.0, 1e-3, "gaussian")
                .unwrap_err()
                .contains("4096")
        );
        assert!(
            grid(&[10.0], 1.0, 1e-3, "cubic")
                .unwrap_err()
                .contains("unknown kernel")
        );
    }
}
