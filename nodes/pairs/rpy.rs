//! The Rotne-Prager-Yamakawa tensor in f64 and the near field of its Positively Split
//! Ewald sum (UAMMD thesis section 20.2; digest section 4), tabulated on the host.
//!
//! A mobility tensor of a pair at separation r is written `f(r) I + g(r) r^ r^`.
//!
//! The PSE split (Hasimoto's splitting function H(k, xi) = (1 + k^2 / (4 xi^2))
//! exp(-k^2 / (4 xi^2))): the far field is the Fourier sum of sinc^2(ka) H(k, xi)
//! (I - k^ k^) / (eta k^2); the near field is what remains of free-space RPY,
//! `M_near(r) = M_RPY(r) - M_far,free(r)`, with M_far,free the radial inverse Fourier
//! transform of the far kernel (angular average of e^(ik.r) (I - k^ k^) is
//! (j0 - j1/x) I + j2 r^ r^, x = kr):
//!
//! M_far,free(r) = 1 / (2 pi^2 eta) int_0^inf dk sinc^2(ka) H(k, xi) [(j0 - j1/x) I + j2 r^ r^].
//!
//! The integral is Gaussian-damped and is done by composite Gauss-Legendre quadrature in
//! f64; the near field decays as exp(-xi^2 r^2), which sets the cutoff.

use std::collections::HashMap;
use std::f64::consts::PI;
use std::sync::{Arc, Mutex, OnceLock};

use crate::expr::fmt_number;

/// Free-space RPY tensor (f, g) at distance r for spheres of radius a in a fluid of
/// viscosity eta; the overlap form for r < 2a (regular at r = 0: f = 1 / (6 pi eta a)).
pub fn rpy(r: f64, a: f64, eta: f64) -> (f64, f64) {
    if r >= 2.0 * a {
        let c = 1.0 / (8.0 * PI * eta * r);
        let s = a * a / (r * r);
        (c * (1.0 + 2.0 * s / 3.0), c * (1.0 - 2.0 * s))
    } else {
        let c = 1.0 / (6.0 * PI * eta * a);
        (c * (1.0 - 9.0 * r / (32.0 * a)), c * (3.0 * r / (32.0 * a)))
    }
}

/// The rotation-rotation RPY mobility f I + g r^ r^ at distance r (overlap form below
/// 2a): (1 / (16 pi eta r^3)) (3 r^ r^ - I) apart, and at r = 0 the self-mobility
/// 1 / (8 pi eta a^3).
pub fn rpy_rotation(r: f64, a: f64, eta: f64) -> (f64, f64) {
    let r0 = 1.0 / (8.0 * PI * eta * a * a * a);
    let s = r / a;
    if s >= 2.0 {
        let c = 1.0 / (8.0 * PI * eta * r * r * r);
        (-0.5 * c, 1.5 * c)
    } else {
        (
            r0 * (1.0 - 27.0 * s / 32.0 + 5.0 * s * s * s / 64.0),
            r0 * (9.0 * s / 32.0 - 3.0 * s * s * s / 64.0),
        )
    }
}

/// The translation-rotation coupling c of RPY: the angular velocity of i from a force on
/// j is c f_j x r_ij, the velocity of i from a torque on j c t_j x r_ij (r_ij = x_i - x_j):
/// 1 / (8 pi eta r^3) apart, (1 / (16 pi eta a^3)) (1 - 3 r / 8a) overlapping.
pub fn rpy_coupling(r: f64, a: f64, eta: f64) -> f64 {
    if r >= 2.0 * a {
        1.0 / (8.0 * PI * eta * r * r * r)
    } else {
        (1.0 - 3.0 * r / (8.0 * a)) / (16.0 * PI * eta * a * a * a)
    }
}

/// (j0(x) - j1(x)/x, j2(x)): the isotropic and r^ r^ parts of the angular average of
/// e^(ik.r) (I - k^ k^); series below x = 0.1, where the closed forms cancel.
fn angular(x: f64) -> (f64, f64) {
    if x < 0.1 {
        let x2 = x * x;
        // j0 - j1/x = 2/3 - 2 x^2/15 + x^4/140 - x^6/5670 ...; j2 = x^2/15 - x^4/210 + x^6/7560.
        (
            2.0 / 3.0 - x2 * (2.0 / 15.0 - x2 * (1.0 / 140.0 - x2 / 5670.0)),
            x2 * (1.0 / 15.0 - x2 * (1.0 / 210.0 - x2 / 7560.0)),
        )
    } else {
        let (s, c) = x.sin_cos();
        let j0 = s / x;
        let j1 = s / (x * x) - c / x;
        let j2 = (3.0 / (x * x) - 1.0) * s / x - 3.0 * c / (x * x);
        (j0 - j1 / x, j2)
    }
}

