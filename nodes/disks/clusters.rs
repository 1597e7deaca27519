//! Clusters of touching disks found through the mesh's edges (host, f64): the measure of
//! motility-induced phase separation (S1 section 7; Fily and Marchetti 2012).
//!
//! Two disks are in contact when their centres are closer than `contact` (the minimum
//! image); a cluster is a connected set of contacts. Only mesh edges are tested, which
//! finds every contact when no pair overlaps and contact < sqrt(2) sigma: a third centre
//! c inside the circle on the diameter ab would see ab at an angle above 90 degrees, so
//! |ac|^2 + |bc|^2 < |ab|^2 < 2 sigma^2, impossible with |ac|, |bc| >= sigma; that circle
//! is empty and ab is a Delaunay edge. `CONTACT` = 1.02 sigma: at packing 0.7 a passive
//! fluid has most disks within 1.1 sigma of a neighbour (one cluster whatever the
//! dynamics), while pressed active disks sit within a few percent of sigma. O(N) per
//! snapshot: a union-find over the 3N edges.

use super::mesh::MESH_WORDS;
use super::minimum_image;

/// The contact distance of the cluster measure, in units of sigma.
pub const CONTACT: f64 = 1.02;

/// Size of each disk's cluster root and the sizes: the clusters of disks connected by
/// mesh edges shorter than `contact` (minimum image in the box `l`), as the cluster id of
/// each disk (its root) and the size of every cluster, largest first.
pub fn clusters(mesh: &[u32], x: &[f64], l: [f64; 2], contact: f64) -> (Vec<usize>, Vec<usize>) {
    let n = x.len() / 2;
    let mut parent: Vec<usize> = (0..n).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    for t in mesh.chunks_exact(MESH_WORDS) {
        for k in 0..3 {
            let (a, b) = (t[k] as usize, t[(k + 1) % 3] as usize);
            if a >= n || b >= n {
                continue;
            }
            let r = [0, 1].map(|d| minimum_image(x[2 * a + d] - x[2 * b + d], l[d]));
            if r[0].hypot(r[1]) < contact {
                let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
                if ra != rb {
                    parent[ra.max(rb)] = ra.min(rb);
                }
            }
        }
    }
    let roots: Vec<usize> = (0..n).map(|i| root(&mut parent, i)).collect();
    let mut size = vec![0usize; n];
    for &r in &roots {
        size[r] += 1;
    }
    let mut sizes: Vec<usize> = size.into_iter().filter(|&s| s > 0).collect();
    sizes.sort_unstable_by(|a, b| b.cmp(a));
    (roots, sizes)
}

/// The fraction of the disks in the largest cluster (contact `CONTACT` x sigma).
pub fn largest_cluster_fraction(mesh: &[u32], x: &[f64], l: [f64; 2], sigma: f64) -> f64 {
    let n = x.len() / 2;
    let (_, sizes) = clusters(mesh, x, l, CONTACT * sigma);
    sizes.first().copied().unwrap_or(0) as f64 / n.max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::super::mesh::periodic_delaunay;
    use super::*;

    /// Against the all-pairs f64 clustering of the same points: a row of touching disks
    /// is one cluster, scattered ones are alone.
    #[test]
    fn mesh_clusters_match_all_pairs_clusters() {
        let l = [12.0, 12.0];
        let mut x = Vec::new();
        // A chain of 6 disks 1.01 apart, and 26 disks 2 apart from each other and far
        // from it (jittered: no four cocircular).
        for i in 0..6 {
            x.extend([-5.0 + 1.01 * i as f64, 0.013 * i as f64]);
        }
        for (j, y) in [-5.0, -3.0, 3.0, 5.0].into_iter().enumerate() {
            for i in 0..6 {
                x.extend([
                    -5.0 + 2.0 * i as f64 + 0.01 * j as f64,
                    y + 0.017 * i as f64,
                ]);
            }
        }
        x.extend([2.5, 0.3, 4.5, -0.2]);
        let mesh = periodic_delaunay(&x, l).unwrap();
        let (roots, sizes) = clusters(&mesh, &x, l, CONTACT);
        // All pairs in f64: contacts join the same cluster, and the mesh's clusters are
        // no larger than what all pairs connect (same count of clusters).
        let n = x.len() / 2;
        let mut label: Vec<usize> = (0..n).collect();
        for _ in 0..n {
            for i in 0..n {
                for j in 0..n {
                    let r = [0, 1].map(|d| minimum_image(x[2 * i + d] - x[2 * j + d], l[d]));
                    if r[0].hypot(r[1]) < CONTACT {
                        let m = label[i].min(label[j]);
                        label[i] = m;
                        label[j] = m;
                    }
                }
            }
        }
        for i in 0..n {
            for j in 0..n {
                assert_eq!(
                    label[i] == label[j],
                    roots[i] == roots[j],
                    "disks {i} and {j}"
                );
            }
        }
        assert_eq!(sizes[0], 6);
        assert!(sizes[1..].iter().all(|&s| s == 1), "{sizes:?}");
        assert!((largest_cluster_fraction(&mesh, &x, l, 1.0) - 6.0 / 32.0).abs() < 1e-12);
    }
}
