//! The planner of graphs/poisson.json, in f64: the far field's Gaussian, grid and support,
//! the near-field cutoff and cell list, the default split and the uniform-background
//! term (UAMMD thesis section 24.1; digest section 6).
//!
//! The far field solves for Gaussian charges of width g_t = sqrt(a^2 + 1 / (4 xi^2))
//! (a the charges' width, xi the split), spread and interpolated with a Gaussian window
//! of that width, so the Green function needs no screening; the near field
//! (nodes/pairs/poisson.rs) is the rest. `split = 0` means no split: g_t = a and no near
//! field.

use crate::nodes::fcm::plan::{
    NOMINAL_DENSITY, check_tolerance, full_rate_fft_size, next_fast_fft,
};
use crate::nodes::pairs::poisson::{far_width as split_far_width, poisson_cutoff};

/// The far field's Gaussian width: g_t, or a itself unsplit (split 0).
pub fn far_width(width: f64, split: f64) -> f64 {
    if split > 0.0 {
        split_far_width(width, split)
    } else {
        width
    }
}

/// Cell size over g_t for a tolerance: UAMMD's rule h = (1.3 - min(-0.1 log10 tol, 0.9)) g_t
/// (1.0 at 1e-3, 0.9 at 1e-4, 0.7 at 1e-6).
fn cell_over_width(tolerance: f64) -> f64 {
    1.3 - (-0.1 * tolerance.log10()).min(0.9)
}

/// Fewest cells per axis UAMMD's rule allows (h <= L / 32).
const MIN_CELLS: u32 = 32;

/// Cells per axis of the far field: L / h rounded up to a full-rate FFT size, at least
/// [`MIN_CELLS`].
pub fn grid(lengths: &[f64], far_width: f64, tolerance: f64) -> Result<Vec<u32>, String> {
    check_tolerance(tolerance)?;
    let h = cell_over_width(tolerance) * far_width;
    lengths
        .iter()
        .map(|&l| {
            let cells = (l / h).ceil().max(MIN_CELLS as f64);
            if cells > crate::nodes::fft::plan::MAX_LENGTH as f64 {
                return Err(format!(
                    "the Poisson far field needs {cells} cells along a box side of {l} (cell {h:.4} for a Gaussian of width {far_width} at tolerance {tolerance}), over the FFT's limit of {}: raise the split or the width",
                    crate::nodes::fft::plan::MAX_LENGTH
                ));
            }
            Ok(next_fast_fft(cells as u32))
        })
        .collect()
}

/// Support in cells of the far field's Gaussian: where exp(-r^2 / (2 g^2)) falls to the
/// tolerance, r = g sqrt(2 ln(1 / tol)), across 2 r / h cells rounded up (at least 3),
/// on the finest axis; at most the grid. UAMMD rounds 2 r / h to the nearest instead:
/// measured against the Ewald sum (tests/it/poisson.rs), that 7 at 1e-3 (h = g) left a
/// pair's field 1.15e-3 off at r = 4a, where 8 gives 1.0e-4.
pub fn support(
    lengths: &[f64],
    grid: &[u32],
    far_width: f64,
    tolerance: f64,
) -> Result<u32, String> {
    check_tolerance(tolerance)?;
    let h = lengths
        .iter()
        .zip(grid)
        .map(|(l, &n)| l / n as f64)
        .fold(f64::INFINITY, f64::min);
    let reach = far_width * (2.0 * (1.0 / tolerance).ln()).sqrt();
    let cells = ((2.0 * reach / h).ceil() as u32).max(3);
    let smallest = grid.iter().copied().min().unwrap_or(1);
    if cells > 32 {
        return Err(format!(
            "the Poisson far field's Gaussian (width {far_width}) spans {cells} cells of {h:.4}, over the 32 a window may have: coarsen the grid"
        ));
    }
    Ok(cells.min(smallest))
}

/// The near field's cutoff; 0 unsplit (there is no near field).
pub fn cutoff(width: f64, split: f64, tolerance: f64, lengths: &[f64]) -> Result<f64, String> {
    if split > 0.0 {
        poisson_cutoff(width, split, tolerance, lengths)
    } else {
        Ok(0.0)
    }
}

/// Cells per axis of the cell list that orders the particles: at least the cutoff wide
/// for the near field, or (unsplit) coarse cells of about 8 grid cells, which only give
/// spreading locality.
pub fn cells(lengths: &[f64], cutoff: f64, grid: &[u32]) -> Vec<u32> {
    if cutoff > 0.0 {
        crate::nodes::pse::neighbour_cells(lengths, cutoff)
    } else {
        grid.iter()
            .map(|&n| crate::nodes::fcm::plan::sort_cells(n as f64) as u32)
            .collect()
    }
}