/// Gauss-Legendre nodes and weights of 8 points on [-1, 1].
pub(crate) const GL8: [(f64, f64); 4] = [
    (0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (0.796_666_477_413_626_7, 0.222_381_034_453_374_5),
    (0.960_289_856_497_536_2, 0.101_228_536_290_376_3),
];

/// The far-field kernel of PSE along k: quadrature nodes k_q with weights w_q times
/// sinc^2(k a) H(k, xi) / (2 pi^2 eta), fine enough for distances up to `r_max`.
struct FarQuadrature {
    nodes: Vec<(f64, f64)>,
}

/// The most Gauss-Legendre panels of a [`FarQuadrature`]. Panels grow as xi (r_max + 2a):
/// about 70 at xi a = 0.5 and 4400 at xi a = 64 (the largest split `pse_split` picks);
/// a split of 1e6 would need 3e7 panels (5e8 nodes, minutes per distance), so the host
/// planner refuses it instead of running without end.
pub const MAX_FAR_PANELS: f64 = 16384.0;

/// The most quadrature nodes times table points one [`NearTable`] may cost (2^26, well under
/// a second of f64 on the host; the default 4096 points at xi a = 0.5 cost 4.4e6).
pub const MAX_NEAR_TABLE_WORK: f64 = (1u64 << 26) as f64;

impl FarQuadrature {
    fn new(a: f64, eta: f64, xi: f64, r_max: f64) -> Result<Self, String> {
        // exp(-k^2 / (4 xi^2)) < 1e-19 past k_max.
        let k_max = 2.0 * xi * 44.0f64.sqrt();
        // Panels of at most a quarter of the fastest oscillation (period 2 pi / (r + 2a)).
        let width = (PI / (4.0 * (r_max + 2.0 * a))).min(k_max / 64.0);
        let panels = (k_max / width).ceil();
        // Checked before the conversion: NaN or infinity (a radius of 5e-324, a cutoff
        // of 1e300) must not saturate into a huge allocation.
        if !panels.is_finite() || panels > MAX_FAR_PANELS {
            return Err(format!(
                "the RPY near field at split {}, radius {} and distance {} needs {panels} quadrature panels, more than MAX_FAR_PANELS ({MAX_FAR_PANELS}): lower the split or the cutoff (xi (cutoff + 2 radius) of about 1000 at most)",
                fmt_number(xi),
                fmt_number(a),
                fmt_number(r_max)
            ));
        }
        let panels = panels.max(1.0) as usize;
        let width = k_max / panels as f64;
        let mut nodes = Vec::with_capacity(8 * panels);
        for p in 0..panels {
            let mid = (p as f64 + 0.5) * width;
            for &(x, w) in &GL8 {
                for k in [mid - 0.5 * width * x, mid + 0.5 * width * x] {
                    let ka = k * a;
                    let sinc = if ka < 1e-8 { 1.0 } else { ka.sin() / ka };
                    let q = k * k / (4.0 * xi * xi);
                    let weight = 0.5 * width * w * sinc * sinc * (1.0 + q) * (-q).exp()
                        / (2.0 * PI * PI * eta);
                    nodes.push((k, weight));
                }
            }
        }
        Ok(FarQuadrature { nodes })
    }

    /// (f, g) of M_far,free at distance r.
    fn at(&self, r: f64) -> (f64, f64) {
        let (mut f, mut g) = (0.0, 0.0);
        for &(k, w) in &self.nodes {
            let (i, rr) = angular(k * r);
            f += w * i;
            g += w * rr;
        }
        (f, g)
    }
}

/// The PSE near field of RPY, f(r) and g(r) on `points` equally spaced distances from 0
/// to `cutoff` (inclusive), for radius a, viscosity eta and splitting parameter xi.
#[derive(Clone, Debug, PartialEq)]
pub struct NearTable {
    pub cutoff: f64,
    pub f: Vec<f64>,
    pub g: Vec<f64>,
}

impl NearTable {
    /// An error (naming the limit) where the table would cost more than
    /// [`MAX_NEAR_TABLE_WORK`] or its quadrature more than [`MAX_FAR_PANELS`].
    pub fn new(a: f64, eta: f64, xi: f64, cutoff: f64, points: usize) -> Result<Self, String> {
        let far = FarQuadrature::new(a, eta, xi, cutoff)?;
        let work = far.nodes.len() as f64 * points as f64;
        if work > MAX_NEAR_TABLE_WORK {
            return Err(format!(
                "the RPY near-field table of {points} points at split {xi} and cutoff {cutoff} would cost {work} quadrature evaluations, more than MAX_NEAR_TABLE_WORK ({MAX_NEAR_TABLE_WORK}): fewer table_points or a smaller split"
            ));
        }
        if points < 2 {
            return Err(format!(
                "the RPY near-field table needs 2 points at least, got {points}"
            ));
        }
        let dr = cutoff / (points - 1) as f64;
        let (mut f, mut g) = (Vec::with_capacity(points), Vec::with_capacity(points));
        for i in 0..points {
            let r = i as f64 * dr;
            let (rf, rg) = rpy(r, a, eta);
            let (ff, fg) = far.at(r);
            f.push(rf - ff);
            g.push(rg - fg);
        }
        Ok(NearTable { cutoff, f, g })
    }

    /// [`NearTable::new`], computed once per set of arguments in a process: a graph that
    /// applies the near field twice (PSE's product and its Lanczos body) builds one table.
    pub fn shared(
        a: f64,
        eta: f64,
        xi: f64,
        cutoff: f64,
        points: usize,
    ) -> Result<Arc<NearTable>, String> {
        type Key = ([u64; 4], usize);
        static TABLES: OnceLock<Mutex<HashMap<Key, Arc<NearTable>>>> = OnceLock::new();
        let key = ([a, eta, xi, cutoff].map(f64::to_bits), points);
        let tables = TABLES.get_or_init(Default::default);
        if let Some(t) = tables.lock().unwrap_or_else(|p| p.into_inner()).get(&key) {
            return Ok(t.clone());
        }
        let table = Arc::new(NearTable::new(a, eta, xi, cutoff, points)?);
        tables
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .insert(key, table.clone());
        Ok(table)
    }

    /// Linear interpolation, as the GPU does it (0 past the cutoff).
    pub fn at(&self, r: f64) -> (f64, f64) {
        if r > self.cutoff {
            return (0.0, 0.0);
        }
        let s = r / self.cutoff * (self.f.len() - 1) as f64;
        let i = (s.floor() as usize).min(self.f.len() - 2);
        let t = s - i as f64;
        (
            self.f[i] + t * (self.f[i + 1] - self.f[i]),
            self.g[i] + t * (self.g[i + 1] - self.g[i]),
        )
    }
}

/// The distance past which the PSE near field stays below `fraction` of the Stokes
/// self-mobility 1 / (6 pi eta a) (both f and g), for radius a and splitting parameter
/// xi: the truncation error of a pair left out. The near field decays as
/// exp(-xi^2 (r - 2a)^2) (the two shells of radius a smear the Gaussian screening), so
/// the cutoff is about 2a + sqrt(-ln fraction) / xi at large xi a and
/// sqrt(-ln fraction) / xi at small; found by stepping out in f64 from the contact
/// distance, past the last point above the fraction.
/// Bounded: an error where the quadrature would pass [`MAX_FAR_PANELS`].
pub fn near_cutoff(a: f64, xi: f64, fraction: f64) -> Result<f64, String> {
    let reach = 2.0 * a + (-(fraction / 100.0).ln()).sqrt() / xi;
    let far = FarQuadrature::new(a, 1.0, xi, reach)?;
    let limit = fraction / (6.0 * PI * a);
    let above = |r: f64| {
        let (rf, rg) = rpy(r, a, 1.0);
        let (ff, fg) = far.at(r);
        (rf - ff).abs() > limit || (rg - fg).abs() > limit
    };
    // Inwards from the reach to the first point above, then bisection to 1e-6 of it.
    let steps = 400;
    let dr = reach / steps as f64;
    let Some(i) = (0..=steps).rev().find(|&i| above(i as f64 * dr)) else {
        return Ok(dr);
    };
    let (mut lo, mut hi) = (i as f64 * dr, (i + 1) as f64 * dr);
    while hi - lo > 1e-6 * reach {
        let mid = 0.5 * (lo + hi);
        if above(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Ok(hi)
}

/// The self term of the PSE near field in closed form (Fiore et al. 2017; digest
/// section 4.3), times 6 pi eta a: (1 / (4 sqrt(pi) xi a)) (1 - exp(-4 a^2 xi^2)) +
/// erfc(2 a xi).
pub fn near_self(a: f64, xi: f64) -> f64 {
    (1.0 - (-4.0 * a * a * xi * xi).exp()) / (4.0 * PI.sqrt() * xi * a) + erfc(2.0 * a * xi)
}

/// erfc in f64 to about 1e-15 relative: the Taylor series of erf below 2, the continued
/// fraction of erfc above (where 1 - erf would cancel).
pub fn erfc(x: f64) -> f64 {
    if x < 0.0 {
        return 2.0 - erfc(-x);
    }
    if x < 2.0 {
        // erf by its Taylor series: 2/sqrt(pi) sum (-1)^n x^(2n+1) / (n! (2n+1)).
        let mut term = x;
        let mut sum = x;
        let x2 = x * x;
        let mut n = 0.0;
        while term.abs() > 1e-17 * sum.abs() {
            n += 1.0;
            term *= -x2 / n;
            sum += term / (2.0 * n + 1.0);
        }
        1.0 - 2.0 / PI.sqrt() * sum
    } else {
        // Continued fraction (Lentz): erfc(x) = exp(-x^2)/sqrt(pi) * 1/(x + 1/2/(x + 1/(x + 3/2/(x + ...)))).
        let tiny = 1e-300;
        let mut f = x;
        let mut c = x;
        let mut d = 0.0;
        for i in 1..200 {
            let an = i as f64 / 2.0;
            d = x + an * d;
            d = if d.abs() < tiny { tiny } else { d };
            c = x + an / c;
            c = if c.abs() < tiny { tiny } else { c };
            d = 1.0 / d;
            let delta = c * d;
            f *= delta;
            if (delta - 1.0).abs() < 1e-16 {
                break;
            }
        }
        (-x * x).exp() / PI.sqrt() / f
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erfc_matches_known_values() {
        // Abramowitz and Stegun table values.
        for (x, want) in [
            (0.0, 1.0),
            (0.5, 0.479_500_122_186_953_5),
            (1.0, 0.157_299_207_050_285_1),
            (2.0, 0.004_677_734_981_047_266),
            (3.0, 2.209_049_699_858_544e-5),
            (-1.0, 1.842_700_792_949_715),
        ] {
            assert!(
                ((erfc(x) - want) / want).abs() < 1e-13,
                "erfc({x}) = {}",
                erfc(x)
            );
        }
    }

    /// Splits, cutoffs and table sizes that would make the host quadrature explode
    /// (minutes, or a saturated allocation) are errors naming the limit.
    #[test]
    fn exploding_near_fields_are_refused() {
        let e = near_cutoff(1.0, 1e6, 1e-3).unwrap_err();
        assert!(e.contains("MAX_FAR_PANELS"), "{e}");
        let e = NearTable::new(1.0, 1.0, 0.5, 1e300, 16).unwrap_err();
        assert!(e.contains("MAX_FAR_PANELS"), "{e}");
        let e = NearTable::new(1.0, 1.0, 0.5, 6.0, 1 << 22).unwrap_err();
        assert!(e.contains("MAX_NEAR_TABLE_WORK"), "{e}");
        assert!(NearTable::new(1.0, 1.0, 0.5, 6.0, 4096).is_ok());
    }

    #[test]
    fn rpy_is_continuous_at_contact() {
        let (a, b) = (rpy(2.0 - 1e-12, 1.0, 1.0), rpy(2.0, 1.0, 1.0));
        assert!((a.0 - b.0).abs() < 1e-12 && (a.1 - b.1).abs() < 1e-12);
    }

    #[test]
    fn near_self_term_matches_the_closed_form() {
        for xi in [0.3, 0.5, 1.0, 2.0] {
            let t = NearTable::new(1.0, 1.0, xi, 1.0, 3).unwrap();
            let want = near_self(1.0, xi) / (6.0 * PI);
            assert!(
                ((t.f[0] - want) / want).abs() < 1e-10,
                "xi {xi}: {} against {want}",
                t.f[0]
            );
            assert!(t.g[0].abs() < 1e-14);
        }
    }

    #[test]
    fn near_cutoff_bounds_the_left_out_pairs() {
        // Past the cutoff, the near field stays below the fraction of the self-mobility;
        // just inside it, it does not. Large xi a: well past sqrt(-ln eps) / xi.
        let self_mobility = 1.0 / (6.0 * PI);
        for (xi, eps) in [(0.5, 1e-3), (1.2, 1e-3), (0.8, 1e-4)] {
            let rc = near_cutoff(1.0, xi, eps).unwrap();
            let t = NearTable::new(1.0, 1.0, xi, 2.0 * rc, 401).unwrap();
            for (i, (f, g)) in t.f.iter().zip(&t.g).enumerate() {
                let r = i as f64 * 2.0 * rc / 400.0;
                if r >= rc {
                    assert!(
                        f.abs().max(g.abs()) <= eps * self_mobility,
                        "xi {xi}: r {r}"
                    );
                }
            }
            let inside = NearTable::new(1.0, 1.0, xi, 0.98 * rc, 2).unwrap();
            assert!(inside.f[1].abs().max(inside.g[1].abs()) > 0.5 * eps * self_mobility);
            assert!(rc > (-f64::ln(eps)).sqrt() / xi, "xi {xi}: {rc}");
        }
    }
}
