//! The Rotne-Prager-Blake grand mobility of spheres above a no-slip wall, in f64: open RPY
//! (forces and torques, overlap forms below contact) plus the wall's corrections, Swan and
//! Brady, Phys. Fluids 19, 113306 (2007), with the cross products taken right-handed (the
//! paper's left-handed Levi-Civita flips their signs), and the damping of Usabiaga et al.
//! (J. Chem. Phys. 2017, appendix 1) that keeps the mobility positive definite when a
//! particle overlaps the wall: a pair's block is scaled by b_i b_j, b = min(h / a, 1), and
//! heights below a are taken as a. The wall is the plane z = `wall`; heights are z - wall.
//! libMobility's NBody solver (bottom wall) computes the same.
//!
//! The corrections are written in units of the radius: lengths over a, and the
//! translation, coupling and rotation blocks over 6 pi eta a, 8 pi eta a^2 and
//! 8 pi eta a^3.

use std::f64::consts::PI;

use super::rpy::{rpy, rpy_coupling, rpy_rotation};

type V3 = [f64; 3];
type M3 = [[f64; 3]; 3];

fn apply(m: &M3, v: V3) -> V3 {
    [0, 1, 2].map(|r| m[r][0] * v[0] + m[r][1] * v[1] + m[r][2] * v[2])
}

fn transpose(m: &M3) -> M3 {
    [0, 1, 2].map(|r| [0, 1, 2].map(|c| m[c][r]))
}

fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// The wall's correction to the translation block (units of 6 pi eta a): for a pair, at
/// R = x_i - image of x_j (R_z = z_i + z_j), h = h_j; for a particle itself, at height h.
fn uf(rv: Option<V3>, h: f64) -> M3 {
    let Some(r) = rv else {
        let (i1, i3, i5) = (1.0 / h, h.powi(-3), h.powi(-5));
        let par = -(9.0 * i1 - 2.0 * i3 + i5) / 16.0;
        let perp = -(9.0 * i1 - 4.0 * i3 + i5) / 8.0;
        return [[par, 0.0, 0.0], [0.0, par, 0.0], [0.0, 0.0, perp]];
    };
    let d = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
    let e = r.map(|x| x / d);
    let hh = h / r[2];
    let (i1, i3, i5) = (1.0 / d, d.powi(-3), d.powi(-5));
    let ez2 = e[2] * e[2];
    let f1 = -(3.0 * (1.0 + 2.0 * hh * (1.0 - hh) * ez2) * i1 + 2.0 * (1.0 - 3.0 * ez2) * i3
        - 2.0 * (1.0 - 5.0 * ez2) * i5)
        / 4.0;
    let f2 = -(3.0 * (1.0 - 6.0 * hh * (1.0 - hh) * ez2) * i1 - 6.0 * (1.0 - 5.0 * ez2) * i3
        + 10.0 * (1.0 - 7.0 * ez2) * i5)
        / 4.0;
    let f3 = e[2]
        * (3.0 * hh * (1.0 - 6.0 * (1.0 - hh) * ez2) * i1 - 6.0 * (1.0 - 5.0 * ez2) * i3
            + 10.0 * (2.0 - 7.0 * ez2) * i5)
        / 2.0;
    let f4 = e[2] * (3.0 * hh * i1 - 10.0 * i5) / 2.0;
    let f5 = -(3.0 * hh * hh * ez2 * i1 + 3.0 * ez2 * i3 + (2.0 - 15.0 * ez2) * i5);
    let mut m = [[0.0; 3]; 3];
    for a in 0..3 {
        for b in 0..3 {
            m[a][b] = f2 * e[a] * e[b];
        }
        m[a][a] += f1;
    }
    for a in 0..2 {
        m[a][2] += f3 * e[a];
        m[2][a] += f4 * e[a];
    }
    m[2][2] += f3 * e[2] + f4 * e[2] + f5;
    m
}

