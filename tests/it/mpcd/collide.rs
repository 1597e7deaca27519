//! Binning and collisions: the shifted grid and exact cell sums, the SRD and biased
//! collisions' conservation laws per cell (or supercell) and their f64 references.

use std::collections::BTreeMap;

use mesoflow::graph::Graph;
use mesoflow::nodes::mpcd::{CELL_WORDS, SUM_V, SumsLayout, value_of};
use mesoflow::nodes::random;
use mesoflow::value::HostArray;

use crate::util::mpcd::{cell_moments, random_particles, run_loaded, thermostat_of};
use crate::util::{Rng, gpu, particles, reference, rows, tmpdir, u32s, write_graph};

fn collide_graph(
    dir: &std::path::Path,
    n: usize,
    d: usize,
    geometry: &str,
    collide: &str,
) -> Graph {
    collide_graph_with(dir, n, d, geometry, "", collide)
}

/// As `collide_graph`, with `bin` added to mpcd_bin's params; mpcd_bin gets the
/// collision's thermostat (it sums |v|^2 for one).
fn collide_graph_with(
    dir: &std::path::Path,
    n: usize,
    d: usize,
    geometry: &str,
    bin: &str,
    collide: &str,
) -> Graph {
    let thermostat = thermostat_of(collide);
    let bin = if bin.is_empty() {
        format!(r#", "thermostat": "{thermostat}""#)
    } else {
        format!(r#", "thermostat": "{thermostat}", {bin}"#)
    };
    let json = format!(
        r#"{{"mesoflow": 1,
  "inputs": {{"x": {{"type": "particles", "rows": {n}, "cols": {d}}}, "v": {{"type": "particles", "rows": {n}, "cols": {d}}}}},
  "nodes": [
    {{"id": "bin", "kind": "mpcd_bin", "params": {{{geometry}{bin}, "seed": 7, "stream": 2}}, "inputs": {{"positions": "inputs.x", "velocities": "inputs.v"}}}},
    {{"id": "collide", "kind": "mpcd_collide", "params": {{{geometry}, {collide}, "seed": 7, "stream": 3}}, "inputs": {{"velocities": "inputs.v", "cell": "bin.cell", "sums": "bin.sums"}}}}
  ],
  "outputs": {{"cell": "bin.cell", "sums": "bin.sums", "v": "collide.velocities"}}}}"#
    );
    crate::util::load(&write_graph(dir, "collide.json", &json))
}

