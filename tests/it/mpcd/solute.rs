//! Solute coupling: solutes binned into the solvent's cells with their mass, collisions
//! conserving mass-weighted cell momentum and energy, thermostats and virtual particles
//! counting both species, equipartition, and the setups that are refused.

use std::collections::BTreeMap;

use mesoflow::expr::ParamValue;
use mesoflow::graph::{self, LoadOptions};
use mesoflow::nodes::mpcd::{CELL_WORDS, SUM_V, SumsLayout, value_of};
use mesoflow::plan::{self, PlanOptions};
use mesoflow::value::{HostArray, ValueType};

use crate::util::mpcd::{mass_moments, random_particles, run_loaded, thermostat_of};
use crate::util::{
    Rng, gpu, particles, reference, registry, root, rows, tmpdir, u32s, write_graph,
};

/// mpcd_bin, mpcd_bin_solute and mpcd_collide on each species (the same params).
fn solute_graph(
    dir: &std::path::Path,
    (n, ns, d): (usize, usize, usize),
    geometry: &str,
    solute_mass: f64,
    collide: &str,
) -> String {
    let p = |rows: usize| format!(r#"{{"type": "particles", "rows": {rows}, "cols": {d}}}"#);
    let thermostat = thermostat_of(collide);
    let json = format!(
        r#"{{"mesoflow": 1,
  "inputs": {{"x": {}, "v": {}, "xs": {}, "vs": {}}},
  "nodes": [
    {{"id": "bin", "kind": "mpcd_bin", "params": {{{geometry}, "thermostat": "{thermostat}", "seed": 7, "stream": 2}}, "inputs": {{"positions": "inputs.x", "velocities": "inputs.v"}}}},
    {{"id": "bin_solute", "kind": "mpcd_bin_solute", "params": {{{geometry}, "solute_mass": {solute_mass}, "seed": 7, "stream": 2}}, "inputs": {{"sums": "bin.sums", "positions": "inputs.xs", "velocities": "inputs.vs"}}}},
    {{"id": "collide", "kind": "mpcd_collide", "params": {{{geometry}, {collide}, "seed": 7, "stream": 3}}, "inputs": {{"velocities": "inputs.v", "cell": "bin.cell", "sums": "bin_solute.sums"}}}},
    {{"id": "collide_solute", "kind": "mpcd_collide", "params": {{{geometry}, {collide}, "seed": 7, "stream": 3}}, "inputs": {{"velocities": "inputs.vs", "cell": "bin_solute.cell", "sums": "bin_solute.sums"}}}}
  ],
  "outputs": {{"cell": "bin.cell", "sums": "bin.sums", "scell": "bin_solute.cell", "ssums": "bin_solute.sums", "v": "collide.velocities", "vs": "collide_solute.velocities"}}}}"#,
        p(n),
        p(n),
        p(ns),
        p(ns)
    );
    write_graph(dir, "solute.json", &json)
        .to_string_lossy()
        .into_owned()
}

/// The collisions of a solute graph run (`solute_graph`: outputs v, vs, cell, scell,
/// ssums) against mpcd_collide's f64 reference, for both species: within 1e-5 (f32
/// rotations of |v - u| < 6 with f32 trigonometry of the axis: about 1e-6).
fn collisions_match_the_reference(
    geometry: &str,
    collide: &str,
    (v, vs): (&[Vec<f64>], &[Vec<f64>]),
    out: &BTreeMap<String, HostArray>,
    case: &str,
) {
    let params = format!("{{{geometry}, {collide}, \"seed\": 7, \"stream\": 3}}");
    for (vel, cell, name) in [
        (particles(v), &out["cell"], "v"),
        (particles(vs), &out["scell"], "vs"),
    ] {
        let r = reference(
            "mpcd_collide",
            &params,
            &[Some(&vel), Some(cell), Some(&out["ssums"])],
        );
        let worst = out[name]
            .data
            .to_f64()
            .iter()
            .zip(&r[0].data)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-5, "{name} {case}: largest |gpu - f64| {worst}");
    }
}

