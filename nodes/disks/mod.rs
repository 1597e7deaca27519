//! Brownian disks in a periodic 2-D box kept apart by a Delaunay triangulation (Carter,
//! Hitschfeld, Navarro and Soto, "GPU parallel simulation algorithm of Brownian particles
//! with excluded volume using Delaunay triangulations", arXiv 1703.02484; the digest
//! `bd-delaunay-and-mpcd-digest.md` part A calls it S1).
//!
//! Positions are N x 2, in a box centred at the origin, [-L/2, L/2) per periodic axis;
//! every difference is taken by the minimum image.
//! - `forces.rs`: `nonreciprocal_forces`, all pairs (S1 eqs. 2-3); the short-range law
//!   through a cell list is `neighbour_sum` with the pair kernel `nonreciprocal`
//!   (nodes/pairs/mod.rs).
//! - `presets.rs`: S1's Table 1 (c0 to c4, `s1_table1`) and `two_species`.
//! - `step.rs`: `brownian_step_2d` (S1 eq. 1 with its noise convention and clipping) and
//!   `abp_move_2d` (S1 eq. 10).
//! - `mesh.rs`: the triangulation of the torus (layout, host construction, checks).
//! - `flip.rs`: the edge-flip predicate and `edge_flip_round`; `overlap.rs`:
//!   `vertex_fans` (each vertex's edges, walked once per mesh) and
//!   `overlap_correction_round`. Their loops are `repeat` nodes (graphs/bd_delaunay.json).
//! - `svg.rs`: a picture of a small system; `clusters.rs`: clusters of touching disks
//!   through the mesh edges (the MIPS measure).

pub mod clusters;
pub mod flip;
pub mod forces;
pub mod mesh;
pub mod overlap;
pub mod pass_through;
pub mod presets;
pub mod step;
pub mod svg;

use crate::expr::ParamValue;
use crate::node::{ParamKind, ParamSpec, Registry};

/// The `box` param of the 2-D disk nodes: two lengths, 0 for an open axis.
pub(crate) fn box_param() -> ParamSpec {
    ParamSpec {
        name: "box",
        kind: ParamKind::Numbers {
            len: Some(2),
            min: 0.0,
            max: 1e18,
        },
        default: Some(ParamValue::Numbers(vec![0.0, 0.0])),
        doc: "box lengths (Lx, Ly) for the minimum image and the wrap into [-L/2, L/2) (0: an open axis)",
    }
}

/// The minimum image of a difference along an axis of length `l` (0: open).
pub fn minimum_image(r: f64, l: f64) -> f64 {
    if l > 0.0 { r - l * (r / l).round() } else { r }
}

/// `x` wrapped into [-l/2, l/2) along an axis of length `l` (0: open, unchanged).
pub fn wrap(x: f64, l: f64) -> f64 {
    if l > 0.0 {
        x - l * ((x + 0.5 * l) / l).floor()
    } else {
        x
    }
}

pub fn register(r: &mut Registry) {
    flip::register(r);
    forces::register(r);
    overlap::register(r);
    pass_through::register(r);
    presets::register(r);
    step::register(r);
}
