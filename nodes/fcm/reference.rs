//! The periodic FCM mobility of Gaussian blobs in f64, by a direct Fourier sum, for
//! `mesoflow bench fcm`'s error column (the tests keep an independent copy of their own):
//!   M(r) = (1/V) sum_{k != 0} cos(k.r) (I - k k^T / k^2) / (eta k^2) exp(-sigma^2 k^2),
//! r = x_i - x_j, over the wave vectors of the box, cut where the Gaussian is below 1e-15.

use std::f64::consts::PI;

/// The 3x3 translational mobility between two Gaussian blobs of standard deviation
/// `sigma` separated by `r` in a periodic box of lengths `l`.
pub fn periodic_gaussian_mobility(r: [f64; 3], l: [f64; 3], eta: f64, sigma: f64) -> [[f64; 3]; 3] {
    let kcut = 5.9 / sigma;
    let nmax = l.map(|la| (kcut * la / (2.0 * PI)).ceil() as i64);
    let mut m = [[0.0; 3]; 3];
    for nx in -nmax[0]..=nmax[0] {
        let kx = 2.0 * PI * nx as f64 / l[0];
        for ny in -nmax[1]..=nmax[1] {
            let ky = 2.0 * PI * ny as f64 / l[1];
            for nz in -nmax[2]..=nmax[2] {
                if nx == 0 && ny == 0 && nz == 0 {
                    continue;
                }
                let kz = 2.0 * PI * nz as f64 / l[2];
                let k = [kx, ky, kz];
                let k2 = kx * kx + ky * ky + kz * kz;
                if k2 > kcut * kcut {
                    continue;
                }
                let w = (k[0] * r[0] + k[1] * r[1] + k[2] * r[2]).cos()
                    * (-sigma * sigma * k2).exp()
                    / (eta * k2);
                for i in 0..3 {
                    for j in 0..3 {
                        let d = if i == j { 1.0 } else { 0.0 };
                        m[i][j] += w * (d - k[i] * k[j] / k2);
                    }
                }
            }
        }
    }
    let v = l[0] * l[1] * l[2];
    m.map(|row| row.map(|x| x / v))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Far from its images a blob has the free Gaussian-FCM self-mobility 1 / (6 pi eta a)
    /// less Hasimoto's leading periodic term.
    #[test]
    fn self_mobility_of_a_blob() {
        let a = 1.0;
        let m = periodic_gaussian_mobility([0.0; 3], [24.0; 3], 1.0, a / PI.sqrt());
        let want = crate::nodes::fcm::plan::hasimoto(a, 24.0) / (6.0 * PI * a);
        assert!((m[0][0] / want - 1.0).abs() < 3e-5, "{} vs {want}", m[0][0]);
        assert!(m[0][1].abs() < 1e-12);
    }
}