#[test]
fn solute_collision_conserves_mass_weighted_cell_momentum_and_energy_and_matches_the_f64_reference()
{
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("mpcd-solute");
    let mut rng = Rng::new(11);
    // (box, walls, M / m): a power of two (exact f32 weights) and not.
    let cases: [(Vec<f64>, &str, f64); 3] = [
        (vec![6.0, 5.0, 4.0], "none", 4.0),
        (vec![8.0, 6.0], "none", 2.5),
        (vec![6.0, 5.0, 4.0], "plates", 4.0),
    ];
    let mut compared = 0;
    for (l, walls, ratio) in cases {
        let d = l.len();
        let (n, ns) = (1500, 400);
        let (x, v) = random_particles(&mut rng, n, &l);
        let (xs, mut vs) = random_particles(&mut rng, ns, &l);
        // Solutes slower, drifting along x against a solvent at rest on average: the
        // collision must pass momentum from the solute to the solvent.
        for row in vs.iter_mut() {
            for (a, va) in row.iter_mut().enumerate() {
                *va = 0.5 * *va + if a == 0 { 1.0 } else { 0.0 };
            }
        }
        let geometry =
            format!(r#""box": {l:?}, "cell": 1, "walls": "{walls}", "mass": 1, "temperature": 1"#);
        let collide = r#""angle": 130, "ghosts": false"#;
        let path = solute_graph(&dir, (n, ns, d), &geometry, ratio, collide);
        let g = crate::util::load(std::path::Path::new(&path));
        let inputs: BTreeMap<String, HostArray> = [
            ("x".to_string(), particles(&x)),
            ("v".to_string(), particles(&v)),
            ("xs".to_string(), particles(&xs)),
            ("vs".to_string(), particles(&vs)),
        ]
        .into();
        let out = run_loaded(
            &g,
            &inputs,
            &["cell", "sums", "scell", "ssums", "v", "vs"],
            1,
        );
        let cells = u32s(&out["cell"]);
        let scells = u32s(&out["scell"]);
        let ssums = u32s(&out["ssums"]);
        let ncells = out["sums"].ty.words() as usize / CELL_WORDS as usize;
        let layout = SumsLayout {
            ncells: ncells as u32,
            energy: false,
            solute: true,
        };
        assert_eq!(ssums.len() as u64, layout.words());
        assert_eq!(f32::from_bits(ssums[ssums.len() - 1]), ratio as f32);

        // Binning against the f64 reference: the same cells (the solvent's grid shift),
        // exact counts, and sums within the rounding of each solute term to the unit.
        let sref = reference(
            "mpcd_bin_solute",
            &format!(r#"{{{geometry}, "solute_mass": {ratio}, "seed": 7, "stream": 2}}"#),
            &[
                Some(&out["sums"]),
                Some(&particles(&xs)),
                Some(&particles(&vs)),
            ],
        );
        let ref_cells: Vec<u32> = sref[0].data.iter().map(|&c| c as u32).collect();
        let same = ref_cells
            .iter()
            .zip(&scells)
            .filter(|(a, b)| a == b)
            .count();
        assert!(same >= ns - 2, "{same} of {ns} solute cells agree");
        if same == ns {
            compared += 1;
            let rs = &sref[1].data;
            for c in 0..ncells {
                let ns_c = ssums[layout.solute_word(c)] as f64;
                assert_eq!(rs[layout.solute_word(c)], ns_c, "solute count of cell {c}");
                let b = layout.cell(c);
                assert_eq!(rs[b], ssums[b] as f64, "count of cell {c}");
                for j in 0..3 {
                    let w = b + SUM_V + 2 * j;
                    let g = value_of(ssums[w] as f64, ssums[w + 1] as f64);
                    let r = value_of(rs[w], rs[w + 1]);
                    // f32 products emulated exactly, ties aside (1 unit per solute).
                    assert!(
                        ((g - r) as f64).abs() <= ns_c,
                        "cell {c} word {j}: {g} vs {r}"
                    );
                }
            }
        }
        // The solvent's cell means are mass-weighted: per cell, m sum v + M sum V and
        // m sum |v|^2 + M sum |V|^2 are conserved.
        let vin = rows(&particles(&v), d);
        let vsin = rows(&particles(&vs), d);
        let vout = rows(&out["v"], d);
        let vsout = rows(&out["vs"], d);
        let before = mass_moments(&[(&cells, &vin, 1.0), (&scells, &vsin, ratio)], ncells);
        let after = mass_moments(&[(&cells, &vout, 1.0), (&scells, &vsout, ratio)], ncells);
        let mut with_solute = 0;
        for c in 0..ncells {
            let (mb, pb, eb) = before[c];
            let (_, pa, ea) = after[c];
            if mb == 0.0 {
                continue;
            }
            with_solute += usize::from(scells.contains(&(c as u32)));
            // f32 rounding of each new velocity (|v| < 5: 3e-7 per component, times M for
            // a solute) and the f32 mean from the fixed-point sums (2^-24 relative): 1e-6
            // per unit of mass bounds it; a wrong weight moves cell momentum by O(1).
            for a in 0..d {
                assert!(
                    (pa[a] - pb[a]).abs() < 1e-6 * mb,
                    "M/m {ratio} {walls}: cell {c} momentum {pb:?} -> {pa:?}"
                );
            }
            assert!(
                (ea - eb).abs() < 2e-6 * eb.max(1.0),
                "M/m {ratio} {walls}: cell {c} energy {eb} -> {ea}"
            );
        }
        assert!(with_solute > ncells / 2);
        // Momentum moved from the solute to the solvent: the solute's x momentum M ns
        // drops by a large fraction (the solvent outweighs it in most cells).
        let px = |vv: &[Vec<f64>]| vv.iter().map(|r| r[0]).sum::<f64>();
        assert!(
            px(&vsout) < 0.6 * px(&vsin),
            "solute x momentum {} -> {}",
            px(&vsin),
            px(&vsout)
        );
        // Both species against the f64 reference on the GPU's cells and sums.
        collisions_match_the_reference(
            &geometry,
            collide,
            (&v, &vs),
            &out,
            &format!("M/m {ratio}"),
        );
    }
    // Cells on a cell edge to f32 precision may differ; most cases compare every word.
    assert!(
        compared >= 2,
        "only {compared} cases had identical solute cells"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn solute_refuses_mismatched_sums_and_takes_biased_collisions() {
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("mpcd-solute-bad");
    let gpu = gpu().expect("GPU");
    let geometry =
        r#""box": [4.0, 4.0, 4.0], "cell": 1, "walls": "none", "mass": 1, "temperature": 1"#;
    let plan_error = |geometry: &str, solute_geometry: &str, collide: &str| {
        let json = format!(
            r#"{{"mesoflow": 1,
  "inputs": {{"x": {{"type": "particles", "rows": 10, "cols": 3}}, "xs": {{"type": "particles", "rows": 4, "cols": 3}}}},
  "nodes": [
    {{"id": "bin", "kind": "mpcd_bin", "params": {{{geometry}}}, "inputs": {{"positions": "inputs.x", "velocities": "inputs.x"}}}},
    {{"id": "bin_solute", "kind": "mpcd_bin_solute", "params": {{{solute_geometry}, "solute_mass": 3}}, "inputs": {{"sums": "bin.sums", "positions": "inputs.xs", "velocities": "inputs.xs"}}}},
    {{"id": "collide", "kind": "mpcd_collide", "params": {{{solute_geometry}, {collide}}}, "inputs": {{"velocities": "inputs.xs", "cell": "bin_solute.cell", "sums": "bin_solute.sums"}}}}
  ],
  "outputs": {{"vs": "collide.velocities"}}}}"#
        );
        let g = crate::util::load(&write_graph(&dir, "bad.json", &json));
        let opts = PlanOptions {
            outputs: Some(vec!["vs".into()]),
            inputs: [
                ("x".to_string(), ValueType::Particles { n: 10, k: 3 }),
                ("xs".to_string(), ValueType::Particles { n: 4, k: 3 }),
            ]
            .into(),
            fuse: true,
            in_place: true,
        };
        plan::plan(&g, &opts, &gpu.caps)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default()
    };
    // A thermostat needs the energy sums, which this mpcd_bin (no thermostat) leaves out.
    for collide in [
        r#""thermostat": "rescale""#,
        r#""thermostat": "monte_carlo""#,
    ] {
        let e = plan_error(geometry, geometry, collide);
        assert!(
            e.contains("collide") && e.contains("sums") && e.contains("thermostat"),
            "{e}"
        );
    }
    let plates =
        r#""box": [4.0, 4.0, 4.0], "cell": 1, "walls": "plates", "mass": 1, "temperature": 1"#;
    assert_eq!(plan_error(plates, plates, r#""ghosts": true"#), "");
    // MPCD-BC takes a solute (the cells' masses for the counts): it plans.
    let biased = format!("{geometry}, \"rule\": \"biased\"");
    assert_eq!(plan_error(&biased, &biased, r#""acceptance": 0.01"#), "");
    // Solvent sums of another grid.
    let other =
        r#""box": [4.0, 4.0, 6.0], "cell": 1, "walls": "none", "mass": 1, "temperature": 1"#;
    let e = plan_error(geometry, other, r#""angle": 130"#);
    assert!(
        e.contains("bin_solute")
            && e.contains("sums")
            && e.contains("768 or 960 words")
            && e.contains("512"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn solute_and_solvent_share_the_temperature_in_equilibrium() {
    if gpu().is_none() {
        return;
    }
    // 5120 solvent particles with uniform velocities of variance 1 per component (not
    // Maxwellian) and 1000 solutes of mass 4 at rest: energy conservation and equipartition
    // give both species kT_eq = m sum |v|^2 / (3 (N + N_s)) after equilibration. The
    // solute's kinetic temperature M <|V|^2> / 3 over 3000 degrees of freedom has a
    // relative standard deviation sqrt(2/3000) = 2.6% (the solvent's 1.1%); 10% is 3.5
    // sigma of the difference. A solute weighted as mass m instead of M would come out at
    // 4 kT_eq; a solute left out of the cell means breaks energy conservation.
    let l = 8.0;
    let (n, ns, ratio) = (5120, 1000, 4.0);
    let mut rng = Rng::new(21);
    let a = 3f64.sqrt();
    let x: Vec<Vec<f64>> = (0..n)
        .map(|_| (0..3).map(|_| rng.uniform(-l / 2.0, l / 2.0)).collect())
        .collect();
    let mut v: Vec<Vec<f64>> = (0..n)
        .map(|_| (0..3).map(|_| rng.uniform(-a, a)).collect())
        .collect();
    // Zero total momentum (so kT_eq needs no centre-of-mass term).
    for k in 0..3 {
        let mean = v.iter().map(|r| r[k]).sum::<f64>() / n as f64;
        v.iter_mut().for_each(|r| r[k] -= mean);
    }
    let xs: Vec<Vec<f64>> = (0..ns)
        .map(|_| (0..3).map(|_| rng.uniform(-l / 2.0, l / 2.0)).collect())
        .collect();
    let vs = vec![vec![0.0; 3]; ns];
    let vin = particles(&v);
    let e0: f64 = vin.data.to_f64().iter().map(|x| x * x).sum();
    let kt_eq = e0 / (3.0 * (n + ns) as f64);
    let dir = tmpdir("mpcd-solute-eq");
    let steps = 150;
    let g = graph::load(
        &root().join("graphs/mpcd_solute.json"),
        registry(),
        &LoadOptions {
            overrides: [
                ("box".to_string(), ParamValue::Numbers(vec![l, l, l])),
                ("solute_mass".to_string(), ParamValue::Number(ratio)),
            ]
            .into(),
            steps,
            seed: 5,
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let inputs: BTreeMap<String, HostArray> = [
        ("positions".to_string(), particles(&x)),
        ("velocities".to_string(), vin),
        ("solute_positions".to_string(), particles(&xs)),
        ("solute_velocities".to_string(), particles(&vs)),
    ]
    .into();
    let out = run_loaded(
        &g,
        &inputs,
        &["velocities", "solute_velocities", "solute_positions"],
        steps,
    );
    let e_solvent: f64 = out["velocities"].data.to_f64().iter().map(|x| x * x).sum();
    let e_solute: f64 = ratio
        * out["solute_velocities"]
            .data
            .to_f64()
            .iter()
            .map(|x| x * x)
            .sum::<f64>();
    let t_solvent = e_solvent / (3.0 * n as f64);
    let t_solute = e_solute / (3.0 * ns as f64);
    eprintln!(
        "kT_eq {kt_eq}: solvent {t_solvent}, solute {t_solute}, energy {e0} -> {}",
        e_solvent + e_solute
    );
    // Energy: f32 rounding per collision, a random walk of ~1e-7 per particle and step.
    assert!(
        ((e_solvent + e_solute) / e0 - 1.0).abs() < 1e-4,
        "energy {e0} -> {}",
        e_solvent + e_solute
    );
    assert!(
        (t_solute / t_solvent - 1.0).abs() < 0.1,
        "solute kT {t_solute}, solvent kT {t_solvent} (kT_eq {kt_eq})"
    );
    assert!(
        (t_solvent / kt_eq - 1.0).abs() < 0.05,
        "solvent kT {t_solvent} vs {kt_eq}"
    );
    assert!(
        (t_solute / kt_eq - 1.0).abs() < 0.1,
        "solute kT {t_solute} vs {kt_eq}"
    );
    // The solutes moved and stayed in the box.
    let pos = out["solute_positions"].data.to_f64();
    assert!(pos.iter().all(|&p| p.abs() <= l / 2.0));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn solute_binning_adds_to_the_energy_sums_when_the_solvent_has_them() {
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("mpcd-solute-energy");
    let mut rng = Rng::new(23);
    let l = vec![5.0, 4.0, 3.0];
    let (n, ns) = (600, 40);
    let (x, v) = random_particles(&mut rng, n, &l);
    let (xs, vs) = random_particles(&mut rng, ns, &l);
    let geometry =
        r#""box": [5.0, 4.0, 3.0], "cell": 1, "walls": "none", "mass": 1, "temperature": 1"#;
    let json = format!(
        r#"{{"mesoflow": 1,
  "inputs": {{"x": {{"type": "particles", "rows": {n}, "cols": 3}}, "v": {{"type": "particles", "rows": {n}, "cols": 3}},
             "xs": {{"type": "particles", "rows": {ns}, "cols": 3}}, "vs": {{"type": "particles", "rows": {ns}, "cols": 3}}}},
  "nodes": [
    {{"id": "bin", "kind": "mpcd_bin", "params": {{{geometry}, "thermostat": "rescale", "seed": 7, "stream": 2}}, "inputs": {{"positions": "inputs.x", "velocities": "inputs.v"}}}},
    {{"id": "bin_solute", "kind": "mpcd_bin_solute", "params": {{{geometry}, "solute_mass": 2.5, "seed": 7, "stream": 2}}, "inputs": {{"sums": "bin.sums", "positions": "inputs.xs", "velocities": "inputs.vs"}}}}
  ],
  "outputs": {{"sums": "bin.sums", "scell": "bin_solute.cell", "ssums": "bin_solute.sums"}}}}"#
    );
    let g = crate::util::load(&write_graph(&dir, "energy.json", &json));
    let inputs: BTreeMap<String, HostArray> = [
        ("x".to_string(), particles(&x)),
        ("v".to_string(), particles(&v)),
        ("xs".to_string(), particles(&xs)),
        ("vs".to_string(), particles(&vs)),
    ]
    .into();
    let out = run_loaded(&g, &inputs, &["sums", "scell", "ssums"], 1);
    let layout = SumsLayout {
        ncells: 60,
        energy: true,
        solute: true,
    };
    let ssums = u32s(&out["ssums"]);
    assert_eq!(ssums.len() as u64, layout.words());
    let sref = reference(
        "mpcd_bin_solute",
        &format!(r#"{{{geometry}, "solute_mass": 2.5, "seed": 7, "stream": 2}}"#),
        &[
            Some(&out["sums"]),
            Some(&particles(&xs)),
            Some(&particles(&vs)),
        ],
    );
    let ref_cells: Vec<u32> = sref[0].data.iter().map(|&c| c as u32).collect();
    assert_eq!(ref_cells, u32s(&out["scell"]), "solute cells");
    let (solvent, rs) = (u32s(&out["sums"]), &sref[1].data);
    let mut with_solute = 0;
    for c in 0..60 {
        let ns_c = ssums[layout.solute_word(c)] as f64;
        assert_eq!(rs[layout.solute_word(c)], ns_c, "solute count of cell {c}");
        let e = layout.energy_word(c);
        let (g, r) = (
            value_of(ssums[e] as f64, ssums[e + 1] as f64),
            value_of(rs[e], rs[e + 1]),
        );
        // f32 |v|^2 M/m (2^-22 relative of <= 2^20 units) rounded: 2 units per solute.
        assert!(
            ((g - r) as f64).abs() <= 2.0 * ns_c + 1e-6 * r.abs() as f64,
            "cell {c} energy: {g} vs {r}"
        );
        let s = value_of(solvent[e] as f64, solvent[e + 1] as f64);
        if ns_c > 0.0 {
            with_solute += 1;
            assert!(g > s, "cell {c}: the solute's energy is added");
        } else {
            assert_eq!(g, s, "cell {c}: no solute, the solvent's energy");
        }
    }
    assert!(with_solute > 10);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn solute_thermostats_and_virtual_particles_count_both_species() {
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("mpcd-solute-thermostat");
    let mut rng = Rng::new(31);
    let l = vec![6.0, 5.0, 4.0];
    let (n, ns) = (1500, 300);
    // (walls, M / m, collision params)
    let cases = [
        (
            "none",
            4.0,
            r#""angle": 130, "thermostat": "rescale", "ghosts": false"#,
        ),
        (
            "none",
            2.5,
            r#""angle": 130, "thermostat": "monte_carlo", "mc_scale": 0.5, "ghosts": false"#,
        ),
        (
            "plates",
            4.0,
            r#""angle": 130, "density": 10, "ghosts": true"#,
        ),
    ];
    for (walls, ratio, collide) in cases {
        let (x, v) = random_particles(&mut rng, n, &l);
        let (xs, vs) = random_particles(&mut rng, ns, &l);
        let geometry =
            format!(r#""box": {l:?}, "cell": 1, "walls": "{walls}", "mass": 1, "temperature": 1"#);
        let path = solute_graph(&dir, (n, ns, 3), &geometry, ratio, collide);
        let g = crate::util::load(std::path::Path::new(&path));
        let inputs: BTreeMap<String, HostArray> = [
            ("x".to_string(), particles(&x)),
            ("v".to_string(), particles(&v)),
            ("xs".to_string(), particles(&xs)),
            ("vs".to_string(), particles(&vs)),
        ]
        .into();
        let out = run_loaded(&g, &inputs, &["cell", "scell", "ssums", "v", "vs"], 1);
        let (cells, scells) = (u32s(&out["cell"]), u32s(&out["scell"]));
        let layers = l[2] as usize + usize::from(walls == "plates");
        let ncells = 30 * layers;
        let (vin, vsin) = (rows(&particles(&v), 3), rows(&particles(&vs), 3));
        let (vout, vsout) = (rows(&out["v"], 3), rows(&out["vs"], 3));
        let species = |a: &[Vec<f64>], b: &[Vec<f64>]| {
            mass_moments(&[(&cells, a, 1.0), (&scells, b, ratio)], ncells)
        };
        let (before, after) = (species(&vin, &vsin), species(&vout, &vsout));
        let mut count = vec![0usize; ncells];
        for &c in cells.iter().chain(&scells) {
            count[c as usize] += 1;
        }
        let mut scaled = 0;
        for c in 0..ncells {
            let ((mb, pb, eb), (_, pa, ea)) = (before[c], after[c]);
            if mb == 0.0 {
                continue;
            }
            let cut = walls == "plates" && (c / 30 == 0 || c / 30 == layers - 1);
            if cut {
                continue;
            }
            for a in 0..3 {
                assert!(
                    (pa[a] - pb[a]).abs() < 1e-6 * mb,
                    "{collide}: cell {c} momentum {pb:?} -> {pa:?}"
                );
            }
            // Twice the relative kinetic energy (units of m) after the collision.
            let rel_after = ea - pa.iter().map(|p| p * p).sum::<f64>() / mb;
            if collide.contains("rescale") {
                if count[c] >= 2 {
                    let want = 3.0 * (count[c] as f64 - 1.0);
                    assert!(
                        (rel_after / want - 1.0).abs() < 1e-5,
                        "cell {c}: relative energy {rel_after} against d (n + n_s - 1) kT = {want}"
                    );
                }
            } else if collide.contains("monte_carlo") {
                scaled += usize::from((ea - eb).abs() > 1e-4 * eb);
            } else {
                assert!(
                    (ea - eb).abs() < 2e-6 * eb.max(1.0),
                    "{collide}: cell {c} energy {eb} -> {ea}"
                );
            }
        }
        if collide.contains("monte_carlo") {
            assert!(scaled > ncells / 10, "{scaled} cells scaled");
        }
        // Both species against the f64 reference on the GPU's cells and sums.
        collisions_match_the_reference(&geometry, collide, (&v, &vs), &out, collide);
    }
    let _ = std::fs::remove_dir_all(&dir);
}
