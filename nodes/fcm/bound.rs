//! The error of FCM's grid pipeline with a Gaussian window (spread, FFT, a Green function,
//! inverse FFT, interpolate), bounded in f64 for every placement and pair: what the FCM
//! and PSE planners choose the window's support (and PSE its width) by.
//!
//! In a box much larger than the window, the pipeline gives between particles at x_s and
//! x_t
//!   M_grid = (2 pi)^-3 int_BZ K(k) P(k) (1 + d_s(k)) conj(1 + d_t(k)) e^{ik.(x_t - x_s)} d^3k,
//! with P = I - k k^T / k^2 and K the mobility's kernel: e^{-sigma^2 k^2} / (eta k^2) for
//! FCM (the two windows' Gaussians), sinc^2(ka) H(k, xi) / (eta k^2) for PSE's far field
//! (whose Green function undoes the Gaussians). 1 + d_x(k) is the discrete window's
//! transform over the continuous Gaussian's,
//!   1 + d_x(k) = prod_a h sum_{j in support} W(x_j - x_a) e^{-i k_a (x_j - x_a)} / e^{-sigma^2 k_a^2 / 2}:
//! aliasing (the grid's images of the window) and truncation (the support) in one factor.
//! The exact mobility is the same integral over all k with d = 0. With
//! D(k) = prod_a (1 + sup_x |d_a(k_a, x)|) - 1, every component of the error, for every
//! placement and every pair, is at most
//!   (2 pi)^-3 [int_BZ K |P_ij| (2 D + D^2) d^3k + int_{outside BZ} K d^3k].
//! The periodic sum over the box's wave numbers is this integral's Riemann sum; for boxes
//! of several windows the two agree to a few per cent (tests/it/pse.rs and
//! tests/it/fcm/mobility.rs check the bound's promise at the worst placements on the GPU).

/// Panels of the graded Gauss-Legendre rule along each wave-number axis: [0, K/2^(P-1)],
/// then doubling to [K/2, K] (K = pi / h), 8 points each, so that the 1/k^2 of the Stokes
/// kernel at k = 0 is resolved (the bound agrees to 4 digits with 10 panels).
const ZONE_PANELS: i32 = 4;

/// Placements per axis the sup over placements samples, over half a cell (the window's
/// error is even in the offset from a cell centre).
const ZONE_PLACEMENTS: u32 = 8;

/// The Fourier-space weights of a mobility kernel on a quadrature of a grid's Brillouin
/// zone, computed once per (kernel, cell sizes) and then evaluated for any Gaussian width
/// and support ([`WindowBound::bound`]).
pub struct WindowBound {
    /// Cell size per axis.
    h: [f64; 3],
    /// Wave numbers and weights per axis, on [0, pi / h_a].
    nodes: [Vec<(f64, f64)>; 3],
    /// K |P_ij| times the quadrature weight at each point of the zone's positive octant
    /// (times 8, the octants: every factor is even in each k_a), for xx, yy, zz, xy, xz, yz.
    weights: Vec<[f64; 6]>,
    /// (2 pi)^-3 int K over the wave vectors past the zone's inscribed sphere, which hold
    /// those outside the zone.
    outside: f64,
}

impl WindowBound {
    /// The weights for a kernel, given as k^2 K(k) (a function of k^2; viscosity 1) that
    /// decays past `k_end`, on cells of these sizes.
    pub fn new(kernel: impl Fn(f64) -> f64, k_end: f64, h: [f64; 3]) -> Self {
        use std::f64::consts::PI;
        let nodes = h.map(|ha| graded_nodes(PI / ha));
        let scale = 8.0 / (2.0 * PI).powi(3);
        let mut weights = Vec::with_capacity(nodes[0].len() * nodes[1].len() * nodes[2].len());
        for &(kz, wz) in &nodes[2] {
            for &(ky, wy) in &nodes[1] {
                for &(kx, wx) in &nodes[0] {
                    let k2 = kx * kx + ky * ky + kz * kz;
                    let b = scale * kernel(k2) / k2 * wx * wy * wz;
                    weights.push([
                        b * (1.0 - kx * kx / k2),
                        b * (1.0 - ky * ky / k2),
                        b * (1.0 - kz * kz / k2),
                        b * (kx * ky / k2),
                        b * (kx * kz / k2),
                        b * (ky * kz / k2),
                    ]);
                }
            }
        }
        // (2 pi)^-3 4 pi int_K^inf K k^2 dk, Gauss-Legendre panels out to `k_end`.
        let k_in = h.iter().map(|&ha| PI / ha).fold(f64::INFINITY, f64::min);
        let k_end = k_end.max(k_in);
        let panels = ((k_end - k_in) / (0.02 * k_end)).ceil().max(1.0) as usize;
        let width = (k_end - k_in) / panels as f64;
        let mut outside = 0.0;
        for p in 0..panels {
            let mid = k_in + (p as f64 + 0.5) * width;
            for &(x, w) in &crate::nodes::pairs::rpy::GL8 {
                for k in [mid - 0.5 * width * x, mid + 0.5 * width * x] {
                    outside += 0.5 * width * w * kernel(k * k);
                }
            }
        }
        WindowBound {
            h,
            nodes,
            weights,
            outside: outside / (2.0 * PI * PI),
        }
    }

