//! The window (smoothing kernel) library of spreading and interpolation.
//!
//! A window is separable: delta(x) = prod over axes of phi(x_a / h_a) / h_a. Each one is a
//! WGSL function `window_phi(r, p)` in `shaders/window/` (r in units of the cell size, p its
//! per-axis params) and, here, the same function in f64 with its support rule. Adding a
//! window is one WGSL file plus one variant below.
//!
//! Formulas: UAMMD thesis section 21 (digest section 1.4); the ES window is Barnett,
//! Magland and af Klinteberg, SIAM J. Sci. Comput. 41 (2019).

/// A window with its parameters fixed (lengths in physical units).
#[derive(Clone, Debug, PartialEq)]
pub enum Window {
    /// Gaussian of standard deviation `sigma`, truncated to `support` cells.
    Gaussian {
        sigma: f64,
        support: u32,
    },
    /// Exponential of semicircle with shape `beta`, zero beyond its half-width: `support`
    /// / 2 cells (tied to the cell, FCM's), or `half_width` as a length (the same window
    /// on any cell, so one radius whatever the grid: the doubly periodic solvers); the
    /// loops visit `support` cells, at least its width. `unit_integral` is the integral of
    /// its shape over a unit half-width, computed once.
    Es {
        beta: f64,
        support: u32,
        half_width: Option<f64>,
        unit_integral: f64,
    },
    Peskin3,
    Peskin4,
    Peskin6,
}

/// Names in graph files.
pub const NAMES: &[&str] = &["gaussian", "es", "peskin3", "peskin4", "peskin6"];

/// Largest support (cells per axis) the kernels handle.
pub const MAX_SUPPORT: u32 = 32;

/// 59/60 - sqrt(29)/20: the second moment of the 6-point window.
pub const PESKIN6_K: f64 = 0.714_075_092_976_608_1;

impl Window {
    /// Builds a window from graph-file params. `h_min` is the smallest cell size (the
    /// Gaussian's support from the tolerance is decided on it).
    pub fn from_params(
        name: &str,
        width: f64,
        support: u32,
        beta: f64,
        tolerance: f64,
        h_min: f64,
    ) -> Result<Window, String> {
        let w = match name {
            "gaussian" => {
                if width <= 0.0 {
                    return Err(
                        "the Gaussian window needs `width` (its standard deviation) > 0".into(),
                    );
                }
                // The kernels evaluate exp(-r^2 / (2 s^2)) / (sqrt(2 pi) s) in f32 with s
                // = width / h: a width far below or above the cell leaves f32's range.
                let s = width / h_min;
                crate::node::check_f32_coefficient(
                    "the Gaussian's exponent factor h^2 / (2 `width`^2) (h the cell size)",
                    0.5 / (s * s),
                )?;
                let support = if support > 0 {
                    support
                } else {
                    gaussian_support(width, tolerance, h_min)
                };
                Window::Gaussian {
                    sigma: width,
                    support,
                }
            }
            "es" if width > 0.0 => {
                // A half-width as a length: the support is the cells it spans on the
                // finest axis, the default shape Barnett's 2.3 per cell spanned.
                let cells = 2.0 * width / h_min;
                if !(cells.is_finite() && cells <= MAX_SUPPORT as f64) {
                    return Err(format!(
                        "the ES window's half-width `width` = {width} spans {cells:.4} cells of {h_min:.6}: more than the {MAX_SUPPORT} supported"
                    ));
                }
                let needed = (cells - 1e-9).ceil().max(2.0) as u32;
                if support > 0 && support < needed {
                    return Err(format!(
                        "support = {support} cells is narrower than the ES window's width, 2 `width` / h = {cells:.4} cells"
                    ));
                }
                let beta = if beta > 0.0 { beta } else { 2.3 * cells };
                Window::es_with_half_width(beta, support.max(needed), width)
            }
            "es" => {
                let support = if support > 0 {
                    support
                } else {
                    es_support(tolerance)
                };
                let beta = if beta > 0.0 {
                    beta
                } else {
                    2.3 * support as f64
                };
                Window::es(beta, support)
            }
            "peskin3" => Window::Peskin3,
            "peskin4" => Window::Peskin4,
            "peskin6" => Window::Peskin6,
            other => {
                return Err(format!(
                    "unknown window `{other}` (windows: {})",
                    NAMES.join(", ")
                ));
            }
        };
        if w.support() > MAX_SUPPORT {
            return Err(format!(
                "a support of {} cells is more than the {MAX_SUPPORT} supported; use a wider grid spacing or a looser tolerance",
                w.support()
            ));
        }
        if w.support() < 2 {
            return Err(format!(
                "a support of {} cell is too small (at least 2)",
                w.support()
            ));
        }
        Ok(w)
    }

