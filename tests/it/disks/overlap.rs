//! `vertex_fans` against its exact twin, `overlap_correction_round` against its f64 twin,
//! and rounds repeated until no pair overlaps: no step above sigma / 4, no overlapping
//! pair left (all pairs checked).

use mesoflow::nodes::disks::mesh::periodic_delaunay;
use mesoflow::nodes::disks::minimum_image;
use mesoflow::value::HostArray;

use crate::util::disks::disk_positions;
use crate::util::{Rng, flat_particles, gpu, indices, run_node_and_reference, u32s};

const L: [f64; 2] = [24.0, 22.0];

/// Overlapping pairs among all pairs (minimum image), and the smallest distance.
fn all_pair_overlaps(x: &[f64], sigma: f64) -> (usize, f64) {
    let n = x.len() / 2;
    let mut count = 0;
    let mut closest = f64::INFINITY;
    for i in 0..n {
        for j in i + 1..n {
            let r = [0, 1].map(|a| minimum_image(x[2 * j + a] - x[2 * i + a], L[a]));
            let d = r[0].hypot(r[1]);
            closest = closest.min(d);
            count += (d < sigma) as usize;
        }
    }
    (count, closest)
}

/// The fan tables of a mesh on the GPU, each equal to its exact twin word for word, at
/// the default width and at width 3 (most vertices of the mesh have more edges: their
/// rounds finish the fan from the mesh).
fn fan_tables(mesh: &HostArray, widths: &[u32]) -> Vec<HostArray> {
    widths
        .iter()
        .map(|w| {
            let (out, refs) = run_node_and_reference(
                "vertex_fans",
                &format!(r#"{{"width": {w}}}"#),
                &[("mesh", mesh.clone())],
            );
            let want: Vec<u32> = refs[0].data.iter().map(|&v| v as u32).collect();
            assert_eq!(u32s(&out["fans"]), want, "width {w}");
            out["fans"].clone()
        })
        .collect()
}

/// 300 disks of diameter 1 placed at least 0.72 apart (packing 0.45): every pair closer
/// than 1 is a Delaunay edge (0.72 > 1 / sqrt(2): no third point fits in its diametral
/// circle), so the first round's count is the all-pairs count. Rounds on the GPU, each
/// within f32 round-off of the f64 round (and bit for bit the same with the fan table 3
/// wide, the rest of each fan walked on the mesh), until one counts no overlap: every
/// step at most sigma / 4, and no pair of all closer than sigma (up to f32 round-off).
#[test]
fn overlap_rounds_remove_every_overlap() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(29);
    let x0 = disk_positions(&mut rng, 300, L, 0.72);
    let mesh = indices(&periodic_delaunay(&x0, L).unwrap());
    let fans = fan_tables(&mesh, &[10, 3]);
    let mut x: Vec<f64> = x0.iter().map(|&v| v as f32 as f64).collect();
    let (initial, _) = all_pair_overlaps(&x, 1.0);
    assert!(initial > 30, "{initial} overlapping pairs");
    let params = r#"{"sigma": 1, "box": [24, 22]}"#;
    let mut counts = Vec::new();
    loop {
        let round = |fans: &HostArray| {
            run_node_and_reference(
                "overlap_correction_round",
                params,
                &[
                    ("positions", flat_particles(&x, 2)),
                    ("mesh", mesh.clone()),
                    ("fans", fans.clone()),
                ],
            )
        };
        let (out, refs) = round(&fans[0]);
        let (narrow, _) = round(&fans[1]);
        let y = out["positions"].data.to_f64();
        // Both count words: the overlapping pairs, then the disks in at least one.
        let words = u32s(&out["overlaps"]);
        assert_eq!(narrow["positions"].data.to_f64(), y, "the narrow table");
        assert_eq!(u32s(&narrow["overlaps"]), words, "the narrow table");
        assert_eq!(
            words.iter().map(|&w| w as f64).collect::<Vec<_>>(),
            refs[1].data,
            "round {}: overlapping pairs and disks",
            counts.len()
        );
        let [count, disks] = words[..] else {
            panic!("the count holds two words, got {words:?}")
        };
        // Two disks per pair at most, and at least two where any pair overlaps.
        assert!(
            (count == 0 && disks == 0) || (2..=2 * count).contains(&disks),
            "{disks} disks in {count} overlapping pairs"
        );
        let mut worst = 0.0f64;
        let mut largest_step = 0.0f64;
        for i in 0..y.len() {
            worst = worst.max(minimum_image(y[i] - refs[0].data[i], L[i % 2]).abs());
        }
        for i in 0..y.len() / 2 {
            let d = [0, 1].map(|a| minimum_image(y[2 * i + a] - x[2 * i + a], L[a]));
            largest_step = largest_step.max(d[0].hypot(d[1]));
        }
        // Positions of magnitude 12 in f32: ulp 1e-6; sums of a few terms.
        assert!(worst < 1e-5, "round {}: error {worst:e}", counts.len());
        assert!(
            largest_step <= 0.25 * (1.0 + 1e-5),
            "round {}: step {largest_step}",
            counts.len()
        );
        if counts.is_empty() {
            assert_eq!(
                count as usize, initial,
                "the first round sees every overlap"
            );
        }
        counts.push(count);
        if count == 0 {
            assert_eq!(largest_step, 0.0, "a round without overlaps moves nothing");
            break;
        }
        assert!(
            counts.len() < 100,
            "no convergence: overlaps per round {counts:?}"
        );
        x = y;
    }
    let (left, closest) = all_pair_overlaps(&x, 1.0 - 1e-5);
    assert_eq!(
        left, 0,
        "closest pair {closest}; overlaps per round {counts:?}"
    );
    eprintln!("overlaps per round {counts:?}, closest pair {closest}");
}
