//! The Positively Split Ewald planner, on the host in f64 (UAMMD thesis section 20.2,
//! digest section 4; Fiore et al. 2017, after Lindbo and Tornberg 2011): from the radius,
//! the tolerance, the box and the splitting parameter xi to the far field's grid and
//! Gaussian and the near field's cutoff and cell list. The operators are generic nodes
//! composed by graphs/pse.json (the far field is graphs/fcm.json with the screened Green
//! function of `stokes`, the near field `neighbour_sum` with the `rpy_near` kernel).

use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};

use crate::nodes::fcm::bound::WindowBound;
use crate::nodes::fcm::plan::{check_tolerance, fast_fft_size};
use crate::nodes::fft::next_friendly;
use crate::nodes::fft::plan::{cells_per_axis, checked_grid};

/// Default splitting parameter: 0.5 / a (UAMMD's usual choice for dilute suspensions,
/// where the near field is cheap), raised where the near-field cutoff would exceed half
/// the smallest box side (the minimum image then misses pairs).
pub fn default_split(radius: f64, tolerance: f64, lengths: &[f64]) -> Result<f64, String> {
    let half = 0.5 * lengths.iter().copied().fold(f64::INFINITY, f64::min);
    let xi = 0.5 / radius;
    if cutoff(radius, xi, tolerance, lengths)? <= half {
        return Ok(xi);
    }
    // The cutoff falls as xi grows: bisect for the smallest xi that fits.
    let (mut lo, mut hi) = (xi, xi);
    while cutoff(radius, hi, tolerance, lengths)? > half {
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
        if cutoff(radius, mid, tolerance, lengths)? > half {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Ok(hi)
}

/// The share of the tolerance the near field may leave out (pairs past the cutoff); the
/// far field's discretisation has the rest, [`FAR_SHARE`]. The two add up for a pair, so
/// together they bound its error by the tolerance; a single particle sees the far part
/// only (its near-field self term is exact).
pub const NEAR_SHARE: f64 = 0.25;

/// The share of the tolerance the far field's discretisation may take ([`far_bound`]).
pub const FAR_SHARE: f64 = 1.0 - NEAR_SHARE;

/// The periodic self-mobility the tolerance is relative to, in units of the free one
/// 1 / (6 pi eta a): Hasimoto's for a cube of the smallest side (the smallest a box of
/// these sides has), at least 0.1 (a near field within half a side keeps boxes above 4a).
fn periodic_self(radius: f64, lengths: &[f64]) -> f64 {
    let smallest = lengths.iter().copied().fold(f64::INFINITY, f64::min);
    crate::nodes::fcm::plan::hasimoto(radius, smallest).max(0.1)
}

/// Near-field cutoff: where the near field falls below [`NEAR_SHARE`] of the tolerance,
/// relative to the periodic self-mobility (`near_cutoff`; about sqrt(-ln tol) / xi, thesis
/// eq. 20.19, at small xi a, and up to 2a further at large xi a, where the shells of the
/// RPY spheres widen the screening).
pub fn cutoff(radius: f64, split: f64, tolerance: f64, lengths: &[f64]) -> Result<f64, String> {
    crate::nodes::pairs::rpy::near_cutoff(
        radius,
        split,
        NEAR_SHARE * tolerance * periodic_self(radius, lengths),
    )
}

/// Far-field cells per axis: wave numbers up to k_cut = 2 xi sqrt(-ln tol) (where
/// Hasimoto's factor falls to tol, eq. 20.18), so h = pi / k_cut; FFT-friendly, and the
/// fast size (2^a or 3 * 2^a) when it is at most 4% finer. On this grid the wave numbers
/// left out cost far less than the tolerance; what limits the far field is the window's
/// aliasing, which [`far_window`] bounds. Each axis is bounded (`cells_per_axis`,
/// `checked_grid`) before it is converted.
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

/// The far field's Gaussian on a grid: its standard deviation and its support in cells.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FarWindow {
    pub width: f64,
    pub support: u32,
}

/// The cheapest far-field Gaussian on this grid whose error bound ([`far_bound`]) is at
/// most [`FAR_SHARE`] of the tolerance (relative to the periodic self-mobility) for
/// every placement and pair: the smallest support for which some width meets it, with
/// the width of the least bound at that support.
///
/// Why not Lindbo and Tornberg's shape (m = 0.976 sqrt(pi P) deviations in P cells, the
/// rule before): it balances the Gaussian's truncation against its aliasing at the
/// lowest wave numbers, exp(-2 pi^2 sigma^2 / h^2), but undoing the two Gaussians in the
/// Green function amplifies the aliased images towards the zone's edge, by
/// exp(2 pi sigma^2 k / h) against H's exp(-k^2 / 4 xi^2): at sigma = 0.765 h (their P = 7,
/// taken at 1e-3 and at 1e-4 alike) the aliasing alone is 4.5e-4 of the self-mobility,
/// within 1e-3 and four times 1e-4.
pub fn far_window(
    radius: f64,
    split: f64,
    tolerance: f64,
    lengths: &[f64],
    cells: &[u32],
) -> Result<FarWindow, String> {
    type Key = (Vec<u64>, Vec<u32>);
    static WINDOWS: OnceLock<Mutex<HashMap<Key, Result<FarWindow, String>>>> = OnceLock::new();
    let key = (
        [radius, split, tolerance]
            .iter()
            .chain(lengths)
            .map(|x| x.to_bits())
            .collect(),
        cells.to_vec(),
    );
    let windows = WINDOWS.get_or_init(Default::default);
    if let Some(w) = windows.lock().unwrap_or_else(|p| p.into_inner()).get(&key) {
        return w.clone();
    }
    let found = search_far_window(radius, split, tolerance, lengths, cells);
    windows
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .insert(key, found.clone());
    found
}

/// The cell sizes of a 3-D far-field grid.
fn cell_sizes(lengths: &[f64], cells: &[u32]) -> Result<[f64; 3], String> {
    if lengths.len() != 3 || cells.len() != 3 {
        return Err(format!(
            "PSE's far field is 3-D: box and grid need 3 values each, got {} and {}",
            lengths.len(),
            cells.len()
        ));
    }
    if cells.contains(&0) || lengths.iter().any(|&l| !(l > 0.0 && l.is_finite())) {
        return Err(format!(
            "box {lengths:?} and grid {cells:?} must be positive"
        ));
    }
    Ok([0, 1, 2].map(|a| lengths[a] / cells[a] as f64))
}

/// The error bound of PSE's far field on cells of sizes `h`: [`WindowBound`] for its
/// kernel sinc^2(ka) H(k, xi) / k^2, returned relative to the free self-mobility
/// 1 / (6 pi eta a) (as a function of the Gaussian's width and support).
pub fn far_bound(radius: f64, split: f64, h: [f64; 3]) -> impl Fn(f64, u32) -> f64 {
    let kernel = move |k2: f64| {
        let ka = k2.sqrt() * radius;
        let sinc = if ka < 1e-8 { 1.0 } else { ka.sin() / ka };
        let q = k2 / (4.0 * split * split);
        sinc * sinc * (1.0 + q) * (-q).exp()
    };
    // H < 1e-19 past 2 xi sqrt(44).
    let bound = WindowBound::new(kernel, 2.0 * split * 44f64.sqrt(), h);
    let free = 6.0 * std::f64::consts::PI * radius;
    move |width, support| free * bound.bound(width, support)
}

/// The far budget in units of the free self-mobility.
fn far_budget(radius: f64, tolerance: f64, lengths: &[f64]) -> f64 {
    FAR_SHARE * tolerance * periodic_self(radius, lengths)
}

/// Supports up to this many cells are searched (the spreading kernels take up to
/// `window::MAX_SUPPORT`; past 16 the far field would be a poor use of PSE anyway: a
/// larger split moves work to the near field).
const MAX_FAR_SUPPORT: u32 = 16;

/// Standard deviations the stencil spans on each side when truncation is to be
/// negligible (erfc(7 / sqrt 2) ~ 3e-12): the aliasing-only bound.
const UNTRUNCATED_DEVIATIONS: f64 = 7.0;

fn search_far_window(
    radius: f64,
    split: f64,
    tolerance: f64,
    lengths: &[f64],
    cells: &[u32],
) -> Result<FarWindow, String> {
    use std::f64::consts::PI;
    let h = cell_sizes(lengths, cells)?;
    let (h_min, h_max) = (h[0].min(h[1]).min(h[2]), h[0].max(h[1]).max(h[2]));
    let bound = far_bound(radius, split, h);
    let budget = far_budget(radius, tolerance, lengths);
    // The aliasing at the lowest wave numbers, about 2 exp(-2 pi^2 sigma^2 / h^2) per
    // axis, is part of the bound whatever the support: the Gaussian must span at least
    // these cells (a lower estimate, with room: it only spares searching supports too
    // short for any width that could meet the budget).
    let narrowest = h_max * ((0.25 / budget).ln().max(0.0) / (2.0 * PI * PI)).sqrt();
    // Undoing the Gaussians in the Green function (exp(sigma^2 k^2) against the
    // screening's exp(-k^2 / 4 xi^2)) outgrows the aliasing it removes as the width nears
    // 1 / (2 xi), where nothing is left to undo.
    let (lo, hi) = ((0.8 * narrowest).max(0.3 * h_min), 0.5 / split);
    // A support wider than the grid wraps around it.
    let largest = MAX_FAR_SUPPORT;
    for support in 3..=largest {
        // A tail past half the support of more than the budget (one side of one axis)
        // at the narrowest width: this support is too short for any width.
        let half = 0.5 * support as f64 * h_min / narrowest;
        if crate::nodes::fcm::plan::erfc(half / std::f64::consts::SQRT_2) > 4.0 * budget {
            continue;
        }
        // Past two deviations in half the support, the tail alone (4.6 % per axis) is
        // beyond any tolerance PSE takes.
        let widest = hi.min(0.25 * support as f64 * h_min).max(lo);
        let (width, least) = golden_min(|w| bound(w, support), lo, widest, 10);
        if least <= budget {
            return Ok(FarWindow { width, support });
        }
    }
    // Why not: the aliasing alone (a support past any truncation) at its best width.
    let untruncated = |sigma: f64| {
        let p = (2.0 * UNTRUNCATED_DEVIATIONS * sigma / h_min).ceil() as u32 + 1;
        bound(sigma, p)
    };
    let (_, aliasing) = golden_min(untruncated, lo, hi, 16);
    let why = if aliasing > budget {
        format!(
            "its Gaussian's aliasing stays at {:.2e} of the self-mobility at best",
            aliasing / periodic_self(radius, lengths)
        )
    } else {
        format!("no support up to {largest} cells cuts its Gaussian there")
    };
    Err(format!(
        "the far-field grid {cells:?} cannot reach PSE's tolerance {tolerance:e} at split {split}: {why}, above the far field's share {:.2e} (set a finer `grid`, a larger `split`, or a looser `tolerance`)",
        FAR_SHARE * tolerance
    ))
}

/// The support PSE's far field needs for a Gaussian of standard deviation `width` on this
/// grid: the fewest cells whose error bound ([`far_bound`]) is within [`FAR_SHARE`] of the
/// tolerance (for the planner's width, the support [`far_window`] chose).
pub fn support(
    radius: f64,
    split: f64,
    tolerance: f64,
    lengths: &[f64],
    cells: &[u32],
    width: f64,
) -> Result<u32, String> {
    if let Ok(w) = far_window(radius, split, tolerance, lengths, cells)
        && w.width == width
    {
        return Ok(w.support);
    }
    let bound = far_bound(radius, split, cell_sizes(lengths, cells)?);
    let budget = far_budget(radius, tolerance, lengths);
    let largest = MAX_FAR_SUPPORT;
    (3..=largest)
        .find(|&p| bound(width, p) <= budget)
        .ok_or_else(|| {
            format!(
                "a far-field Gaussian of width {width} on the grid {cells:?} misses PSE's tolerance {tolerance:e} with any support up to {largest} cells (its aliasing or its tail is too large: leave `width` to the planner, or set a finer `grid`)"
            )
        })
}

/// The x in [lo, hi] where a unimodal f is least, by golden-section search, with f there.
fn golden_min(f: impl Fn(f64) -> f64, mut lo: f64, mut hi: f64, steps: u32) -> (f64, f64) {
    let r = 0.5 * (5f64.sqrt() - 1.0);
    let (mut a, mut b) = (hi - r * (hi - lo), lo + r * (hi - lo));
    let (mut fa, mut fb) = (f(a), f(b));
    for _ in 0..steps {
        if fa <= fb {
            hi = b;
            (b, fb) = (a, fa);
            a = hi - r * (hi - lo);
            fa = f(a);
        } else {
            lo = a;
            (a, fa) = (b, fb);
            b = lo + r * (hi - lo);
            fb = f(b);
        }
    }
    if fa <= fb { (a, fa) } else { (b, fb) }
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
        let l = [128.0; 3];
        let g = grid(&l, 0.5, 1e-3).unwrap();
        assert_eq!(g, vec![108; 3]);
        let rc = cutoff(1.0, 0.5, 1e-3, &l).unwrap();
        assert!(rc > 5.2565 && rc < 6.5, "{rc}");
        assert_eq!(neighbour_cells(&l, 5.3), vec![24; 3]);
        // The far-field Gaussian: the least support whose bound meets 3/4 of the
        // tolerance, one more than UAMMD's Lindbo-Tornberg shape at 1e-3 (7) cut at 6.
        let w = far_window(1.0, 0.5, 1e-3, &l, &g).unwrap();
        assert_eq!(w.support, 7);
        assert_eq!(support(1.0, 0.5, 1e-3, &l, &g, w.width), Ok(7));
        let bound = far_bound(1.0, 0.5, [128.0 / 108.0; 3]);
        assert!(bound(w.width, 7) <= far_budget(1.0, 1e-3, &l));
        assert!(bound(w.width, 6) > far_budget(1.0, 1e-3, &l));
    }

    /// The far field of PSE as its graph computes it, in f64: spread with the stencil of
    /// `GridWindow`, the screened Green function with both Gaussians undone, interpolate;
    /// written as the sum over the grid's wave numbers of the two stencils' transforms.
    /// The velocity of a particle at `target` per unit force at `source` (row: velocity
    /// component).
    fn far_pipeline(
        l: f64,
        n: u32,
        split: f64,
        window: FarWindow,
        source: [f64; 3],
        target: [f64; 3],
    ) -> [[f64; 3]; 3] {
        use crate::nodes::spread::{GridWindow, window::Window};
        use std::f64::consts::PI;
        let grid = GridWindow {
            lengths: vec![l; 3],
            cells: vec![n; 3],
            window: Window::Gaussian {
                sigma: window.width,
                support: window.support,
            },
            workgroup: 256,
            contiguous: false,
            auto_order: true,
            lanes: true,
            min_width_cells: 0.0,
        };
        let n = n as i64;
        let h = l / n as f64;
        let wave = |i: i64| if i <= n / 2 { i } else { i - n };
        // Per axis: sum_j w_j e^{-i k x_j} for every wave number of the grid.
        let transform = |x: [f64; 3]| -> Vec<Vec<(f64, f64)>> {
            (0..3)
                .map(|a| {
                    let (first, w) = grid.stencil(x[a], a);
                    (0..n)
                        .map(|i| {
                            let k = 2.0 * PI * wave(i) as f64 / l;
                            w.iter().enumerate().fold((0.0, 0.0), |(re, im), (j, wj)| {
                                let xj = -0.5 * l + ((first + j as i64) as f64 + 0.5) * h;
                                (re + wj * (k * xj).cos(), im - wj * (k * xj).sin())
                            })
                        })
                        .collect()
                })
                .collect()
        };
        let (s, t) = (transform(source), transform(target));
        let mut m = [[0.0; 3]; 3];
        for iz in 0..n {
            for iy in 0..n {
                for ix in 0..n {
                    let w = [wave(ix), wave(iy), wave(iz)];
                    if w == [0, 0, 0] {
                        continue;
                    }
                    let k = w.map(|m| 2.0 * PI * m as f64 / l);
                    let k2: f64 = k.iter().map(|x| x * x).sum();
                    // The projection leaves out unpaired Nyquist wave numbers (stokes).
                    let kp = [0, 1, 2].map(|a| if w[a].abs() * 2 == n { 0.0 } else { k[a] });
                    let kp2: f64 = kp.iter().map(|x| x * x).sum();
                    let green =
                        crate::nodes::spectral::pse_screening(k2, 1.0, split, window.width) / k2;
                    let at = [ix as usize, iy as usize, iz as usize];
                    let (mut re, mut im) = (1.0, 0.0);
                    for a in 0..3 {
                        let ((sr, si), (tr, ti)) = (s[a][at[a]], t[a][at[a]]);
                        let (cr, ci) = (sr * tr + si * ti, si * tr - sr * ti);
                        (re, im) = (re * cr - im * ci, re * ci + im * cr);
                    }
                    for (i, row) in m.iter_mut().enumerate() {
                        for (j, v) in row.iter_mut().enumerate() {
                            let d = if i == j { 1.0 } else { 0.0 };
                            let p = if kp2 > 0.0 {
                                d - kp[i] * kp[j] / kp2
                            } else {
                                d
                            };
                            *v += green * p * re;
                        }
                    }
                }
            }
        }
        let scale = h.powi(3) / (n * n * n) as f64;
        m.map(|row| row.map(|v| v * scale))
    }

    /// The far field exactly: (1/V) sum_k sinc^2(ka) H(k) (I - k k^T / k^2) e^{ik.r} / k^2.
    fn far_exact(l: f64, split: f64, r: [f64; 3]) -> [[f64; 3]; 3] {
        use std::f64::consts::PI;
        let k_max = 2.0 * split * 40f64.sqrt();
        let kn = (k_max * l / (2.0 * PI)).ceil() as i64;
        let mut m = [[0.0; 3]; 3];
        for kx in -kn..=kn {
            for ky in -kn..=kn {
                for kz in -kn..=kn {
                    let k = [kx, ky, kz].map(|c| 2.0 * PI * c as f64 / l);
                    let k2: f64 = k.iter().map(|x| x * x).sum();
                    if k2 == 0.0 || k2 > k_max * k_max {
                        continue;
                    }
                    let c = (k[0] * r[0] + k[1] * r[1] + k[2] * r[2]).cos()
                        * crate::nodes::spectral::pse_screening(k2, 1.0, split, 0.0)
                        / (k2 * l * l * l);
                    for (i, row) in m.iter_mut().enumerate() {
                        for (j, v) in row.iter_mut().enumerate() {
                            *v += c * (if i == j { 1.0 } else { 0.0 } - k[i] * k[j] / k2);
                        }
                    }
                }
            }
        }
        m
    }

    /// The planner's far-field Gaussian keeps the pipeline's error, computed in f64 (no
    /// f32 rounding), within 3/4 of the tolerance at the placements where aliasing and
    /// truncation peak (a grid point, a cell's centre, faces and edges: the window's
    /// error peaks where the particle sits on a grid point or midway on each axis) and
    /// for pairs, at 1e-2 to 1e-6. Lindbo and Tornberg's shape, the rule before, gave
    /// 4.6e-4 at 1e-4 here (L = 16: sigma = 0.765 h, support 7).
    #[test]
    fn far_window_meets_the_tolerance_at_the_worst_placements() {
        use std::f64::consts::PI;
        let l = 16.0;
        for tol in [1e-2, 3e-3, 1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 1e-6] {
            let lengths = [l; 3];
            let split = default_split(1.0, tol, &lengths).unwrap();
            let cells = grid(&lengths, split, tol).unwrap();
            let window = far_window(1.0, split, tol, &lengths, &cells).unwrap();
            let h = l / cells[0] as f64;
            let self_mobility = crate::nodes::fcm::plan::hasimoto(1.0, l) / (6.0 * PI);
            let exact_self = far_exact(l, split, [0.0; 3]);
            let mut worst: f64 = 0.0;
            let origin = -0.5 * l + 3.5 * h; // a grid point (a cell's centre)
            for offset in [
                [0.0; 3],
                [0.5; 3],
                [0.5, 0.0, 0.0],
                [0.5, 0.5, 0.0],
                [0.25, 0.0, 0.5],
            ] {
                let x = offset.map(|o| origin + o * h);
                let m = far_pipeline(l, cells[0], split, window, x, x);
                for a in 0..3 {
                    worst = worst.max((m[a][a] - exact_self[a][a]).abs() / self_mobility);
                }
                for (r, direction) in [(1.3, [1.0, 0.0, 0.0]), (4.1, [0.6, 0.0, 0.8])] {
                    let y = [0, 1, 2].map(|c| x[c] + r * direction[c]);
                    let m = far_pipeline(l, cells[0], split, window, x, y);
                    let want = far_exact(l, split, [0, 1, 2].map(|c| y[c] - x[c]));
                    for (row, want_row) in m.iter().zip(&want) {
                        for (v, w) in row.iter().zip(want_row) {
                            worst = worst.max((v - w).abs() / self_mobility);
                        }
                    }
                }
            }
            assert!(
                worst <= FAR_SHARE * tol,
                "tolerance {tol:e}: grid {}, width {:.4} h, support {}: far-field error {worst:.3e}",
                cells[0],
                window.width / h,
                window.support
            );
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
        assert!(2.0 * cutoff(1.0, s, 1e-3, &[8.0; 3]).unwrap() <= 8.0 && s > 0.5);
        let s = default_split(1.0, 1e-3, &[2.0, 8.0, 8.0]).unwrap();
        assert!(cutoff(1.0, s, 1e-3, &[2.0, 8.0, 8.0]).unwrap() <= 1.0);
    }
}
