//! A picture of a disk system: the disks coloured by species and the triangulation's
//! edges, as SVG text (for small systems: one element per disk and per edge).

use std::fmt::Write;

use super::mesh::MESH_WORDS;
use super::minimum_image;

/// Fill colours by species (cycled).
const COLOURS: [&str; 4] = ["#3b6fb6", "#d1495b", "#66a182", "#edae49"];

/// The disks of diameter `sigma` at `x` (flat N x 2, box centred at the origin) coloured
/// by `species[i]`, and each edge of `mesh` once, drawn from its lower vertex by the
/// minimum image (an edge across a face leaves the box on that side). Pixels per unit
/// length: `scale`.
pub fn disks_svg(
    x: &[f64],
    species: &[u32],
    mesh: &[u32],
    l: [f64; 2],
    sigma: f64,
    scale: f64,
) -> String {
    let (w, h) = (l[0] * scale, l[1] * scale);
    let px = |v: f64, a: usize| {
        if a == 0 {
            (v + 0.5 * l[0]) * scale
        } else {
            (0.5 * l[1] - v) * scale
        }
    };
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w:.0}\" height=\"{h:.0}\" viewBox=\"0 0 {w:.2} {h:.2}\">\n<rect width=\"{w:.2}\" height=\"{h:.2}\" fill=\"white\"/>\n"
    );
    for (i, p) in x.chunks(2).enumerate() {
        let colour = COLOURS[species.get(i).copied().unwrap_or(0) as usize % COLOURS.len()];
        let _ = writeln!(
            s,
            "<circle cx=\"{:.2}\" cy=\"{:.2}\" r=\"{:.2}\" fill=\"{colour}\" fill-opacity=\"0.6\"/>",
            px(p[0], 0),
            px(p[1], 1),
            0.5 * sigma * scale
        );
    }
    for (t, tri) in mesh.chunks(MESH_WORDS).enumerate() {
        for k in 0..3 {
            // Each edge once: by the slot that is the smaller of the pair.
            if (tri[3 + k] as usize) < 3 * t + k {
                continue;
            }
            let (a, b) = (tri[(k + 1) % 3] as usize, tri[(k + 2) % 3] as usize);
            let end =
                [0, 1].map(|d| x[2 * a + d] + minimum_image(x[2 * b + d] - x[2 * a + d], l[d]));
            let _ = writeln!(
                s,
                "<line x1=\"{:.2}\" y1=\"{:.2}\" x2=\"{:.2}\" y2=\"{:.2}\" stroke=\"black\" stroke-width=\"0.6\"/>",
                px(x[2 * a], 0),
                px(x[2 * a + 1], 1),
                px(end[0], 0),
                px(end[1], 1)
            );
        }
    }
    s.push_str("</svg>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nodes::disks::mesh::periodic_delaunay;

    /// One circle per disk, one line per edge (E = 3N), coloured by species.
    #[test]
    fn one_circle_per_disk_and_one_line_per_edge() {
        let l = [8.0, 8.0];
        let x: Vec<f64> = (0..40)
            .flat_map(|i| {
                let (a, b) = ((i % 7) as f64, (i / 7) as f64);
                [a * 1.1 - 3.9 + 0.05 * b, b * 1.3 - 3.7 + 0.07 * a * a]
            })
            .collect();
        let mesh = periodic_delaunay(&x, l).unwrap();
        let species: Vec<u32> = (0..40).map(|i| i % 2).collect();
        let svg = disks_svg(&x, &species, &mesh, l, 1.0, 20.0);
        assert_eq!(svg.matches("<circle").count(), 40);
        assert_eq!(svg.matches("<line").count(), 120);
        assert_eq!(svg.matches(COLOURS[1]).count(), 20);
        assert!(svg.starts_with("<svg") && svg.ends_with("</svg>\n"));
    }
}