    /// The bound on every component of the pipeline's error, for any placement and pair,
    /// for a Gaussian window of standard deviation `width` cut at `support` cells: in the
    /// kernel's units (a mobility at viscosity 1).
    pub fn bound(&self, width: f64, support: u32) -> f64 {
        let mut sup: Vec<Vec<f64>> = Vec::with_capacity(3);
        for a in 0..3 {
            // Axes of the same cell size have the same defect.
            let same = (0..a).find(|&b| self.h[b] == self.h[a]);
            let d = match same {
                Some(b) => sup[b].clone(),
                None => self.nodes[a]
                    .iter()
                    .map(|&(k, _)| window_defect(k, self.h[a], width, support))
                    .collect(),
            };
            sup.push(d);
        }
        let mut sums = [0.0; 6];
        let mut i = 0;
        for dz in &sup[2] {
            for dy in &sup[1] {
                for dx in &sup[0] {
                    let d = (1.0 + dx) * (1.0 + dy) * (1.0 + dz) - 1.0;
                    let f = 2.0 * d + d * d;
                    for (s, w) in sums.iter_mut().zip(&self.weights[i]) {
                        *s += f * w;
                    }
                    i += 1;
                }
            }
        }
        sums.into_iter().fold(0.0, f64::max) + self.outside
    }
}

/// sup over placements x of |d(k, x)| along one axis: the discrete Gaussian window's
/// transform, h sum_j W(x_j - x) e^{-ik(x_j - x)} over the `support` cells the stencil
/// takes (`GridWindow::stencil`: cells centred at whole multiples of h), over the
/// continuous one's e^{-sigma^2 k^2 / 2}, minus 1.
fn window_defect(k: f64, h: f64, sigma: f64, support: u32) -> f64 {
    let continuous = (-0.5 * sigma * sigma * k * k).exp();
    let norm = h / ((2.0 * std::f64::consts::PI).sqrt() * sigma);
    (0..=ZONE_PLACEMENTS)
        .map(|i| {
            let t = 0.5 * i as f64 / ZONE_PLACEMENTS as f64;
            let first = (t - 0.5 * support as f64).floor() + 1.0;
            let (mut re, mut im) = (0.0, 0.0);
            for j in 0..support {
                let d = (first + j as f64 - t) * h;
                let w = norm * (-0.5 * d * d / (sigma * sigma)).exp();
                let (s, c) = (k * d).sin_cos();
                re += w * c;
                im -= w * s;
            }
            ((re / continuous - 1.0).powi(2) + (im / continuous).powi(2)).sqrt()
        })
        .fold(0.0, f64::max)
}

/// Gauss-Legendre nodes and weights on [0, k_max], panels graded towards 0.
fn graded_nodes(k_max: f64) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(8 * ZONE_PANELS as usize);
    let mut lo = 0.0;
    for p in (0..ZONE_PANELS).rev() {
        let hi = k_max / 2f64.powi(p);
        let (mid, half) = (0.5 * (lo + hi), 0.5 * (hi - lo));
        for &(x, w) in &crate::nodes::pairs::rpy::GL8 {
            out.push((mid - half * x, half * w));
            out.push((mid + half * x, half * w));
        }
        lo = hi;
    }
    out
}