/// The wall's correction to the rotation block (units of 8 pi eta a^3).
fn wt(rv: Option<V3>, h: f64) -> M3 {
    let Some(r) = rv else {
        let i3 = h.powi(-3);
        return [
            [-5.0 * i3 / 16.0, 0.0, 0.0],
            [0.0, -5.0 * i3 / 16.0, 0.0],
            [0.0, 0.0, -i3 / 8.0],
        ];
    };
    let d = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
    let e = r.map(|x| x / d);
    let i3 = d.powi(-3);
    let f1 = (1.0 - 6.0 * e[2] * e[2]) * i3 / 2.0;
    let f2 = -1.5 * i3;
    let f3 = 3.0 * i3 * e[2];
    let f4 = 3.0 * i3;
    [
        [
            f1 + f2 * e[0] * e[0] + f4 * e[1] * e[1],
            (f2 - f4) * e[0] * e[1],
            f2 * e[0] * e[2],
        ],
        [
            (f2 - f4) * e[0] * e[1],
            f1 + f2 * e[1] * e[1] + f4 * e[0] * e[0],
            f2 * e[1] * e[2],
        ],
        [
            f2 * e[2] * e[0] + f3 * e[0],
            f2 * e[2] * e[1] + f3 * e[1],
            f1 + f2 * e[2] * e[2] + f3 * e[2],
        ],
    ]
}

/// The wall's correction to the rotation-from-force block (units of 8 pi eta a^2), for
/// R = x_i - image of x_j and h = h_j; its transpose at R = x_j - image of x_i, h = h_i,
/// is the translation-from-torque block of the pair (i, j).
fn wf(rv: Option<V3>, h: f64) -> M3 {
    let Some(r) = rv else {
        let i4 = h.powi(-4);
        return [[0.0, -i4 / 8.0, 0.0], [i4 / 8.0, 0.0, 0.0], [0.0, 0.0, 0.0]];
    };
    let d = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
    let e = r.map(|x| x / d);
    let hh = h / r[2];
    let (i2, i4) = (d.powi(-2), d.powi(-4));
    let ez2 = e[2] * e[2];
    let f1 = i2;
    let f2 = 2.0 * (6.0 * hh * ez2 * i2 + (1.0 - 10.0 * ez2) * i4);
    let f3 = -2.0 * e[2] * (3.0 * hh * i2 - 5.0 * i4);
    let f4 = -2.0 * e[2] * (hh * i2 - i4);
    // Subtracted in Swan and Brady's (left-handed) form: the signs here are the flip.
    [
        [
            f3 * e[0] * e[1],
            -(f1 * e[2] - f3 * e[1] * e[1] + f4),
            f1 * e[1] + f2 * e[1] + f3 * e[1] * e[2],
        ],
        [
            f1 * e[2] - f3 * e[0] * e[0] + f4,
            -f3 * e[0] * e[1],
            -(f1 * e[0] + f2 * e[0] + f3 * e[0] * e[2]),
        ],
        [-f1 * e[1], f1 * e[0], 0.0],
    ]
}

/// The damping factor of a particle at height h (radius a): min(h / a, 1), at least 0.
pub fn damping(h: f64, a: f64) -> f64 {
    (h / a).clamp(0.0, 1.0)
}

