//! Helpers of the 2-D disk tests (`disks/`): disk packings with a minimum separation.

use super::Rng;

/// `n` points in the periodic box `l` (centred at the origin) no two closer than
/// `min_dist` by the minimum image, by random sequential addition (panics when the box is
/// too full to place them in 1000 tries each).
pub fn disk_positions(rng: &mut Rng, n: usize, l: [f64; 2], min_dist: f64) -> Vec<f64> {
    let mut x: Vec<f64> = Vec::with_capacity(2 * n);
    for _ in 0..n {
        let mut placed = false;
        for _ in 0..1000 {
            let p = [
                rng.uniform(-0.5 * l[0], 0.5 * l[0]),
                rng.uniform(-0.5 * l[1], 0.5 * l[1]),
            ];
            let clear = x.chunks(2).all(|q| {
                let d: Vec<f64> = (0..2)
                    .map(|a| mesoflow::nodes::disks::minimum_image(p[a] - q[a], l[a]))
                    .collect();
                d[0] * d[0] + d[1] * d[1] >= min_dist * min_dist
            });
            if clear {
                x.extend(p);
                placed = true;
                break;
            }
        }
        assert!(placed, "no room for {n} disks of {min_dist} in {l:?}");
    }
    x
}