/// The coefficient c of the uniform-background term c Q_tot added to every potential:
/// the near field's real-space sum has the mean Q_tot (g_t^2 - a^2) / (eps V) =
/// Q_tot / (4 xi^2 eps V) over the box (its kernel integrates to (g_t^2 - a^2) / eps),
/// while the Fourier part leaves k = 0 out; removing that mean makes the k = 0 mode of
/// the whole potential zero for every split, as unsplit. 0 unsplit.
pub fn background(lengths: &[f64], split: f64, permittivity: f64) -> f64 {
    if split > 0.0 {
        let volume: f64 = lengths.iter().product();
        -1.0 / (4.0 * split * split * permittivity * volume)
    } else {
        0.0
    }
}

/// Modelled cost per volume a^3 at the nominal density (FCM's units,
/// `fcm::plan::fcm_cost`): the transforms per grid cell, the window per particle, and
/// the near field per candidate pair (27 cells of the cell list per particle).
fn cost(width: f64, split: f64, tolerance: f64, lengths: &[f64]) -> Option<f64> {
    let g = far_width(width, split);
    let grid = grid(lengths, g, tolerance).ok()?;
    let p = support(lengths, &grid, g, tolerance).ok()?;
    let rc = cutoff(width, split, tolerance, lengths).ok()?;
    let volume: f64 = lengths.iter().product();
    let a3 = width.powi(3);
    let cells: f64 = grid.iter().map(|&n| n as f64).product();
    let slow = if grid.iter().all(|&n| full_rate_fft_size(n)) {
        1.0
    } else {
        1.5
    };
    let density = NOMINAL_DENSITY / a3;
    let far = 78.0 * slow * cells * a3 / volume + 16.0 * NOMINAL_DENSITY * (p as f64).powi(3);
    let list = cells_volume(lengths, rc);
    let near = if rc > 0.0 {
        2.0 * NOMINAL_DENSITY * density * list
    } else {
        0.0
    };
    Some(far + near)
}

/// The volume of the 27 cells a particle's near field walks.
fn cells_volume(lengths: &[f64], rc: f64) -> f64 {
    if rc <= 0.0 {
        return 0.0;
    }
    let c = crate::nodes::pse::neighbour_cells(lengths, rc);
    lengths
        .iter()
        .zip(&c)
        .map(|(l, &n)| 3.0 * (l / n as f64).min(*l))
        .product()
}

/// The default split: the one the cost model finds cheapest among unsplit (0) and far
/// widths g_t = a 1.15^k (k = 1..40) whose near field fits the box.
pub fn default_split(width: f64, tolerance: f64, lengths: &[f64]) -> Result<f64, String> {
    check_tolerance(tolerance)?;
    let mut best: Option<(f64, f64)> = cost(width, 0.0, tolerance, lengths).map(|c| (c, 0.0));
    for k in 1..=40 {
        let g = width * 1.15f64.powi(k);
        let split = 1.0 / (2.0 * (g * g - width * width).sqrt());
        if let Some(c) = cost(width, split, tolerance, lengths)
            && best.is_none_or(|(b, _)| c < b)
        {
            best = Some((c, split));
        }
    }
    best.map(|(_, s)| s).ok_or_else(|| {
        format!(
            "no split plans Poisson for width {width} in a box of {lengths:?} at tolerance {tolerance}: the grid is too large unsplit and the near field reaches past half the box split"
        )
    })
}