    /// The ES window over `support` cells (its half-width support / 2 cells).
    pub fn es(beta: f64, support: u32) -> Window {
        Window::Es {
            beta,
            support,
            half_width: None,
            unit_integral: es_integral(beta, 1.0),
        }
    }

    /// The ES window of half-width `half_width` (a length), visited over `support` cells.
    pub fn es_with_half_width(beta: f64, support: u32, half_width: f64) -> Window {
        Window::Es {
            beta,
            support,
            half_width: Some(half_width),
            unit_integral: es_integral(beta, 1.0),
        }
    }

    /// Where the window ends, in cells of size h: half the support, or the ES window's
    /// half-width over h.
    pub fn half_support_cells(&self, h: f64) -> f64 {
        match self {
            Window::Es {
                half_width: Some(w),
                ..
            } => w / h,
            _ => self.support() as f64 / 2.0,
        }
    }

    /// Cells per axis the window touches.
    pub fn support(&self) -> u32 {
        match self {
            Window::Gaussian { support, .. } | Window::Es { support, .. } => *support,
            Window::Peskin3 => 3,
            Window::Peskin4 => 4,
            Window::Peskin6 => 6,
        }
    }

    /// The WGSL file defining `window_phi`.
    pub fn shader(&self) -> &'static str {
        match self {
            Window::Gaussian { .. } => "window/gaussian.wgsl",
            Window::Es { .. } => "window/es.wgsl",
            Window::Peskin3 => "window/peskin3.wgsl",
            Window::Peskin4 => "window/peskin4.wgsl",
            Window::Peskin6 => "window/peskin6.wgsl",
        }
    }

    /// The per-axis params `p` of `window_phi` for cell size `h`.
    pub fn gpu_params(&self, h: f64) -> [f32; 4] {
        match self {
            Window::Gaussian { sigma, .. } => [(sigma / h) as f32, 0.0, 0.0, 0.0],
            Window::Es {
                beta,
                unit_integral,
                ..
            } => {
                let alpha = self.half_support_cells(h);
                [
                    *beta as f32,
                    alpha as f32,
                    (1.0 / (alpha * unit_integral)) as f32,
                    0.0,
                ]
            }
            _ => [0.0; 4],
        }
    }

    /// phi(r) per unit h, r = distance / h, in f64.
    pub fn phi(&self, r: f64, h: f64) -> f64 {
        match self {
            Window::Gaussian { sigma, .. } => {
                let s = sigma / h;
                (-0.5 * r * r / (s * s)).exp() / ((2.0 * std::f64::consts::PI).sqrt() * s)
            }
            Window::Es {
                beta,
                unit_integral,
                ..
            } => {
                let alpha = self.half_support_cells(h);
                es_shape(r, *beta, alpha) / (alpha * unit_integral)
            }
            Window::Peskin3 => peskin3(r),
            Window::Peskin4 => peskin4(r),
            Window::Peskin6 => peskin6(r),
        }
    }

    /// The Fourier transform of phi per unit length, int phi(x) cos(k x) dx, at wave number
    /// k (inverse length) on cells of size h, in f64: exact for the Gaussian, Simpson's
    /// rule over the support (4000 intervals) for the others. For the references.
    pub fn transform(&self, k: f64, h: f64) -> f64 {
        if let Window::Gaussian { sigma, .. } = self {
            return (-0.5 * sigma * sigma * k * k).exp();
        }
        let half = self.half_support_cells(h) * h;
        simpson(-half, half, 4000, |x| {
            self.phi(x / h, h) / h * (k * x).cos()
        })
    }

    /// One line for `mesoflow inspect`.
    pub fn describe(&self) -> String {
        match self {
            Window::Gaussian { sigma, support } => {
                format!("Gaussian window, sigma = {sigma}, support {support} cells")
            }
            Window::Es {
                beta,
                support,
                half_width: None,
                ..
            } => {
                format!("ES window, beta = {beta}, support {support} cells")
            }
            Window::Es {
                beta,
                support,
                half_width: Some(w),
                ..
            } => {
                format!("ES window, beta = {beta}, half-width {w} (over {support} cells)")
            }
            Window::Peskin3 => "Peskin 3-point window".into(),
            Window::Peskin4 => "Peskin 4-point window".into(),
            Window::Peskin6 => "Peskin 6-point window (Bao, Kaye, Peskin)".into(),
        }
    }
}

