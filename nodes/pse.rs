//! The Positively Split Ewald planner, on the host in f64 (UAMMD thesis section 20.2,
//! digest section 4; Fiore et al. 2017, after Lindbo and Tornberg 2011): from the radius,
//! the tolerance, the box and the splitting parameter xi to the far field's grid and
//! Gaussian and the near field's cutoff and cell list. The operators are generic nodes
//! composed by graphs/pse.json (the far field is graphs/fcm.json with the screened Green
//! function of `stokes`, the near field `neighbour_sum` with the `rpy_near` kernel).

use crate::nodes::fcm::plan::{check_tolerance, erfc_inverse, fast_fft_size};
use crate::nodes::fft::next_friendly;
use crate::nodes::fft::plan::{cells_per_axis, checked_grid};

/// Default splitting parameter: 0.5 / a (UAMMD's usual choice for dilute suspensions,
/// where the near field is cheap), raised where the near-field cutoff would exceed half
/// the smallest box side (the minimum image then misses pairs).
pub fn default_split(radius: f64, tolerance: f64, lengths: &[f64]) -> Result<f64, String> {
    let half = 0.5 * lengths.iter().copied().fold(f64::INFINITY, f64::min);
    let xi = 0.5 / radius;
    if cutoff(radius, xi, tolerance)? <= half {
        return Ok(xi);
    }
    // The cutoff falls as xi grows: bisect for the smallest xi that fits.
    let (mut lo, mut hi) = (xi, xi);
    while cutoff(radius, hi, tolerance)? > half {
        hi *= 2.0;
        if hi > 64.0 / radius {
            return Err(format!(
                "the box (smallest side {}) is too small for PSE at radius {radius}: the near field reaches further than half of it at any split",
                2.0 * half
            ));
        }
    }
    while hi - lo > 1e-6 * hi {
        let mid = 0.5 * (lo + hi);
        if cutoff(radius, mid, tolerance)? > half {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Ok(hi)
}

/// Near-field cutoff: where the near field falls below tol / 2 of the self-mobility
/// (`near_cutoff`; about sqrt(-ln tol) / xi, thesis eq. 20.19, at small xi a, and up to
/// 2a further at large xi a, where the shells of the RPY spheres widen the screening).
pub fn cutoff(radius: f64, split: f64, tolerance: f64) -> Result<f64, String> {
    crate::nodes::pairs::rpy::near_cutoff(radius, split, 0.5 * tolerance)
}

/// Far-field cells per axis: wave numbers up to k_cut = 2 xi sqrt(-ln tol) (where
/// Hasimoto's factor falls to tol, eq. 20.18), so h = pi / k_cut; FFT-friendly, and the
/// fast size (2^a or 3 * 2^a) when it is at most 4% finer.
/// Each axis is bounded (`cells_per_axis`, `checked_grid`) before it is converted.
pub fn grid(lengths: &[f64], split: f64, tolerance: f64) -> Result<Vec<u32>, String> {
    check_tolerance(tolerance)?;
    let k_cut = 2.0 * split * (-tolerance.ln()).sqrt();
    let h = std::f64::consts::PI / k_cut;
    let cells = lengths
        .iter()
        .map(|l| {
            let what = format!("the PSE far field (box length {l}, split {split})");
            let n = next_friendly(cells_per_axis(&what, ((l / h).floor() + 1.0).max(8.0))?);
            let fast = fast_fft_size(n);
            Ok(if (fast as f64) <= 1.04 * n as f64 {
                fast
            } else {
                n
            })
        })
        .collect::<Result<Vec<u32>, String>>()?;
    checked_grid("the PSE far field", cells)
}

/// The number of standard deviations m the far-field Gaussian is cut at: the quadrature
/// error erfc(m / sqrt 2) at most tol / 10.
fn deviations(tolerance: f64) -> f64 {
    std::f64::consts::SQRT_2 * erfc_inverse(0.1 * tolerance)
}

/// The Lindbo-Tornberg support P that shapes the far-field Gaussian: P with m = 0.976
/// sqrt(pi P) (Lindbo and Tornberg), odd, at most the smallest grid side. [`width`] of
/// it sets the Gaussian; [`support`] then cuts that Gaussian where the tolerance allows.
pub fn shape_support(tolerance: f64, cells: &[u32]) -> u32 {
    let m = deviations(tolerance);
    let mut p = ((m / 0.976).powi(2) / std::f64::consts::PI).ceil() as u32;
    if p.is_multiple_of(2) {
        p += 1;
    }
    let smallest = cells.iter().copied().min().unwrap_or(p);
    p.min(smallest).max(3)
}

/// Far-field support in cells: the Gaussian of standard deviation `width` cut at the m
/// deviations the tolerance needs (erfc(m / sqrt 2) at most tol / 10), 2 m width / h
/// cells rounded up (even or odd), 3 at least and at most the smallest grid side. The
/// Lindbo-Tornberg support the width comes from rounds P up to an odd count: at tol
/// 1e-3, 7 cells where 5.95 suffice (3.92 deviations each side against the 3.89 needed),
/// so the spreading and interpolation of 6^3 points instead of 7^3.
pub fn support(tolerance: f64, lengths: &[f64], cells: &[u32], width: f64) -> u32 {
    // The finest cell needs the most cells to cover the cut.
    let h = finest_cell(lengths, cells);
    let p = (2.0 * deviations(tolerance) * width / h - 1e-9)
        .ceil()
        .max(3.0) as u32;
    let smallest = cells.iter().copied().min().unwrap_or(p);
    p.min(smallest.max(3))
}

/// Standard deviation of the far-field Gaussian for a support of P cells: the half width
/// w = P h / 2 over m = 0.976 sqrt(pi P) (Lindbo and Tornberg), on the finest cell of the
/// grid (sigma^2 = lambda / (4 xi^2), eq. 20.17): sigma = 0.765 h for P = 7. Taking m
/// from P rather than from the tolerance means that rounding P up to an odd count cuts
/// the Gaussian further out instead of making it narrower.
pub fn width(lengths: &[f64], cells: &[u32], support: u32) -> f64 {
    let h = finest_cell(lengths, cells);
    let p = support as f64;
    0.5 * p * h / (0.976 * (std::f64::consts::PI * p).sqrt())
}

/// The smallest cell size of the far-field grid over the axes.
fn finest_cell(lengths: &[f64], cells: &[u32]) -> f64 {
    lengths
        .iter()
        .zip(cells)
        .map(|(l, &n)| l / n as f64)
        .fold(f64::INFINITY, f64::min)
}

/// Cells per axis of the near field's cell list: as many as keep cells at least the
/// cutoff wide (at most 1024).
pub fn neighbour_cells(lengths: &[f64], cutoff: f64) -> Vec<u32> {
    lengths
        .iter()
        .map(|l| ((l / cutoff).floor() as u32).clamp(1, 1024))
        .collect()
}

/// The periodic RPY mobility tensor (row-major 3x3) at separation r in a cubic box of
/// side l, in f64 by Ewald summation at splitting parameter `xi`: the near field over
/// the lattice images (a fine table of `rpy::NearTable`) plus the direct Fourier sum of
/// the far field. `mesoflow bench pse` measures errors against it (at a split other than
/// the one benchmarked); the tests have an independent copy.
pub fn periodic_rpy(
    r: [f64; 3],
    l: f64,
    a: f64,
    eta: f64,
    xi: f64,
) -> Result<[[f64; 3]; 3], String> {
    use std::f64::consts::PI;
    let reach = crate::nodes::pairs::rpy::near_cutoff(a, xi, 1e-12)?;
    let table = crate::nodes::pairs::rpy::NearTable::new(a, eta, xi, reach, 20001)?;
    let mut m = [[0.0; 3]; 3];
    let add = |f: f64, g: f64, d: [f64; 3], m: &mut [[f64; 3]; 3]| {
        let d2: f64 = d.iter().map(|x| x * x).sum();
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += if i == j { f } else { 0.0 }
                    + if d2 > 0.0 { g * d[i] * d[j] / d2 } else { 0.0 };
            }
        }
    };
    let images = (reach / l).ceil() as i64 + 1;
    for nx in -images..=images {
        for ny in -images..=images {
            for nz in -images..=images {
                let d = [
                    r[0] + nx as f64 * l,
                    r[1] + ny as f64 * l,
                    r[2] + nz as f64 * l,
                ];
                let dist = d.iter().map(|x| x * x).sum::<f64>().sqrt();
                if dist <= reach {
                    let (f, g) = table.at(dist);
                    add(f, g, d, &mut m);
                }
            }
        }
    }
    let k_max = 2.0 * xi * 40f64.sqrt();
    let dk = 2.0 * PI / l;
    let kn = (k_max / dk).ceil() as i64;
    for kx in -kn..=kn {
        for ky in -kn..=kn {
            for kz in -kn..=kn {
                let k = [kx as f64 * dk, ky as f64 * dk, kz as f64 * dk];
                let k2: f64 = k.iter().map(|x| x * x).sum();
                if k2 == 0.0 || k2 > k_max * k_max {
                    continue;
                }
                let phase = (k[0] * r[0] + k[1] * r[1] + k[2] * r[2]).cos();
                let c = phase * crate::nodes::spectral::pse_screening(k2, a, xi, 0.0)
                    / (eta * k2 * l * l * l);
                for i in 0..3 {
                    for j in 0..3 {
                        m[i][j] += c * (if i == j { 1.0 } else { 0.0 } - k[i] * k[j] / k2);
                    }
                }
            }
        }
    }
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uammd_sizes() {
        // UAMMD's benchmark: a = 1, tol 1e-3, L = 128, xi = 0.5: k_cut = 2.63, h = 1.19.
        let g = grid(&[128.0; 3], 0.5, 1e-3).unwrap();
        assert_eq!(g, vec![108; 3]);
        let rc = cutoff(1.0, 0.5, 1e-3).unwrap();
        assert!(rc > 5.2565 && rc < 6.5, "{rc}");
        assert_eq!(neighbour_cells(&[128.0; 3], 5.3), vec![24; 3]);
        assert_eq!(shape_support(1e-3, &g), 7);
        let sigma = width(&[128.0; 3], &g, 7);
        assert_eq!(support(1e-3, &[128.0; 3], &g, sigma), 6);
        // At 1e-2 and 1e-4 the odd Lindbo-Tornberg count is what the cut needs.
        for (tol, p) in [(1e-2, 5), (1e-4, 7)] {
            let sigma = width(&[128.0; 3], &g, shape_support(tol, &g));
            assert_eq!(support(tol, &[128.0; 3], &g, sigma), p, "{tol}");
        }
    }

    #[test]
    fn periodic_rpy_self_is_hasimoto() {
        let m = periodic_rpy([0.0; 3], 20.0, 1.0, 1.0, 0.7).unwrap();
        let want = crate::nodes::fcm::plan::hasimoto(1.0, 20.0) / (6.0 * std::f64::consts::PI);
        assert!(
            (m[0][0] / want - 1.0).abs() < 1e-5,
            "{} against {want}",
            m[0][0]
        );
    }

    #[test]
    fn split_grows_for_small_boxes() {
        assert_eq!(default_split(1.0, 1e-3, &[128.0; 3]), Ok(0.5));
        let s = default_split(1.0, 1e-3, &[8.0, 8.0, 8.0]).unwrap();
        assert!(2.0 * cutoff(1.0, s, 1e-3).unwrap() <= 8.0 && s > 0.5);
        let s = default_split(1.0, 1e-3, &[2.0, 8.0, 8.0]).unwrap();
        assert!(cutoff(1.0, s, 1e-3).unwrap() <= 1.0);
    }
}