/// Potentials and fields of Gaussian charges (width `a`) in a periodic box by Ewald
/// summation in f64 (k = 0 mode of the potential zero, each charge's own cloud included):
/// the reference `mesoflow bench poisson` measures errors against. The Ewald width is
/// min(L) / 10 (at least 1.5 a); real space over images within 12 of it, Fourier space
/// up to |k| = 6.5 over it. The tests have an independent copy.
pub fn ewald_reference(
    pos: &[[f64; 3]],
    q: &[f64],
    a: f64,
    eps: f64,
    l: [f64; 3],
) -> (Vec<f64>, Vec<[f64; 3]>) {
    use crate::nodes::pairs::poisson::near_terms;
    use std::f64::consts::PI;
    let n = pos.len();
    let g = (l.iter().cloned().fold(f64::INFINITY, f64::min) / 10.0).max(1.5 * a);
    // The near terms of a split at xi with g_t = g: 1 / (4 xi^2) = g^2 - a^2.
    let xi = 0.5 / (g * g - a * a).sqrt();
    let volume = l[0] * l[1] * l[2];
    let mut phi = vec![0.0; n];
    let mut e = vec![[0.0; 3]; n];
    let reach = 12.0 * g;
    let images = [0, 1, 2].map(|d| (reach / l[d]).ceil() as i64 + 1);
    for i in 0..n {
        for j in 0..n {
            for nx in -images[0]..=images[0] {
                for ny in -images[1]..=images[1] {
                    for nz in -images[2]..=images[2] {
                        let r = [
                            pos[i][0] - pos[j][0] + nx as f64 * l[0],
                            pos[i][1] - pos[j][1] + ny as f64 * l[1],
                            pos[i][2] - pos[j][2] + nz as f64 * l[2],
                        ];
                        let d = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
                        if d > reach {
                            continue;
                        }
                        let (p, _, slope_over_r) = near_terms(d, a, xi, eps);
                        phi[i] += q[j] * p;
                        for c in 0..3 {
                            e[i][c] -= q[j] * slope_over_r * r[c];
                        }
                    }
                }
            }
        }
    }
    let kmax = 6.5 / g;
    let m = [0, 1, 2].map(|d| (kmax * l[d] / (2.0 * PI)).ceil() as i64);
    for mx in -m[0]..=m[0] {
        for my in -m[1]..=m[1] {
            for mz in -m[2]..=m[2] {
                let k = [
                    2.0 * PI * mx as f64 / l[0],
                    2.0 * PI * my as f64 / l[1],
                    2.0 * PI * mz as f64 / l[2],
                ];
                let k2 = k[0] * k[0] + k[1] * k[1] + k[2] * k[2];
                if k2 == 0.0 || k2 > kmax * kmax {
                    continue;
                }
                let w = (-k2 * g * g).exp() / (eps * volume * k2);
                let (mut sr, mut si) = (0.0, 0.0);
                for j in 0..n {
                    let ph = k[0] * pos[j][0] + k[1] * pos[j][1] + k[2] * pos[j][2];
                    sr += q[j] * ph.cos();
                    si -= q[j] * ph.sin();
                }
                for i in 0..n {
                    let ph = k[0] * pos[i][0] + k[1] * pos[i][1] + k[2] * pos[i][2];
                    let (c, s) = (ph.cos(), ph.sin());
                    phi[i] += w * (c * sr - s * si);
                    for d in 0..3 {
                        e[i][d] += w * k[d] * (s * sr + c * si);
                    }
                }
            }
        }
    }
    let total: f64 = q.iter().sum();
    for p in phi.iter_mut() {
        *p -= total * (g * g - a * a) / (eps * volume);
    }
    (phi, e)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_follows_uammd_rule() {
        // h / g_t = 1.1, 1.0, 0.9, 0.8, 0.7 at 1e-2 .. 1e-6 (digest 13.3 #26).
        for (tol, ratio) in [
            (1e-2, 1.1),
            (1e-3, 1.0),
            (1e-4, 0.9),
            (1e-5, 0.8),
            (1e-6, 0.7),
        ] {
            assert!((cell_over_width(tol) - ratio).abs() < 1e-12, "{tol}");
        }
        // L = 128, g = 1 at 1e-3: 128 cells (a full-rate size); at least 32 cells.
        assert_eq!(grid(&[128.0; 3], 1.0, 1e-3).unwrap(), vec![128; 3]);
        assert_eq!(grid(&[16.0; 3], 2.0, 1e-3).unwrap(), vec![32; 3]);
        assert!(grid(&[1e5; 3], 1.0, 1e-3).is_err());
    }

    #[test]
    fn unsplit_has_no_near_field_and_no_background() {
        assert_eq!(cutoff(1.0, 0.0, 1e-3, &[32.0; 3]).unwrap(), 0.0);
        assert_eq!(background(&[32.0; 3], 0.0, 1.0), 0.0);
        assert_eq!(far_width(1.0, 0.0), 1.0);
        // The near kernel integrates to (g_t^2 - a^2) / eps = 1 / (4 xi^2 eps).
        let c = background(&[2.0, 3.0, 4.0], 0.5, 2.0);
        assert!((c + 1.0 / (4.0 * 0.25 * 2.0 * 24.0)).abs() < 1e-15);
    }

    #[test]
    fn default_split_is_planned_and_fits_the_box() {
        for (w, l) in [(1.0, 128.0), (1.0, 16.0), (0.1, 8.0), (0.05, 40.0)] {
            let s = default_split(w, 1e-3, &[l; 3]).unwrap();
            assert!(s >= 0.0);
            assert!(cutoff(w, s, 1e-3, &[l; 3]).unwrap() <= l / 2.0);
            let g = far_width(w, s);
            grid(&[l; 3], g, 1e-3).unwrap();
        }
        // Narrow charges in a large box are split (the unsplit grid would be huge).
        assert!(default_split(0.05, 1e-3, &[40.0; 3]).unwrap() > 0.0);
    }
}