/// UAMMD's Gaussian support rule (FCM_kernels.cuh): step r by h/2 from h/2 until the
/// unit-integral Gaussian in units of h, exp(-r^2 / 2 s^2) / (sqrt(2 pi) s) with s = sigma/h,
/// drops to the tolerance; then n = max(3, round(2r/h)).
pub fn gaussian_support(sigma: f64, tolerance: f64, h: f64) -> u32 {
    let s = sigma / h;
    let phi = |r: f64| (-0.5 * r * r / (s * s)).exp() / ((2.0 * std::f64::consts::PI).sqrt() * s);
    let mut r = 0.5;
    while phi(r) > tolerance {
        r += 0.5;
    }
    ((2.0 * r + 0.5) as u32).max(3)
}

/// Barnett-Magland rule: about one cell per digit, plus one.
pub fn es_support(tolerance: f64) -> u32 {
    ((-tolerance.log10()).ceil() as u32 + 1).max(2)
}

fn es_shape(r: f64, beta: f64, alpha: f64) -> f64 {
    let z = r / alpha;
    if z.abs() >= 1.0 {
        0.0
    } else {
        (beta * ((1.0 - z * z).sqrt() - 1.0)).exp()
    }
}

/// Integral of the ES shape over [-alpha, alpha] (Simpson, 20000 intervals, as UAMMD).
pub fn es_integral(beta: f64, alpha: f64) -> f64 {
    simpson(-alpha, alpha, 20_000, |x| es_shape(x, beta, alpha))
}

/// Simpson's weight of sample i of n intervals (n even), without the step / 3: 1 at the
/// ends, 4 and 2 between.
pub fn simpson_weight(i: usize, n: usize) -> f64 {
    if i == 0 || i == n {
        1.0
    } else if i % 2 == 1 {
        4.0
    } else {
        2.0
    }
}

/// int_lo^hi f by Simpson's rule on n intervals (n even), the ends added first.
pub fn simpson(lo: f64, hi: f64, n: usize, f: impl Fn(f64) -> f64) -> f64 {
    let dx = (hi - lo) / n as f64;
    let at = |i: usize| f(lo + i as f64 * dx);
    let mut s = at(0) + at(n);
    for i in 1..n {
        s += simpson_weight(i, n) * at(i);
    }
    s * dx / 3.0
}

fn peskin3(r: f64) -> f64 {
    let r = r.abs();
    if r < 0.5 {
        (1.0 + (1.0 - 3.0 * r * r).sqrt()) / 3.0
    } else if r < 1.5 {
        let s = 1.0 - r;
        (5.0 - 3.0 * r - (1.0 - 3.0 * s * s).max(0.0).sqrt()) / 6.0
    } else {
        0.0
    }
}

fn peskin4(r: f64) -> f64 {
    let r = r.abs();
    if r < 1.0 {
        (3.0 - 2.0 * r + (1.0 + 4.0 * r * (1.0 - r)).sqrt()) / 8.0
    } else if r < 2.0 {
        (5.0 - 2.0 * r - (-7.0 + 12.0 * r - 4.0 * r * r).max(0.0).sqrt()) / 8.0
    } else {
        0.0
    }
}

