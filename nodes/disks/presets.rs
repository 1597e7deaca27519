//! S1's Table 1 (Carter et al. 2017): the five two-species configurations c0 to c4 as
//! graph-level presets, and `two_species`, the node that draws each disk's species.
//!
//! The table comes from the digest's reconstruction (`bd-delaunay-and-mpcd-digest.md`
//! part D): the fractions and packing fractions are read directly; the multiset of
//! (alpha, mu) values is certain, their order inside c2 to c4 is the digest's best reading
//! of the behaviours (like repel / unlike attract for c2 and c4, like attract / unlike
//! repel for c3). A graph reads a row through the host function `s1_table1(config)`
//! (graphs/bd_delaunay.json's `config` param); each value stays a param of its own, so a
//! user may override any of them (`--set species2=[-2,-1]`).

use super::super::pointwise::{BASE, ElemCtx, Param, PointwiseKind, pointwise_kind};
use super::super::random::{seed_param, stream_param, uniform};
use crate::expr::{HostFunction, ParamValue};
use crate::node::{ParamKind, ParamSpec, Params, Registry};
use crate::value::ValueType;

/// One row of Table 1: name, fraction of species 1, (alpha, mu) of species 1 and of
/// species 2, packing fraction.
pub type Configuration = (&'static str, f64, [f64; 2], [f64; 2], f64);

/// S1 Table 1 as the digest reconstructs it.
pub const TABLE1: [Configuration; 5] = [
    // Asymmetric 1 -> 2 attraction: a homogeneous fluid-like mixture.
    ("c0", 0.7, [1.0, 1.0], [-1.0, 1.0], 0.79),
    // Species 2 self-attracts (a dense cluster), species 1 self-repels (a gas).
    ("c1", 0.5, [1.0, 1.0], [-1.0, 1.0], 0.52),
    // Like repel, unlike attract: alternating chains.
    ("c2", 0.5, [1.0, 1.0], [-1.0, -2.0], 0.52),
    // Like attract, unlike repel: dense segregated clusters.
    ("c3", 0.5, [1.0, -1.0], [-2.0, 1.0], 0.79),
    // As c2, dilute: small clusters.
    ("c4", 0.5, [1.0, 1.0], [-1.0, -4.0], 0.0873),
];

/// The names a `config` param takes: `custom` (the charges given as an input) and c0..c4.
pub const CONFIGS: [&str; 6] = ["custom", "c0", "c1", "c2", "c3", "c4"];

/// A configuration by name.
pub fn configuration(name: &str) -> Option<Configuration> {
    TABLE1.iter().find(|c| c.0 == name).copied()
}

/// `s1_table1(config)`: [fraction of species 1, alpha1, mu1, alpha2, mu2, packing
/// fraction]; `custom`: one species, alpha = mu = 1, packing 0.79 (the defaults a user
/// overrides).
fn s1_table1(args: &[ParamValue]) -> Result<ParamValue, String> {
    let [ParamValue::Text(name)] = args else {
        return Err(
            "takes one argument, the configuration's name ('c0' to 'c4' or 'custom')".into(),
        );
    };
    let (fraction, a, b, density) = match configuration(name) {
        Some((_, f, a, b, d)) => (f, a, b, d),
        None if name == "custom" => (1.0, [1.0, 1.0], [1.0, 1.0], 0.79),
        None => {
            return Err(format!(
                "no configuration `{name}`: S1's Table 1 has c0 to c4 (or custom)"
            ));
        }
    };
    Ok(ParamValue::Numbers(vec![
        fraction, a[0], a[1], b[0], b[1], density,
    ]))
}

fn pair_param(name: &'static str, doc: &'static str) -> ParamSpec {
    ParamSpec {
        name,
        kind: ParamKind::Numbers {
            len: Some(2),
            min: -1e6,
            max: 1e6,
        },
        default: None,
        doc,
    }
}

fn two_columns(t: &ValueType, _: &[f64]) -> Result<(), String> {
    match t {
        ValueType::Particles { k: 2, .. } => Ok(()),
        other => Err(format!(
            "expected one (alpha, mu) row per disk (N x 2), got {other}"
        )),
    }
}

/// The species of disk i: 1 (`true`) when its uniform draw (seed, stream, step 0, i) is
/// below `fraction`.
pub fn first_species(i: u64, seed: u64, stream: u32, fraction: f64) -> bool {
    uniform(i, 0, seed, stream) < fraction
}

pub static KINDS: &[PointwiseKind] = &[PointwiseKind {
    name: "two_species",
    doc: "(alpha, mu) per disk for two species (S1 Table 1): disk i is of species 1 when its uniform draw (seed, stream, step 0, element i) is below `fraction`, else of species 2; the same every step",
    inputs: &[(
        "like",
        "N x 2 template (the positions; values not read): one row per disk",
        false,
    )],
    params: || {
        vec![
            seed_param(),
            stream_param(),
            ParamSpec::number(
                "fraction",
                None,
                0.0,
                1.0,
                "fraction of species 1 (the expected share; each disk draws)",
            ),
            pair_param("species1", "(alpha, mu) of species 1"),
            pair_param("species2", "(alpha, mu) of species 2"),
        ]
    },
    flatten: |p: &Params| {
        let seed = p.number("seed") as u64;
        let (a, b) = (p.numbers("species1"), p.numbers("species2"));
        vec![
            Param::Bits(seed as u32),
            Param::Bits((seed >> 32) as u32),
            Param::Bits(p.number("stream") as u32),
            Param::Number(p.number("fraction")),
            Param::Number(a[0]),
            Param::Number(a[1]),
            Param::Number(b[0]),
            Param::Number(b[1]),
        ]
    },
    check: two_columns,
    body:
        "let u = philox_uniform(idx / 2u, 0u, bitcast<u32>(p0), bitcast<u32>(p1), bitcast<u32>(p2));
    let first = select(p5, p4, comp == 0u);
    let second = select(p7, p6, comp == 0u);
    return select(second, first, u < p3);",
    imports: &["common/philox.wgsl"],
    reference: |_, e: ElemCtx, p| {
        let seed = (p[1] as u64) << 32 | p[0] as u64;
        let first = first_species(e.idx / 2, seed, p[2] as u32, p[3]);
        match (first, e.comp) {
            (true, 0) => p[4],
            (true, _) => p[5],
            (false, 0) => p[6],
            (false, _) => p[7],
        }
    },
    ..BASE
}];

pub fn register(r: &mut Registry) {
    for row in KINDS {
        r.add(pointwise_kind(row));
    }
    r.add_function(HostFunction {
        name: "s1_table1",
        doc: "s1_table1(config): S1's Table 1 row ('c0' to 'c4'; 'custom': one species alpha = mu = 1 at packing 0.79) as [fraction of species 1, alpha1, mu1, alpha2, mu2, packing fraction] (nodes/disks/presets.rs)",
        call: s1_table1,
    });
}

/// The sites of the widest triangular lattice of at least `n` sites that tiles the square
/// periodic box of side `l`: `ny` rows (an even number, so that the shifted rows close
/// over the boundary) of `nx = ceil(n / ny)` sites, the row count chosen to make the
/// nearest-neighbour distance (the smallest of the row spacing `l / nx`, the distance
/// to the next row and twice the row height) as large as possible. Returns the sites
/// (row by row, in [-l/2, l/2)) and that distance.
///
/// The lattice is as uniform as the box allows: at packing 0.79 its spacing is about
/// 1.07 sigma with at most a row's worth of empty sites. (A lattice of spacing
/// `l / floor(l / sigma)` with the surplus sites left empty at random, what the disks
/// started from before, packs the occupied regions almost as densely as close packing
/// for large N, spacing 1.005 sigma at N = 16384: the first move's overlaps then spread
/// through the jammed regions, the overlap correction ran for ~100 rounds moving disks
/// by more than a diameter on a fixed mesh, left the mesh folded with disks 0.08 sigma
/// apart, and the next step counted pass-throughs.)
pub fn triangular_lattice(n: usize, l: f64) -> (Vec<[f64; 2]>, f64) {
    let mut best = (0, 0, 0.0f64);
    let max_rows = (2.0 * n as f64).sqrt().ceil() as usize + 2;
    for ny in (2..=2 * max_rows).step_by(2) {
        let nx = n.div_ceil(ny).max(1);
        let (ax, ay) = (l / nx as f64, l / ny as f64);
        let d = ax.min((0.5 * ax).hypot(ay)).min(2.0 * ay);
        if d > best.2 {
            best = (nx, ny, d);
        }
    }
    let (nx, ny, d) = best;
    let (ax, ay) = (l / nx as f64, l / ny as f64);
    let sites = (0..ny)
        .flat_map(|j| {
            (0..nx).map(move |i| {
                let shift = if j % 2 == 1 { 0.5 * ax } else { 0.0 };
                [i as f64 * ax + shift - 0.5 * l, j as f64 * ay - 0.5 * l]
            })
        })
        .collect();
    (sites, d)
}

/// The jitter of `lattice_disks`, per coordinate uniform in [-J/2, J/2] with
/// J = `JITTER` (d - sigma) for lattice spacing d: a pair comes closer by at most
/// sqrt(2) J < d - sigma, and a jitter that is a sizeable part of the gap keeps the
/// quads around the empty sites (cocircular on a perfect lattice) well away from
/// cocircular at f32 resolution, so the GPU's flip predicate and the host's
/// triangulation agree.
pub const JITTER: f64 = 0.5;

/// `n` disks of diameter `sigma` at packing `density` in a square periodic box centred
/// at the origin, as the example and `bench disks` start them: the widest triangular
/// lattice of at least `n` sites in the box (`triangular_lattice`; spacing d, about
/// 1.07 sigma at packing 0.79), `n` of its sites drawn at random, each jittered by up to
/// `JITTER` (d - sigma) / 2 per coordinate (no four points near a circle, so the periodic
/// Delaunay triangulation is unique and robust in f32; no two disks closer than sigma),
/// and the species of each (`true`: species 1, with probability `fraction`). Returns the
/// positions, the species and the box side; an error when the lattice is closer than
/// sigma (packing above close packing, or too few disks for a lattice).
pub fn lattice_disks(
    n: usize,
    density: f64,
    sigma: f64,
    fraction: f64,
    seed: u64,
) -> Result<(Vec<f64>, Vec<bool>, f64), String> {
    lattice_disks_in(n, density, sigma, fraction, seed, false)
}

/// `lattice_disks` with the disks numbered in the lattice's row order (`in_order`), the
/// same sites, jitter draws and species otherwise: particles near in number are near in
/// space, so the long-range force's tiles are compact (its one-image path) and the mesh's
/// neighbours sit close in memory. With `in_order` false it is `lattice_disks`.
pub fn lattice_disks_in(
    n: usize,
    density: f64,
    sigma: f64,
    fraction: f64,
    seed: u64,
    in_order: bool,
) -> Result<(Vec<f64>, Vec<bool>, f64), String> {
    let l = (n as f64 * std::f64::consts::PI * 0.25 * sigma * sigma / density).sqrt();
    let mut state = seed | 1;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let (mut sites, d) = triangular_lattice(n, l);
    if d < sigma {
        return Err(format!(
            "{n} disks do not fit a triangular lattice of spacing at least {sigma} in a box of {l:.2} (packing {density}; spacing {d:.4})"
        ));
    }
    let last = sites.len() - 1;
    // The draw of n sites, as the indices of the lattice's sites.
    let mut index: Vec<usize> = (0..sites.len()).collect();
    for i in 0..n {
        let j = i + (uniform() * (sites.len() - i) as f64) as usize;
        index.swap(i, j.min(last));
    }
    index.truncate(n);
    if in_order {
        index.sort_unstable();
    }
    sites = index.iter().map(|&i| sites[i]).collect();
    let jitter = JITTER * (d - sigma);
    let x = sites
        .iter()
        .flat_map(|p| p.map(|c| super::wrap(c + jitter * (uniform() - 0.5), l)))
        .collect();
    let species = (0..n).map(|_| uniform() < fraction).collect();
    Ok((x, species, l))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table1_rows_and_refusals() {
        let row = s1_table1(&[ParamValue::Text("c4".into())]).unwrap();
        assert_eq!(
            row,
            ParamValue::Numbers(vec![0.5, 1.0, 1.0, -1.0, -4.0, 0.0873])
        );
        let err = s1_table1(&[ParamValue::Text("c5".into())]).unwrap_err();
        assert!(err.contains("no configuration `c5`"), "{err}");
        assert!(s1_table1(&[ParamValue::Number(1.0)]).is_err());
    }

    /// Lattice order numbers the same sites so that neighbours in number are neighbours in
    /// space; random order (lattice_disks) does not; both keep every pair sigma apart.
    #[test]
    fn lattice_order_numbers_the_same_sites_by_row() {
        let (n, sigma) = (500, 1.0);
        let (a, sa, l) = lattice_disks(n, 0.6, sigma, 0.5, 9).unwrap();
        let (b, sb, lb) = lattice_disks_in(n, 0.6, sigma, 0.5, 9, true).unwrap();
        assert_eq!((l, &sa), (lb, &sb), "box and species");
        let dist = |x: &[f64], i: usize, j: usize| {
            let d: Vec<f64> = (0..2)
                .map(|k| super::super::minimum_image(x[2 * i + k] - x[2 * j + k], l))
                .collect();
            d[0].hypot(d[1])
        };
        let step = |x: &[f64]| (1..n).map(|i| dist(x, i - 1, i)).sum::<f64>() / (n - 1) as f64;
        let (_, d) = triangular_lattice(n, l);
        assert!(step(&b) < 2.0 * d, "lattice order: mean step {}", step(&b));
        assert!(step(&a) > 4.0 * d, "random order: mean step {}", step(&a));
        for x in [&a, &b] {
            for i in 0..n {
                for j in 0..i {
                    assert!(dist(x, i, j) >= sigma, "disks {i} and {j} overlap");
                }
            }
        }
        // The same sites: every disk of one order within the jitter of one of the other.
        let jitter = JITTER * (d - sigma);
        for i in 0..n {
            let near = (0..n).any(|j| {
                let dx = super::super::minimum_image(a[2 * j] - b[2 * i], l);
                let dy = super::super::minimum_image(a[2 * j + 1] - b[2 * i + 1], l);
                dx.hypot(dy) <= jitter * std::f64::consts::SQRT_2
            });
            assert!(
                near,
                "disk {i} of the lattice order has no site in the random order"
            );
        }
    }
}
