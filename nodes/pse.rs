//! The Positively Split Ewald planner, on the host in f64 (UAMMD thesis section 20.2,
//! digest section 4; Fiore et al. 2017, after Lindbo and Tornberg 2011): from the radius,
//! the tolerance, the box and the splitting parameter xi to the far field's grid and
//! Gaussian and the near field's cutoff and cell list. The operators are generic nodes
//! composed by graphs/pse.json (the far field is graphs/fcm.json with the screened Green
//! function of `stokes`, the near field `neighbour_sum` with the `rpy_near` kernel).

use crate::nodes::fcm::plan::{erfc_inverse, fast_fft_size};
use crate::nodes::fft::next_friendly;

/// Default splitting parameter: 0.5 / a (UAMMD's usual choice for dilute suspensions,
/// where the near field is cheap), raised where the near-field cutoff would exceed half
/// the smallest box side (the minimum image then misses pairs).
pub fn default_split(radius: f64, tolerance: f64, lengths: &[f64]) -> f64 {
    let smallest = lengths.iter().copied().fold(f64::INFINITY, f64::min);
    let needed = 2.0 * (-tolerance.ln()).sqrt() / smallest;
    (0.5 / radius).max(needed * (1.0 + 1e-9))
}

/// Near-field cutoff: the real-space error decays as exp(-xi^2 r^2) (thesis eq. 20.19).
pub fn cutoff(split: f64, tolerance: f64) -> f64 {
    (-tolerance.ln()).sqrt() / split
}

/// Far-field cells per axis: wave numbers up to k_cut = 2 xi sqrt(-ln tol) (where
/// Hasimoto's factor falls to tol, eq. 20.18), so h = pi / k_cut; FFT-friendly, and the
/// fast size (2^a or 3 * 2^a) when it is at most 4% finer.
pub fn grid(lengths: &[f64], split: f64, tolerance: f64) -> Vec<u32> {
    let k_cut = 2.0 * split * (-tolerance.ln()).sqrt();
    let h = std::f64::consts::PI / k_cut;
    lengths
        .iter()
        .map(|l| {
            let n = next_friendly(((l / h).floor() as u32 + 1).max(8));
            let fast = fast_fft_size(n);
            if (fast as f64) <= 1.04 * n as f64 {
                fast
            } else {
                n
            }
        })
        .collect()
}

/// The number of standard deviations m the far-field Gaussian is cut at: the quadrature
/// error erfc(m / sqrt 2) at most tol / 10.
fn deviations(tolerance: f64) -> f64 {
    std::f64::consts::SQRT_2 * erfc_inverse(0.1 * tolerance)
}

/// Far-field support in cells: P with m = 0.976 sqrt(pi P) (Lindbo and Tornberg), odd,
/// at most the smallest grid side.
pub fn support(tolerance: f64, cells: &[u32]) -> u32 {
    let m = deviations(tolerance);
    let mut p = ((m / 0.976).powi(2) / std::f64::consts::PI).ceil() as u32;
    if p % 2 == 0 {
        p += 1;
    }
    let smallest = cells.iter().copied().min().unwrap_or(p);
    p.min(smallest).max(3)
}

/// Standard deviation of the far-field Gaussian: the support's half width over m, on the
/// finest cell of the grid (sigma^2 = lambda / (4 xi^2), eq. 20.17).
pub fn width(lengths: &[f64], cells: &[u32], tolerance: f64) -> f64 {
    let h = lengths
        .iter()
        .zip(cells)
        .map(|(l, &n)| l / n as f64)
        .fold(f64::INFINITY, f64::min);
    0.5 * support(tolerance, cells) as f64 * h / deviations(tolerance)
}

/// Cells per axis of the near field's cell list: as many as keep cells at least the
/// cutoff wide (at most 1024).
pub fn neighbour_cells(lengths: &[f64], cutoff: f64) -> Vec<u32> {
    lengths
        .iter()
        .map(|l| ((l / cutoff).floor() as u32).clamp(1, 1024))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uammd_sizes() {
        // UAMMD's benchmark: a = 1, tol 1e-3, L = 128, xi = 0.5: k_cut = 2.63, h = 1.19.
        let g = grid(&[128.0; 3], 0.5, 1e-3);
        assert_eq!(g, vec![108; 3]);
        let rc = cutoff(0.5, 1e-3);
        assert!((rc - 5.2565).abs() < 1e-3);
        assert_eq!(neighbour_cells(&[128.0; 3], rc), vec![24; 3]);
        assert_eq!(support(1e-3, &g), 7);
    }

    #[test]
    fn split_grows_for_small_boxes() {
        assert_eq!(default_split(1.0, 1e-3, &[128.0; 3]), 0.5);
        let s = default_split(1.0, 1e-3, &[8.0, 8.0, 8.0]);
        assert!(2.0 * cutoff(s, 1e-3) <= 8.0);
    }
}