fn peskin6_chi(rr: f64) -> f64 {
    let k = PESKIN6_K;
    let r2 = rr * rr;
    let alpha = 28.0;
    let beta = 9.0 / 4.0 - 1.5 * (k + r2) + (22.0 / 3.0 - 7.0 * k) * rr - (7.0 / 3.0) * r2 * rr;
    let gamma = 0.25
        * (0.5 * (161.0 / 36.0 - (59.0 / 6.0) * k + 5.0 * k * k) * r2
            + (1.0 / 3.0) * (-109.0 / 24.0 + 5.0 * k) * r2 * r2
            + (5.0 / 18.0) * r2 * r2 * r2);
    let disc = (beta * beta - 4.0 * alpha * gamma).max(0.0);
    (-beta + disc.sqrt()) / (2.0 * alpha)
}

fn peskin6(r: f64) -> f64 {
    let r = r.abs();
    let k = PESKIN6_K;
    if r >= 3.0 {
        return 0.0;
    }
    // chi is evaluated at the position within the piece: r on [0, 1], r - 1 on (1, 2],
    // r - 2 on (2, 3).
    if r <= 1.0 {
        2.0 * peskin6_chi(r) + 5.0 / 8.0 - 0.25 * (k + r * r)
    } else if r <= 2.0 {
        let s = r - 1.0;
        -3.0 * peskin6_chi(s) + 0.25 - (1.0 / 6.0) * (4.0 - 3.0 * k) * s + (1.0 / 6.0) * s * s * s
    } else {
        let s = r - 2.0;
        peskin6_chi(s) - 1.0 / 16.0 + 0.125 * (k + s * s)
            - (1.0 / 12.0) * (3.0 * k - 1.0) * s
            - (1.0 / 12.0) * s * s * s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// sum_j f(x - j) over the integers j where phi is non-zero.
    fn lattice_sum(f: impl Fn(f64) -> f64, x: f64) -> f64 {
        (-8..=8).map(|j| f(x - j as f64)).sum()
    }

    /// The Peskin identities of the thesis digest (section 13.1), in f64 to 1e-12.
    #[test]
    fn peskin_identities() {
        let cases: [(Window, f64); 3] = [
            (Window::Peskin3, 0.5),
            (Window::Peskin4, 3.0 / 8.0),
            (Window::Peskin6, 0.325_777_615_390),
        ];
        for (w, square_sum) in cases {
            for i in 0..40 {
                let x = i as f64 / 40.0;
                let phi = |r: f64| w.phi(r, 1.0);
                assert!(
                    (lattice_sum(phi, x) - 1.0).abs() < 1e-12,
                    "{w:?} unit mass at {x}"
                );
                assert!(
                    lattice_sum(|r| r * phi(r), x).abs() < 1e-12,
                    "{w:?} first moment at {x}"
                );
                assert!(
                    (lattice_sum(|r| phi(r) * phi(r), x) - square_sum).abs() < 1e-11,
                    "{w:?} sum of squares at {x}"
                );
                if w != Window::Peskin3 {
                    let even: f64 = (-8..=8)
                        .filter(|j: &i32| j % 2 == 0)
                        .map(|j| phi(x - j as f64))
                        .sum();
                    assert!((even - 0.5).abs() < 1e-12, "{w:?} even/odd at {x}");
                }
                if w == Window::Peskin6 {
                    assert!(
                        (lattice_sum(|r| r * r * phi(r), x) - PESKIN6_K).abs() < 1e-12,
                        "second moment at {x}"
                    );
                    assert!(
                        lattice_sum(|r| r * r * r * phi(r), x).abs() < 1e-12,
                        "third moment at {x}"
                    );
                }
            }
        }
        let p = |w: &Window, r: f64| w.phi(r, 1.0);
        assert!((p(&Window::Peskin3, 0.0) - 2.0 / 3.0).abs() < 1e-15);
        assert!((p(&Window::Peskin3, 1.0) - 1.0 / 6.0).abs() < 1e-15);
        assert!(
            (p(&Window::Peskin4, 0.0) - 0.5).abs() < 1e-15
                && (p(&Window::Peskin4, 1.0) - 0.25).abs() < 1e-15
        );
        assert!((p(&Window::Peskin6, 0.0) - 0.446_481_226_8).abs() < 1e-10);
        assert!((p(&Window::Peskin6, 1.0) - 0.25).abs() < 1e-12);
        assert!((p(&Window::Peskin6, 2.0) - 0.026_759_386_7).abs() < 1e-10);
        assert_eq!(p(&Window::Peskin6, 3.0), 0.0);
        // Continuity at the breakpoints.
        for w in [Window::Peskin3, Window::Peskin4, Window::Peskin6] {
            for b in [0.5, 1.0, 1.5, 2.0, 2.5, 3.0] {
                assert!(
                    (p(&w, b - 1e-9) - p(&w, b + 1e-9)).abs() < 1e-7,
                    "{w:?} jumps at {b}"
                );
            }
        }
    }

    /// ES normalisation against the digest's values (beta = 3.6 n_s, alpha = n_s / 2).
    #[test]
    fn es_integrals() {
        for (ns, s) in [
            (3.0, 1.103_130_805_8),
            (4.0, 1.285_908_097_9),
            (5.0, 1.445_710_624_8),
            (6.0, 1.589_506_894_0),
        ] {
            assert!(
                (es_integral(3.6 * ns, ns / 2.0) - s).abs() < 1e-8,
                "n_s = {ns}"
            );
        }
    }

    /// The Gaussian support table of the digest (section 1.5), from sigma = g_u h.
    #[test]
    fn gaussian_support_table() {
        for (eps, gu, ns) in [
            (1e-2, 0.7175, 5),
            (1e-3, 0.8275, 6),
            (1e-4, 0.9375, 8),
            (1e-5, 1.0475, 10),
            (1e-6, 1.1575, 12),
            (1e-7, 1.2675, 14),
        ] {
            assert_eq!(gaussian_support(gu, eps, 1.0), ns, "tolerance {eps}");
        }
    }

    /// An ES window with a half-width as a length is the same function of length on any
    /// cell (one integral, one transform), visits the cells it spans, and refuses a support
    /// narrower than itself.
    #[test]
    fn es_half_width_is_a_length() {
        let w = Window::from_params("es", 1.3, 0, 11.5, 1e-3, 0.5).unwrap();
        assert_eq!(w.support(), 6, "2 x 1.3 / 0.5 = 5.2 cells");
        for h in [0.5, 0.37, 0.8] {
            let n = 20_000;
            let dx = 2.6 / n as f64;
            let integral: f64 = (0..n)
                .map(|i| w.phi((-1.3 + (i as f64 + 0.5) * dx) / h, h) / h * dx)
                .sum();
            assert!((integral - 1.0).abs() < 1e-6, "h {h}: integral {integral}");
            assert_eq!(w.phi(1.3 / h, h), 0.0);
            let p = w.gpu_params(h);
            assert!((p[1] as f64 - 1.3 / h).abs() < 1e-6 && p[0] == 11.5);
            assert!((p[2] as f64 - w.phi(0.0, h)).abs() < 1e-6 * w.phi(0.0, h));
        }
        assert!((w.transform(0.0, 0.5) - 1.0).abs() < 1e-6);
        assert!((w.transform(2.0, 0.5) - w.transform(2.0, 0.3)).abs() < 1e-12);
        let err = Window::from_params("es", 1.3, 5, 0.0, 1e-3, 0.5).unwrap_err();
        assert!(err.contains("narrower"), "{err}");
        let g = Window::Gaussian {
            sigma: 0.7,
            support: 12,
        };
        // The Gaussian's transform by the quadrature the others use.
        let n = 40_000;
        let dx = 16.0 / n as f64;
        let k = 1.7;
        let q: f64 = (0..n)
            .map(|i| {
                let x = -8.0 + (i as f64 + 0.5) * dx;
                g.phi(x, 1.0) * (k * x).cos() * dx
            })
            .sum();
        assert!((g.transform(k, 1.0) - q).abs() < 1e-9);
    }

    #[test]
    fn windows_integrate_to_one() {
        for w in [
            Window::Gaussian {
                sigma: 0.9,
                support: 12,
            },
            Window::es(9.2, 4),
            Window::Peskin3,
            Window::Peskin4,
            Window::Peskin6,
        ] {
            let n = 60_000;
            let dx = 16.0 / n as f64;
            let s: f64 = (0..n)
                .map(|i| w.phi(-8.0 + (i as f64 + 0.5) * dx, 1.0) * dx)
                .sum();
            assert!((s - 1.0).abs() < 1e-6, "{w:?}: integral {s}");
        }
    }
}
