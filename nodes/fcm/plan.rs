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
//! - ES: support w = ceil((-log10 tol + 2) / 2) cells (at least 2), beta = 3.6 w, and
//!   h = 1.36409985665115 w^-0.53028415751646 a (UAMMD's fit of the measured radius).
//!   The radius follows the actual cell size.

use crate::nodes::fft::next_friendly;

/// Empirical upsampling of the Gaussian window (thesis Eq. 21.21).
pub fn gaussian_upsampling(tolerance: f64) -> f64 {
    (0.55 - 0.11 * (3.0 * tolerance).log10()).min(1.65)
}

/// ES support in cells for a tolerance (UAMMD's FCM rule, at least 2).
pub fn es_support(tolerance: f64) -> u32 {
    (((-tolerance.log10() + 2.0) / 2.0).clamp(1.5, 9.0).ceil() as u32).max(2)
}

/// ES shape parameter for a support.
pub fn es_beta(support: u32) -> f64 {
    3.6 * support as f64
}

/// Radius per cell size, a / h, of a window on the actual grid.
pub fn radius_per_cell(kernel: &str, tolerance: f64) -> Result<f64, String> {
    Ok(match kernel {
        "gaussian" => std::f64::consts::PI.sqrt() * gaussian_upsampling(tolerance),
        "peskin3" => 1.0,
        "peskin4" => 1.31,
        "peskin6" => 1.5195,
        "es" => {
            1.0 / (1.364_099_856_651_15
                * (es_support(tolerance) as f64).powf(-0.530_284_157_516_46))
        }
        other => {
            return Err(format!(
                "unknown kernel `{other}` (kernels: gaussian, es, peskin3, peskin4, peskin6)"
            ));
        }
    })
}

/// FFT-friendly cells per axis: the next friendly size from L / h truncated, as UAMMD
/// does (so the grids of its benchmarks are the same here); the actual cell size can
/// exceed the target by less than one cell's worth over the box.
pub fn grid(
    lengths: &[f64],
    radius: f64,
    tolerance: f64,
    kernel: &str,
) -> Result<Vec<u32>, String> {
    if radius <= 0.0 {
        return Err(format!("the radius must be positive, got {radius}"));
    }
    let h = radius / radius_per_cell(kernel, tolerance)?;
    lengths
        .iter()
        .map(|&l| {
            if l <= 0.0 {
                return Err(format!("box lengths must be positive, got {l}"));
            }
            let n = (l / h).floor().max(1.0);
            if n > 4096.0 {
                return Err(format!(
                    "a box length of {l} needs {n} cells of {h:.4} for radius {radius}; more than the 4096 an FFT axis takes"
                ));
            }
            Ok(next_friendly(n as u32))
        })
        .collect()
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

    /// UAMMD's grids for the benchmark boxes (a = 1, Gaussian).
    #[test]
    fn grids_match_uammd() {
        for (l, tol, n) in [
            (64.0, 1e-2, 81),
            (127.0, 1e-2, 162),
            (264.0, 1e-2, 336),
            (65.0, 1e-3, 96),
            (129.0, 1e-3, 189),
            (256.0, 1e-3, 375),
            (65.0, 1e-4, 108),
            (130.0, 1e-4, 216),
            (260.0, 1e-4, 432),
        ] {
            assert_eq!(
                grid(&[l], 1.0, tol, "gaussian").unwrap(),
                vec![n],
                "L = {l}, tolerance {tol}"
            );
        }
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