#[test]
fn binning_uses_the_shifted_grid_and_exact_sums() {
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("mpcd-bin");
    let mut rng = Rng::new(3);
    for (l, walls) in [
        (vec![6.0, 5.0, 4.0], "none"),
        (vec![6.0, 5.0, 4.0], "plates"),
        (vec![8.0, 6.0], "plates"),
    ] {
        let d = l.len();
        let n = 3000;
        let (x, v) = random_particles(&mut rng, n, &l);
        let geometry =
            format!(r#""box": {l:?}, "cell": 1, "walls": "{walls}", "temperature": 1, "mass": 1"#);
        let inputs: BTreeMap<String, HostArray> = [
            ("x".to_string(), particles(&x)),
            ("v".to_string(), particles(&v)),
        ]
        .into();
        // Native 64-bit atomics (where the adapter has them) and 32-bit pairs give the
        // same exact integers; without a thermostat the energy block is left out.
        let int64 = gpu().is_some_and(|g| g.caps.int64_atomics);
        let bin = |atomics: &str, thermostat: &str| {
            let g = collide_graph_with(
                &dir,
                n,
                d,
                &geometry,
                &format!(r#""atomics": "{atomics}""#),
                &format!(r#""angle": 130, "thermostat": "{thermostat}""#),
            );
            run_loaded(&g, &inputs, &["cell", "sums"], 1)
        };
        let out = bin("int32", "rescale");
        if int64 {
            let native = bin("int64", "rescale");
            assert_eq!(
                u32s(&native["sums"]),
                u32s(&out["sums"]),
                "{walls} {d}D int64"
            );
            assert_eq!(u32s(&native["cell"]), u32s(&out["cell"]));
        }
        let plain = bin("auto", "none");
        let ncells_all = u32s(&out["sums"]).len() / (CELL_WORDS as usize + 2);
        assert_eq!(
            u32s(&plain["sums"]),
            u32s(&out["sums"])[..ncells_all * CELL_WORDS as usize],
            "{walls} {d}D: the sums without a thermostat are the first block"
        );
        let cells = u32s(&out["cell"]);
        // The shift of step 0: Philox block 0 of (seed 7, stream 2), words 0..d, each mapped
        // to [-a/2, a/2).
        let w = random::block(0, 0, 7, 2);
        let s: Vec<f64> = (0..d)
            .map(|a| (w[a] >> 8) as f64 / 16_777_216.0 - 0.5)
            .collect();
        let mut dims: Vec<u32> = l.iter().map(|&x| x as u32).collect();
        if walls == "plates" {
            dims[d - 1] += 1;
        }
        let mut checked = 0;
        for p in 0..n {
            let mut c = 0u64;
            let mut near_edge = false;
            for a in (0..d).rev() {
                let mut y = x[p][a] as f32 as f64 + l[a] / 2.0 + s[a];
                if walls == "plates" && a == d - 1 {
                    y += 0.5;
                }
                near_edge |= (y - y.round()).abs() < 1e-5;
                let i = (y.floor() as i64).rem_euclid(dims[a] as i64);
                c = c * dims[a] as u64 + i as u64;
            }
            if !near_edge {
                assert_eq!(cells[p] as u64, c, "{walls} {d}D particle {p}");
                checked += 1;
            }
        }
        assert!(checked > n - 20);
        // Sums against f64 sums of the f32 inputs over the GPU's cells: each particle
        // rounds to the fixed-point unit, so |error| <= n/2 units.
        let ncells: u32 = dims.iter().product();
        let m = cell_moments(&cells, &rows(&particles(&v), d), ncells as usize);
        let sums = u32s(&out["sums"]);
        let (fix_v, fix_e) = (16_777_216.0, 65_536.0);
        let layout = SumsLayout {
            ncells,
            energy: true,
            solute: false,
        };
        assert_eq!(sums.len() as u64, layout.words());
        for c in 0..ncells as usize {
            let w = &sums[layout.cell(c)..layout.cell(c) + CELL_WORDS as usize];
            assert_eq!(
                value_of(w[0] as f64, w[1] as f64) as f64,
                m[c].0,
                "count of cell {c}"
            );
            for a in 0..3 {
                let gpu_sum =
                    value_of(w[SUM_V + 2 * a] as f64, w[SUM_V + 1 + 2 * a] as f64) as f64 / fix_v;
                let want = if a < d { m[c].1[a] } else { 0.0 };
                assert!(
                    (gpu_sum - want).abs() <= (0.5 * m[c].0 + 1.0) / fix_v,
                    "cell {c} axis {a}: {gpu_sum} vs {want}"
                );
            }
            let e = layout.energy_word(c);
            let gpu_e = value_of(sums[e] as f64, sums[e + 1] as f64) as f64 / fix_e;
            // f32 |v|^2 (relative 2^-23) then rounding to the unit.
            assert!(
                (gpu_e - m[c].2).abs() <= m[c].0 / fix_e + 3e-7 * m[c].2,
                "cell {c} energy"
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn srd_collision_conserves_cell_momentum_and_energy_and_matches_the_f64_reference() {
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("mpcd-collide");
    let mut rng = Rng::new(5);
    // (box, walls, kT, collision params); bin and collide share kT (the fixed-point unit).
    let cases: [(Vec<f64>, &str, f64, &str); 5] = [
        (vec![6.0, 5.0, 4.0], "none", 1.0, r#""angle": 130"#),
        (vec![8.0, 6.0], "none", 1.0, r#""angle": 90"#),
        (
            vec![6.0, 5.0, 4.0],
            "none",
            1.5,
            r#""angle": 130, "thermostat": "rescale""#,
        ),
        (
            vec![6.0, 5.0, 4.0],
            "none",
            1.5,
            r#""angle": 130, "thermostat": "monte_carlo""#,
        ),
        (
            vec![6.0, 5.0, 4.0],
            "plates",
            1.0,
            r#""angle": 130, "density": 10"#,
        ),
    ];
    for (l, walls, kt, collide) in cases {
        let d = l.len();
        let n = 2000;
        let (x, v) = random_particles(&mut rng, n, &l);
        let geometry = format!(
            r#""box": {l:?}, "cell": 1, "walls": "{walls}", "mass": 1, "temperature": {kt}"#
        );
        let g = collide_graph(&dir, n, d, &geometry, collide);
        let inputs: BTreeMap<String, HostArray> = [
            ("x".to_string(), particles(&x)),
            ("v".to_string(), particles(&v)),
        ]
        .into();
        let out = run_loaded(&g, &inputs, &["cell", "sums", "v"], 1);
        let cells = u32s(&out["cell"]);
        let vin = rows(&particles(&v), d);
        let vout = rows(&out["v"], d);
        let layers = l[d - 1] as usize + usize::from(walls == "plates");
        let ncells = l[..d - 1].iter().map(|&x| x as usize).product::<usize>() * layers;
        let before = cell_moments(&cells, &vin, ncells);
        let after = cell_moments(&cells, &vout, ncells);
        let layers = if walls == "plates" {
            l[d - 1] as u32 + 1
        } else {
            l[d - 1] as u32
        };
        let per_layer = ncells as u32 / layers;
        let mut rotated = 0.0;
        for c in 0..ncells {
            let (nb, pb, eb) = before[c];
            let (_, pa, ea) = after[c];
            if nb == 0.0 {
                continue;
            }
            let layer = c as u32 / per_layer;
            let ghost_cell = walls == "plates" && (layer == 0 || layer == layers - 1) && nb < 10.0;
            if ghost_cell {
                continue; // virtual particles exchange momentum with the wall
            }
            // f32 rounding of each new velocity (|v| < 4: 2.4e-7 per component) plus the
            // fixed-point mean (n x 2^-25): 1e-6 per particle is a safe bound; an SRD bug
            // (wrong mean, mixed cells) moves cell momentum by O(1).
            for a in 0..d {
                assert!(
                    (pa[a] - pb[a]).abs() < 1e-6 * nb,
                    "{collide}: cell {c} momentum {pb:?} -> {pa:?}"
                );
            }
            let u2: f64 = pb.iter().map(|p| p * p).sum::<f64>() / nb;
            let rel_b = eb - u2;
            let rel_a = ea - u2;
            if collide.contains("rescale") {
                // Relative kinetic energy set to d (n - 1) kT exactly.
                if nb >= 2.0 {
                    let want = d as f64 * (nb - 1.0) * kt;
                    assert!(
                        (rel_a - want).abs() < 1e-5 * ea.max(1.0),
                        "cell {c}: {rel_a} vs {want}"
                    );
                }
            } else if collide.contains("monte_carlo") {
                // Either unchanged or scaled by S^2 with S in [1/1.3, 1.3].
                let ratio = rel_a / rel_b.max(1e-30);
                assert!(
                    rel_b < 1e-6 || (1.0 / 1.69 - 1e-5..=1.69 + 1e-5).contains(&ratio),
                    "cell {c}: ratio {ratio}"
                );
            } else {
                assert!(
                    (ea - eb).abs() < 2e-6 * eb.max(1.0),
                    "{collide}: cell {c} energy {eb} -> {ea}"
                );
            }
            rotated += rel_b;
        }
        assert!(rotated > 0.0);
        // Against the node's f64 reference on the GPU's cells and sums.
        let params = format!("{{{geometry}, {collide}, \"seed\": 7, \"stream\": 3}}");
        let r = reference(
            "mpcd_collide",
            &params,
            &[Some(&particles(&v)), Some(&out["cell"]), Some(&out["sums"])],
        );
        let g = out["v"].data.to_f64();
        let mut worst: f64 = 0.0;
        for (a, b) in g.iter().zip(&r[0].data) {
            worst = worst.max((a - b).abs());
        }
        // f32 rotation of |v - u| < 6 with f32 trigonometry of the axis: ~1e-6.
        assert!(worst < 1e-5, "{collide}: largest |gpu - f64| {worst}");
        // The collision did something: velocities moved by O(1).
        let moved: f64 = g
            .iter()
            .zip(particles(&v).data.to_f64())
            .map(|(a, b)| (a - b).abs())
            .sum::<f64>()
            / g.len() as f64;
        assert!(moved > 0.3, "{collide}: mean |dv| {moved}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn biased_collisions_conserve_supercell_momentum_and_energy_and_match_the_f64_reference() {
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("mpcd-biased");
    let mut rng = Rng::new(13);
    for l in [vec![6.0, 4.0, 4.0], vec![8.0, 6.0]] {
        let d = l.len();
        let n = 2000;
        let (x, v) = random_particles(&mut rng, n, &l);
        let geometry = format!(r#""box": {l:?}, "cell": 1, "rule": "biased", "temperature": 1"#);
        // A large A makes most approaching pairs collide (tanh(A du n1 n2) ~ 1).
        let g = collide_graph(&dir, n, d, &geometry, r#""acceptance": 0.05"#);
        let inputs: BTreeMap<String, HostArray> = [
            ("x".to_string(), particles(&x)),
            ("v".to_string(), particles(&v)),
        ]
        .into();
        let out = run_loaded(&g, &inputs, &["cell", "sums", "v"], 1);
        let cells = u32s(&out["cell"]);
        let vin = rows(&particles(&v), d);
        let vout = rows(&out["v"], d);
        // Supercell of each cell: coordinates halved.
        let dims: Vec<u32> = l.iter().map(|&x| x as u32).collect();
        let supercell = |c: u32| {
            let (ix, iy) = (c % dims[0], (c / dims[0]) % dims[1]);
            let iz = if d == 3 { c / (dims[0] * dims[1]) } else { 0 };
            ix / 2 + dims[0] / 2 * (iy / 2 + dims[1] / 2 * (iz / 2))
        };
        let super_cells: Vec<u32> = cells.iter().map(|&c| supercell(c)).collect();
        let ns = dims.iter().map(|&c| c as usize / 2).product::<usize>();
        let before = cell_moments(&super_cells, &vin, ns);
        let after = cell_moments(&super_cells, &vout, ns);
        for s in 0..ns {
            // f32 rounding of the new velocities: 1e-6 per particle (see the SRD test).
            for a in 0..d {
                assert!(
                    (after[s].1[a] - before[s].1[a]).abs() < 1e-6 * before[s].0,
                    "supercell {s} momentum"
                );
            }
            assert!(
                (after[s].2 - before[s].2).abs() < 2e-6 * before[s].2.max(1.0),
                "supercell {s} energy"
            );
        }
        // Collisions happened and changed velocities of whole cells.
        let changed = (0..n)
            .filter(|&p| (0..d).any(|a| (vout[p][a] - vin[p][a]).abs() > 1e-3))
            .count();
        assert!(changed > n / 4, "{d}D: {changed} of {n} particles collided");
        let params = format!("{{{geometry}, \"acceptance\": 0.05, \"seed\": 7, \"stream\": 3}}");
        let r = reference(
            "mpcd_collide",
            &params,
            &[Some(&particles(&v)), Some(&out["cell"]), Some(&out["sums"])],
        );
        let worst = out["v"]
            .data
            .to_f64()
            .iter()
            .zip(&r[0].data)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-5, "{d}D: largest |gpu - f64| {worst}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// MPCD-BC between plates (S2 §4.2.3 with the biased rule): the walled axis has L/a + 2
/// layers (the shift spans 2a), binning and collisions match their f64 references for
/// several shifts (seeds), supercells clear of the plates conserve momentum and energy,
/// and the cells the plates cut take part with their virtual particles: the supercells
/// at the plates exchange momentum with the wall.
#[test]
fn biased_collisions_between_plates_match_the_f64_reference() {
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("mpcd-biased-plates");
    let mut rng = Rng::new(17);
    for l in [vec![6.0, 4.0, 4.0], vec![8.0, 6.0]] {
        let d = l.len();
        let n = 2000;
        let mut wall_exchange = 0.0;
        for seed in [7, 8, 9] {
            let (x, v) = random_particles(&mut rng, n, &l);
            let geometry = format!(
                r#""box": {l:?}, "cell": 1, "walls": "plates", "rule": "biased", "temperature": 1"#
            );
            let json = format!(
                r#"{{"mesoflow": 1,
  "inputs": {{"x": {{"type": "particles", "rows": {n}, "cols": {d}}}, "v": {{"type": "particles", "rows": {n}, "cols": {d}}}}},
  "nodes": [
    {{"id": "bin", "kind": "mpcd_bin", "params": {{{geometry}, "seed": {seed}, "stream": 2}}, "inputs": {{"positions": "inputs.x", "velocities": "inputs.v"}}}},
    {{"id": "collide", "kind": "mpcd_collide", "params": {{{geometry}, "acceptance": 0.05, "density": 5, "shift_stream": 2, "seed": {seed}, "stream": 3}}, "inputs": {{"velocities": "inputs.v", "cell": "bin.cell", "sums": "bin.sums"}}}}
  ],
  "outputs": {{"cell": "bin.cell", "sums": "bin.sums", "v": "collide.velocities"}}}}"#
            );
            let g = crate::util::load(&write_graph(&dir, "collide.json", &json));
            let inputs: BTreeMap<String, HostArray> = [
                ("x".to_string(), particles(&x)),
                ("v".to_string(), particles(&v)),
            ]
            .into();
            let out = run_loaded(&g, &inputs, &["cell", "sums", "v"], 1);
            let mut dims: Vec<u32> = l.iter().map(|&x| x as u32).collect();
            dims[d - 1] += 2;
            let ncells: u32 = dims.iter().product();
            assert_eq!(
                u32s(&out["sums"]).len() as u32,
                ncells * CELL_WORDS,
                "{d}D: L/a + 2 layers"
            );
            let bin_params = format!("{{{geometry}, \"seed\": {seed}, \"stream\": 2}}");
            let rb = reference(
                "mpcd_bin",
                &bin_params,
                &[Some(&particles(&x)), Some(&particles(&v))],
            );
            let cells = u32s(&out["cell"]);
            for (p, &c) in cells.iter().enumerate() {
                assert_eq!(
                    c as f64, rb[0].data[p],
                    "{d}D seed {seed}: particle {p}'s cell"
                );
            }
            let params = format!(
                "{{{geometry}, \"acceptance\": 0.05, \"density\": 5, \"shift_stream\": 2, \"seed\": {seed}, \"stream\": 3}}"
            );
            let r = reference(
                "mpcd_collide",
                &params,
                &[Some(&particles(&v)), Some(&out["cell"]), Some(&out["sums"])],
            );
            let worst = out["v"]
                .data
                .to_f64()
                .iter()
                .zip(&r[0].data)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(
                worst < 1e-5,
                "{d}D seed {seed}: largest |gpu - f64| {worst}"
            );
            let vin = rows(&particles(&v), d);
            let vout = rows(&out["v"], d);
            let below = dims[..d - 1].iter().product::<u32>();
            let supercell = |c: u32| {
                let (ix, iy) = (c % dims[0], (c / dims[0]) % dims[1]);
                let iz = if d == 3 { c / (dims[0] * dims[1]) } else { 0 };
                ix / 2 + dims[0] / 2 * (iy / 2 + dims[1] / 2 * (iz / 2))
            };
            let super_cells: Vec<u32> = cells.iter().map(|&c| supercell(c)).collect();
            let ns = dims.iter().map(|&c| c as usize / 2).product::<usize>();
            let before = cell_moments(&super_cells, &vin, ns);
            let after = cell_moments(&super_cells, &vout, ns);
            let top = dims[d - 1] / 2 - 1;
            for s in 0..ns {
                // The supercell's layer pair: the first and last touch the plates.
                let layer_pair = s as u32 / (below / 2u32.pow(d as u32 - 1));
                let dp: f64 = (0..d).map(|a| (after[s].1[a] - before[s].1[a]).abs()).sum();
                if layer_pair == 0 || layer_pair == top {
                    wall_exchange += dp;
                    continue;
                }
                assert!(dp < 1e-6 * d as f64 * before[s].0, "supercell {s} momentum");
                assert!(
                    (after[s].2 - before[s].2).abs() < 2e-6 * before[s].2.max(1.0),
                    "supercell {s} energy"
                );
            }
        }
        assert!(
            wall_exchange > 1.0,
            "{d}D: momentum exchanged with the plates {wall_exchange}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
