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
    use crate::nodes::spread::window::simpson_weight;
    use std::f64::consts::PI;
    // phi^(k) = int phi(x) cos(k x) dx by Simpson over the support (phi is even).
    let nx = 2000;
    let dx = 2.0 * half_width / nx as f64;
    let samples: Vec<(f64, f64)> = (0..=nx)
        .map(|i| {
            let x = -half_width + i as f64 * dx;
            (x, simpson_weight(i, nx) * phi(x) * dx / 3.0)
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
    es_window_radius(es_beta(w), w)
}

/// The hydrodynamic radius, in cells, of the ES window of shape `beta` over `support`
/// cells (`window_radius_cells`); computed once per (beta, support) in a process (about
/// 0.1 s) and kept. With support 2 it is a over the half-width, the radius of the shape
/// whatever its width (the doubly periodic windows').
pub fn es_window_radius(beta: f64, support: u32) -> f64 {
    use std::collections::HashMap;
    use std::sync::{Mutex, OnceLock};
    static KNOWN: OnceLock<Mutex<HashMap<(u64, u32), f64>>> = OnceLock::new();
    let key = (beta.to_bits(), support);
    let known = KNOWN.get_or_init(Default::default);
    if let Some(r) = known.lock().ok().and_then(|m| m.get(&key).copied()) {
        return r;
    }
    let window = crate::nodes::spread::window::Window::es(beta, support);
    let r = window_radius_cells(|x| window.phi(x, 1.0), support as f64 / 2.0);
    if let Ok(mut m) = known.lock() {
        m.insert(key, r);
    }
    r
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
    let cells = nominal_grid_for(lengths, radius, tolerance, kernel, rotation)?;
    if kernel == "gaussian" {
        refine_for_accuracy(lengths, cells, radius, tolerance)
            .and_then(|cells| checked_grid("the FCM grid", cells))
    } else {
        Ok(cells)
    }
}

/// [`grid_for`] before the Gaussian's refinement for the worst placement: the spacing
/// of UAMMD's upsampling rule (and the rotation's), rounded to FFT-friendly sizes. PSE's
/// far field, which plans its own grid, takes this as fcm.json's (unused) default.
pub fn nominal_grid_for(
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
            if l < 2.0 * radius {
                return Err(format!(
                    "a box side of {} is shorter than the spheres' diameter 2a = {}: each sphere would overlap its own periodic images (make `box` at least {} per side, or `radius` at most {})",
                    fmt_number(l),
                    fmt_number(2.0 * radius),
                    fmt_number(2.0 * radius),
                    fmt_number(0.5 * l)
                ));
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

/// The Gaussian's grid: the nominal one ([`nominal_grid_for`]: UAMMD's upsampling g_u(tol),
/// fitted to mean errors) or a finer one (every axis to its next FFT-friendly sizes),
/// whichever is cheapest ([`fcm_cost`]) among those on which some support keeps the
/// self-mobility within the tolerance at the worst placement ([`force_support`]): the
/// first such grid and the [`REFINEMENTS`] after it. At a cell corner UAMMD's grid can
/// fall short with any support (L = 12 a at 1e-4: 20 cells, 1.15e-4), or need a wide one
/// (L = 130 a at 1e-4: 216 cells need support 10; 224 take 9, for less in all).
fn refine_for_accuracy(
    lengths: &[f64],
    mut cells: Vec<u32>,
    radius: f64,
    tolerance: f64,
) -> Result<Vec<u32>, String> {
    let sigma = gaussian_width(radius);
    let mut best: Option<(f64, Vec<u32>)> = None;
    let mut after_first = 0;
    let mut first_problem = None;
    loop {
        match force_support(tolerance, sigma, lengths, &cells) {
            Ok(support) => {
                let cost = fcm_cost(lengths, &cells, support, radius);
                if best.as_ref().is_none_or(|(c, _)| cost < *c) {
                    best = Some((cost, cells.clone()));
                }
            }
            Err(e) => {
                first_problem.get_or_insert(e);
            }
        }
        if best.is_some() {
            if after_first == REFINEMENTS {
                break;
            }
            after_first += 1;
        }
        let finer: Vec<u32> = cells.iter().map(|&n| next_fast_fft(n + 1)).collect();
        if finer.iter().any(|&n| n > 4096) {
            break;
        }
        cells = finer;
    }
    best.map(|(_, cells)| cells).ok_or_else(|| {
        format!(
            "{}; a finer grid would take more than the 4096 cells an FFT axis takes",
            first_problem.unwrap_or_default()
        )
    })
}

/// Whether the transforms run an FFT of `n` points at full rate: n = 2^a 3^b 5^c 7^d with
/// b <= 1 and c <= 1 (or c >= 2 with a factor 7). On an H200 (bench fft, 3 components,
/// rfft + irfft, 2026-12-03) such sizes reach 1730-2560 GB/s at 112-512 points (175 =
/// 5^2 7: 1955, 448 = 2^6 7: 1978); the others run at 1000-1760 (441 = 3^2 7^2: 12.0 ms
/// against 6.57 at 448; 432 = 2^4 3^3: 8.16; 162 = 2 3^4: 0.353 against 0.333 at 168).
/// Fitted to that one run: it steers the grid choice only, never its accuracy.
pub fn full_rate_fft_size(n: u32) -> bool {
    let mut r = n;
    let mut count = |p: u32| {
        let mut k = 0;
        while r > 0 && r.is_multiple_of(p) {
            r /= p;
            k += 1;
        }
        k
    };
    let (_, threes, fives, sevens) = (count(2), count(3), count(5), count(7));
    r == 1 && threes <= 1 && (fives <= 1 || sevens >= 1)
}

/// The smallest FFT size >= `n` that [`full_rate_fft_size`] takes: the grid refinement steps
/// through these only.
pub fn next_fast_fft(n: u32) -> u32 {
    let mut m = next_friendly(n);
    while !full_rate_fft_size(m) {
        m = next_friendly(m + 1);
    }
    m
}

/// How much more a transform of a size [`full_rate_fft_size`] refuses costs per cell than one
/// it takes (about 2200 against 1450 GB/s in the run it cites).
const SLOW_FFT_FACTOR: f64 = 1.5;

/// Finer grids than the first accurate one that [`refine_for_accuracy`] weighs.
const REFINEMENTS: u32 = 2;

/// Particles per a^3 FCM's grid choice assumes: UAMMD's benchmarks (10^4 in 64^3 a^3 to
/// 10^6 in 264^3 a^3, 0.038 to 0.057).
pub const NOMINAL_DENSITY: f64 = 0.045;

/// GPU time of one M F per unit volume, in ps per a^3 (an H200's, BENCHMARKS.md, 1e-2 at
/// 10^5: 0.33 ms of transforms on 162^3 cells, 78 ps a cell; 0.2 ms of spreading and
/// interpolation for 10^5 particles of 5^3 support cells, 16 ps each): what the grid
/// choice weighs, cells against support; cells of a grid with an axis the transforms do
/// not run at full rate cost [`SLOW_FFT_FACTOR`] times more.
pub fn fcm_cost(lengths: &[f64], cells: &[u32], support: u32, radius: f64) -> f64 {
    let volume: f64 = lengths.iter().product();
    let cell_count: f64 = cells.iter().map(|&n| n as f64).product();
    let per_volume = radius.powi(3) / volume;
    let slow = cells.iter().any(|&n| !full_rate_fft_size(n));
    let fft = if slow { SLOW_FFT_FACTOR } else { 1.0 };
    78.0 * fft * cell_count * per_volume
        + 16.0 * NOMINAL_DENSITY * (support as f64).powi(lengths.len() as i32)
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

/// The share of the tolerance FCM's Gaussian may take at the worst placement, as
/// [`gaussian_self_error`] computes it: the rest covers the difference between its
/// reference box and larger boxes (below 1 % from 48 cells per axis up).
pub const SELF_ERROR_SHARE: f64 = 0.98;

/// Cells per axis of the periodic box [`gaussian_self_error`] evaluates the
/// discretisation in: the grid's own where it has fewer; a larger box's error differs
/// by less than 1 % (the finite-size part of the aliasing falls as 1 / L: at a cell
/// corner, sigma = 0.72 h, support 5: 9.95e-3 at 32 cells, 9.88e-3 at 48, 9.85e-3 at 64,
/// 9.83e-3 at 81).
pub const REFERENCE_CELLS: u32 = 48;

/// The worst self-mobility error of FCM's Gaussian pipeline (spread, Stokes Green
/// function, interpolate) for a Gaussian of standard deviation `sigma` cut at `support`
/// cells on a grid of these cells, relative to the exact periodic mobility of the
/// Gaussian, over the placements where it peaks: on a grid point (a cell's centre) or
/// midway between two, per axis (the aliased images and the cut tail both oscillate
/// with the offset from a cell centre, extreme at these; a particle at a cell corner,
/// midway on every axis, or on a grid point gives the worst). Computed in f64 exactly as
/// the pipeline sums it (the same stencil, the projection without unpaired Nyquist wave
/// numbers), in a periodic box of the grid's cells, at most [`REFERENCE_CELLS`] per
/// axis; the exact mobility is the same sum with the continuous Gaussian over the
/// grid's wave numbers plus the integral past them.
pub fn gaussian_self_error(sigma: f64, lengths: &[f64], cells: &[u32], support: u32) -> f64 {
    use std::f64::consts::PI;
    let n: Vec<u32> = cells.iter().map(|&c| c.min(REFERENCE_CELLS)).collect();
    let h: Vec<f64> = lengths
        .iter()
        .zip(cells)
        .map(|(l, &c)| l / c as f64)
        .collect();
    let box_lengths: Vec<f64> = h.iter().zip(&n).map(|(h, &n)| h * n as f64).collect();
    let wave = |i: u32, n: u32| -> i64 {
        if i <= n / 2 {
            i as i64
        } else {
            i as i64 - n as i64
        }
    };
    // h^2 |sum_j w_j e^{-ik x_j}|^2 per axis, wave number and offset (0: on a grid point,
    // 1: midway), w the stencil's weights per unit length (`GridWindow::stencil`): the
    // continuous Gaussian's e^{-sigma^2 k^2} where the grid resolves it.
    let power: Vec<[Vec<f64>; 2]> = (0..3)
        .map(|a| {
            [0.0, 0.5].map(|offset: f64| {
                let first = (offset - 0.5 * support as f64).floor() + 1.0;
                let weights: Vec<(f64, f64)> = (0..support)
                    .map(|j| {
                        let d = (first + j as f64 - offset) * h[a];
                        let w = h[a] * (-0.5 * d * d / (sigma * sigma)).exp()
                            / ((2.0 * PI).sqrt() * sigma);
                        (d, w)
                    })
                    .collect();
                (0..n[a])
                    .map(|i| {
                        let k = 2.0 * PI * wave(i, n[a]) as f64 / box_lengths[a];
                        let (re, im) = weights.iter().fold((0.0, 0.0), |(re, im), &(d, w)| {
                            let (s, c) = (k * d).sin_cos();
                            (re + w * c, im - w * s)
                        });
                        re * re + im * im
                    })
                    .collect()
            })
        })
        .collect();
    // Per axis: the pipeline's self-mobility times the volume for each of the 8
    // placements, and the exact one over the grid's wave numbers.
    let mut grid_mobility = [[0.0f64; 3]; 8];
    let mut exact = [0.0f64; 3];
    for iz in 0..n[2] {
        for iy in 0..n[1] {
            for ix in 0..n[0] {
                let idx = [ix, iy, iz];
                let w = [0, 1, 2].map(|a| wave(idx[a], n[a]));
                if w == [0, 0, 0] {
                    continue;
                }
                let k = [0, 1, 2].map(|a| 2.0 * PI * w[a] as f64 / box_lengths[a]);
                let k2: f64 = k.iter().map(|x| x * x).sum();
                let gaussian = (-sigma * sigma * k2).exp() / k2;
                for (a, e) in exact.iter_mut().enumerate() {
                    *e += gaussian * (1.0 - k[a] * k[a] / k2);
                }
                // The projection leaves out unpaired Nyquist wave numbers (`stokes`).
                let kp = [0, 1, 2].map(|a| {
                    if n[a].is_multiple_of(2) && w[a].unsigned_abs() * 2 == n[a] as u64 {
                        0.0
                    } else {
                        k[a]
                    }
                });
                let kp2: f64 = kp.iter().map(|x| x * x).sum();
                let projection = [0, 1, 2].map(|a| {
                    if kp2 > 0.0 {
                        1.0 - kp[a] * kp[a] / kp2
                    } else {
                        1.0
                    }
                });
                for (p, m) in grid_mobility.iter_mut().enumerate() {
                    let s = [p & 1, (p >> 1) & 1, (p >> 2) & 1];
                    let weight = power[0][s[0]][ix as usize]
                        * power[1][s[1]][iy as usize]
                        * power[2][s[2]][iz as usize]
                        / k2;
                    for a in 0..3 {
                        m[a] += weight * projection[a];
                    }
                }
            }
        }
    }
    let volume: f64 = box_lengths.iter().product();
    let zone = [0, 1, 2].map(|a| PI / h[a]);
    let past = past_the_zone(sigma, zone);
    let exact = [0, 1, 2].map(|a| exact[a] / volume + past[a]);
    grid_mobility
        .iter()
        .flat_map(|m| (0..3).map(move |a| (m[a] / volume / exact[a] - 1.0).abs()))
        .fold(0.0, f64::max)
}

/// (2 pi)^-3 int e^{-sigma^2 k^2} (1 - k_a^2 / k^2) / k^2 d^3k over the wave vectors
/// outside the zone |k_b| <= zone[b] (the exact mobility's part the grid cannot hold), per
/// axis a: by inclusion and exclusion over the slabs |k_b| > zone[b], each a product
/// domain away from k = 0, by Gauss-Legendre in the positive octant.
fn past_the_zone(sigma: f64, zone: [f64; 3]) -> [f64; 3] {
    use std::f64::consts::PI;
    // e^{-sigma^2 k^2} < 2e-21 past 7 / sigma from where the slab starts.
    let reach = 7.0 / sigma;
    let rule = |lo: f64| -> Vec<(f64, f64)> {
        let panels = 4;
        let width = reach / panels as f64;
        let mut out = Vec::with_capacity(8 * panels);
        for p in 0..panels {
            let mid = lo + (p as f64 + 0.5) * width;
            for &(x, w) in &crate::nodes::pairs::rpy::GL8 {
                out.push((mid - 0.5 * width * x, 0.5 * width * w));
                out.push((mid + 0.5 * width * x, 0.5 * width * w));
            }
        }
        out
    };
    let free = rule(0.0);
    let cut: Vec<Vec<(f64, f64)>> = zone.iter().map(|&z| rule(z)).collect();
    let mut total = [0.0; 3];
    for slabs in 1..8usize {
        let sign = if slabs.count_ones() % 2 == 1 {
            1.0
        } else {
            -1.0
        };
        let axis = |b: usize| if slabs >> b & 1 == 1 { &cut[b] } else { &free };
        for &(kz, wz) in axis(2) {
            for &(ky, wy) in axis(1) {
                for &(kx, wx) in axis(0) {
                    let k2 = kx * kx + ky * ky + kz * kz;
                    let f = sign * 8.0 * wx * wy * wz * (-sigma * sigma * k2).exp() / k2;
                    total[0] += f * (1.0 - kx * kx / k2);
                    total[1] += f * (1.0 - ky * ky / k2);
                    total[2] += f * (1.0 - kz * kz / k2);
                }
            }
        }
    }
    total.map(|t| t / (2.0 * PI).powi(3))
}

/// The support FCM's force Gaussian (standard deviation `sigma`) needs on this grid: the
/// fewest cells whose [`gaussian_self_error`] is within [`SELF_ERROR_SHARE`] of the
/// tolerance at the worst placement, memoised. Refused when no support reaches it
/// (the grid's aliasing alone is too large: the grid is too coarse for the tolerance).
/// Grids of other than 3 axes take the erfc rule ([`gaussian_support`]).
pub fn force_support(
    tolerance: f64,
    sigma: f64,
    lengths: &[f64],
    cells: &[u32],
) -> Result<u32, String> {
    use std::collections::HashMap;
    use std::sync::{Mutex, OnceLock};
    let h_min = lengths
        .iter()
        .zip(cells)
        .map(|(l, &n)| l / n as f64)
        .fold(f64::INFINITY, f64::min);
    let nominal = gaussian_support(tolerance, sigma / h_min);
    if lengths.len() != 3 || cells.len() != 3 {
        return Ok(nominal);
    }
    type Key = (Vec<u64>, Vec<u32>);
    static SUPPORTS: OnceLock<Mutex<HashMap<Key, Result<u32, String>>>> = OnceLock::new();
    let key = (
        [tolerance, sigma]
            .iter()
            .chain(lengths)
            .map(|x| x.to_bits())
            .collect(),
        cells.to_vec(),
    );
    let supports = SUPPORTS.get_or_init(Default::default);
    if let Some(s) = supports.lock().unwrap_or_else(|p| p.into_inner()).get(&key) {
        return s.clone();
    }
    let budget = SELF_ERROR_SHARE * tolerance;
    // A support wider than the grid wraps around it (small boxes: 3a takes 9 cells on 5).
    let largest = crate::nodes::spread::window::MAX_SUPPORT;
    let mut found = None;
    let mut previous = f64::INFINITY;
    let mut least = f64::INFINITY;
    for support in nominal.saturating_sub(2).max(3)..=largest {
        let error = gaussian_self_error(sigma, lengths, cells, support);
        least = least.min(error);
        if error <= budget {
            found = Some(support);
            break;
        }
        // A wider support no longer helps: what is left is the grid's aliasing.
        if error > 0.97 * previous {
            break;
        }
        previous = error;
    }
    let result = found.ok_or_else(|| {
        format!(
            "the grid {cells:?} is too coarse for FCM's Gaussian (sigma = {}) at tolerance {tolerance:e}: its self-mobility error at the worst placement stays at {least:.2e} with any support (set a finer `grid` or a looser `tolerance`)",
            fmt_number(sigma)
        )
    });
    supports
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .insert(key, result.clone());
    result
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

    /// The refinement's sizes skip the slow FFT lengths (3^2 or 5^2 factors).
    #[test]
    fn refinement_steps_through_fast_fft_sizes() {
        assert_eq!(next_fast_fft(433), 448);
        assert_eq!(next_fast_fft(217), 224);
        assert_eq!(next_fast_fft(109), 112);
        assert_eq!(next_fast_fft(343), 343);
        assert_eq!(next_fast_fft(170), 175);
        assert!(!full_rate_fft_size(441) && !full_rate_fft_size(432) && !full_rate_fft_size(162));
        for n in 1..=1024 {
            let m = next_fast_fft(n);
            assert!(
                m >= n && full_rate_fft_size(m) && !m.is_multiple_of(9),
                "{n} -> {m}"
            );
        }
    }

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

    /// The exact periodic self-mobility split at the grid's zone (the sum over the grid's
    /// wave numbers plus the integral past them) against the direct Fourier sum.
    #[test]
    fn the_exact_mobility_splits_at_the_zone() {
        use std::f64::consts::PI;
        let (l, n) = (12.0, 20i64);
        let sigma = gaussian_width(1.0);
        let mut inside = 0.0;
        for mx in -n / 2 + 1..=n / 2 {
            for my in -n / 2 + 1..=n / 2 {
                for mz in -n / 2 + 1..=n / 2 {
                    let k = [mx, my, mz].map(|m| 2.0 * PI * m as f64 / l);
                    let k2: f64 = k.iter().map(|x| x * x).sum();
                    if k2 > 0.0 {
                        inside += (-sigma * sigma * k2).exp() / k2 * (1.0 - k[0] * k[0] / k2);
                    }
                }
            }
        }
        let split = inside / l.powi(3) + past_the_zone(sigma, [PI * n as f64 / l; 3])[0];
        let direct =
            crate::nodes::fcm::reference::periodic_gaussian_mobility([0.0; 3], [l; 3], 1.0, sigma)
                [0][0];
        assert!(
            (split / direct - 1.0).abs() < 2e-5,
            "{split} against {direct}"
        );
    }

    /// UAMMD's discretisation at 1e-4 (sigma = 0.9375 h, support 8) misses at a cell
    /// corner; the planner's grid and support do not.
    #[test]
    fn the_gaussian_meets_the_tolerance_at_the_worst_placement() {
        let sigma = gaussian_width(1.0);
        let h = sigma / 0.9375;
        let e = gaussian_self_error(sigma, &[48.0 * h; 3], &[48; 3], 8);
        assert!(e > 1.05e-4, "{e}");
        for (l, tol) in [(12.0, 1e-4), (16.0, 3e-4), (20.0, 1e-2), (32.0, 1e-5)] {
            let cells = grid_for(&[l; 3], 1.0, tol, "gaussian", false).unwrap();
            let support = force_support(tol, sigma, &[l; 3], &cells).unwrap();
            let e = gaussian_self_error(sigma, &[l; 3], &cells, support);
            assert!(e <= SELF_ERROR_SHARE * tol, "L = {l}, {tol}: {e}");
            assert!(
                gaussian_self_error(sigma, &[l; 3], &cells, support - 1) > SELF_ERROR_SHARE * tol,
                "L = {l}, {tol}: support {support} is not the least"
            );
        }
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
            // The nominal rule; `grid` then refines it where the worst placement, or the
            // transforms' rate, asks for another (refinement_steps_through_...).
            assert_eq!(
                nominal_grid_for(&[l], 1.0, tol, "gaussian", false).unwrap(),
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