/// The velocity and angular velocity of sphere i (at xi) from the force fj and torque tj
/// on sphere j (at xj), or from its own (`same`: i is j), above the wall z = `wall`.
#[allow(clippy::too_many_arguments)]
pub fn blake(xi: V3, xj: V3, fj: V3, tj: V3, a: f64, eta: f64, wall: f64, same: bool) -> (V3, V3) {
    let bij = damping(xi[2] - wall, a) * damping(xj[2] - wall, a);
    let hi = (xi[2] - wall).max(a);
    let hj = (xj[2] - wall).max(a);
    let t0 = 1.0 / (6.0 * PI * eta * a);
    let rt0 = 1.0 / (8.0 * PI * eta * a * a);
    let r0 = 1.0 / (8.0 * PI * eta * a * a * a);
    let (mut u, mut w) = ([0.0; 3], [0.0; 3]);
    let add = |acc: &mut V3, v: V3, s: f64| {
        for c in 0..3 {
            acc[c] += s * v[c];
        }
    };
    if same {
        add(&mut u, fj, t0);
        add(&mut w, tj, r0);
        add(&mut u, apply(&uf(None, hj / a), fj), t0);
        add(&mut w, apply(&wt(None, hj / a), tj), r0);
        add(&mut w, apply(&wf(None, hj / a), fj), rt0);
        add(&mut u, apply(&transpose(&wf(None, hi / a)), tj), rt0);
    } else {
        // In-plane separation as given, heights clamped.
        let r = [xi[0] - xj[0], xi[1] - xj[1], hi - hj];
        let d = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
        let (f, g) = rpy(d, a, eta);
        let rf = if d > 0.0 {
            (r[0] * fj[0] + r[1] * fj[1] + r[2] * fj[2]) / (d * d)
        } else {
            0.0
        };
        add(&mut u, fj, f);
        add(&mut u, r, g * rf);
        let (fr, gr) = rpy_rotation(d, a, eta);
        let rt = if d > 0.0 {
            (r[0] * tj[0] + r[1] * tj[1] + r[2] * tj[2]) / (d * d)
        } else {
            0.0
        };
        add(&mut w, tj, fr);
        add(&mut w, r, gr * rt);
        let c = rpy_coupling(d, a, eta);
        add(&mut u, cross(tj, r), c);
        add(&mut w, cross(fj, r), c);
        // The image of j seen from i, and of i seen from j (the coupling's transpose).
        let rim = [r[0] / a, r[1] / a, (hi + hj) / a];
        let rim_ji = [-r[0] / a, -r[1] / a, (hj + hi) / a];
        add(&mut u, apply(&uf(Some(rim), hj / a), fj), t0);
        add(&mut w, apply(&wt(Some(rim), hj / a), tj), r0);
        add(&mut w, apply(&wf(Some(rim), hj / a), fj), rt0);
        add(
            &mut u,
            apply(&transpose(&wf(Some(rim_ji), hi / a)), tj),
            rt0,
        );
    }
    (u.map(|x| bij * x), w.map(|x| bij * x))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two coincident spheres see each other through the wall as one sees itself: every
    /// pair correction at R = (0, 0, 2h) is the self correction.
    #[test]
    fn pair_corrections_at_coincidence_are_the_self_ones() {
        for h in [1.0, 1.7, 5.0] {
            let r = Some([0.0, 0.0, 2.0 * h]);
            for (name, pair, own) in [
                ("uf", uf(r, h), uf(None, h)),
                ("wt", wt(r, h), wt(None, h)),
                ("wf", wf(r, h), wf(None, h)),
            ] {
                for a in 0..3 {
                    for b in 0..3 {
                        assert!(
                            (pair[a][b] - own[a][b]).abs() < 1e-12,
                            "{name} h {h} [{a}][{b}]: {} vs {}",
                            pair[a][b],
                            own[a][b]
                        );
                    }
                }
            }
        }
    }

    /// The self mobilities reach the closed forms the digest quotes (section 7.7):
    /// parallel 1 - 9/16 (a/h) + 1/8 (a/h)^3 - 1/16 (a/h)^5 and perpendicular
    /// 1 - 9/8 (a/h) + 1/2 (a/h)^3 - 1/8 (a/h)^5, over 6 pi eta a.
    #[test]
    fn self_mobilities_are_the_closed_forms() {
        let (a, eta) = (1.3, 0.7);
        let t0 = 1.0 / (6.0 * PI * eta * a);
        for h in [1.0, 1.5, 2.0, 4.0, 10.0] {
            let x = [0.3, -0.2, h * a + 2.0];
            let s = 1.0 / h;
            let (u, _) = blake(x, x, [1.0, 0.0, 0.0], [0.0; 3], a, eta, 2.0, true);
            let par = 1.0 - 9.0 / 16.0 * s + s.powi(3) / 8.0 - s.powi(5) / 16.0;
            assert!(
                (u[0] / t0 - par).abs() < 1e-13,
                "h {h}: {} vs {par}",
                u[0] / t0
            );
            let (u, _) = blake(x, x, [0.0, 0.0, 1.0], [0.0; 3], a, eta, 2.0, true);
            let perp = 1.0 - 9.0 / 8.0 * s + s.powi(3) / 2.0 - s.powi(5) / 8.0;
            assert!(
                (u[2] / t0 - perp).abs() < 1e-13,
                "h {h}: {} vs {perp}",
                u[2] / t0
            );
        }
    }
}
