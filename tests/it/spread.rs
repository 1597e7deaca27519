//! Spreading and interpolation against f64 references: single particles (the separable
//! product exactly), random particles in 2D and 3D, every window, both variants,
//! conservation, adjointness, periodic wrap, faces and edges, empty input.

use std::collections::BTreeMap;

use mesoflow::value::{HostArray, ValueType};

use crate::util::{
    Rng, gpu, reference, rel_max_err, run_node_and_reference, single_node_graph, tmpdir,
    write_graph,
};

fn run_node(
    kind: &str,
    params: &str,
    inputs: &[(&str, HostArray)],
) -> (HostArray, mesoflow::value::RefArray) {
    let (mut out, mut refs) = run_node_and_reference(kind, params, inputs);
    (out.remove("out").expect("output `out`"), refs.remove(0))
}

fn positions(rng: &mut Rng, n: u32, lengths: &[f64]) -> HostArray {
    let d = lengths.len();
    let v = (0..n as usize * d)
        .map(|i| rng.uniform(-0.5 * lengths[i % d], 0.5 * lengths[i % d]) as f32)
        .collect();
    HostArray::f32(ValueType::Particles { n, k: d as u32 }, v)
}

/// Window params used across the tests: (name, extra params).
const WINDOWS: &[(&str, &str)] = &[
    ("gaussian", r#""width": 0.6, "tolerance": 1e-4"#),
    ("es", r#""support": 6"#),
    ("peskin3", ""),
    ("peskin4", ""),
    ("peskin6", ""),
];

fn params(window: &str, extra: &str, lengths: &[f64], cells: &[u32], variant: &str) -> String {
    let sep = if extra.is_empty() { "" } else { ", " };
    format!(
        r#"{{"box": {lengths:?}, "grid": {cells:?}, "window": "{window}"{sep}{extra}, "variant": "{variant}"}}"#
    )
}

/// Window params `extra` (possibly empty) with `more` params appended.
fn with(extra: &str, more: &str) -> String {
    if extra.is_empty() {
        more.to_string()
    } else {
        format!("{extra}, {more}")
    }
}

/// f32 window weights and accumulation against f64: relative to the largest value.
const TOL: f64 = 2e-6;

/// Runs node `kind` with `params` on `inputs` and asserts its output within `tol` of its
/// f64 reference, relative to the largest reference value (`what` names the case).
fn assert_like_reference(
    kind: &str,
    params: &str,
    inputs: &[(&str, HostArray)],
    tol: f64,
    what: &str,
) {
    let (g, r) = run_node(kind, params, inputs);
    let (err, at) = rel_max_err(&g, &r);
    assert!(err < tol, "{what}: error {err:e} at {at}");
}

#[test]
fn a_single_particle_spreads_the_separable_product() {
    if gpu().is_none() {
        return;
    }
    let lengths = [16.0, 12.0, 10.0];
    let cells = [16u32, 24, 10];
    // Inside, on a cell face, on a cell centre, at -L/2 and +L/2 (which wrap together).
    for q in [
        [0.3, -2.7, 4.1],
        [1.0, 0.5, 0.0],
        [0.5, 0.25, 0.5],
        [-8.0, -6.0, -5.0],
        [8.0, 6.0, 5.0],
    ] {
        let pos = HostArray::f32(ValueType::Particles { n: 1, k: 3 }, q.to_vec());
        let vals = HostArray::f32(ValueType::Particles { n: 1, k: 2 }, vec![1.5, -0.5]);
        for (w, extra) in WINDOWS {
            let p = params(w, extra, &lengths, &cells, "auto");
            assert_like_reference(
                "spread",
                &p,
                &[("positions", pos.clone()), ("values", vals.clone())],
                TOL,
                &format!("{w} at {q:?}"),
            );
        }
    }
}

#[test]
fn many_particles_spread_and_interpolate_like_the_reference() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(17);
    // 3D non-cubic, and 2D.
    for (lengths, cells) in [
        (vec![20.0, 14.0, 9.0], vec![32u32, 20, 12]),
        (vec![30.0, 10.0], vec![48u32, 16]),
    ] {
        let n = 300;
        let pos = positions(&mut rng, n, &lengths);
        let vals = rng.array(ValueType::Particles { n, k: 3 }, -1.0, 1.0);
        let mut dims = [1u32; 3];
        dims[..cells.len()].copy_from_slice(&cells);
        let field = rng.array(ValueType::RealGrid { dims, comps: 3 }, -1.0, 1.0);
        let quad = rng.array(ValueType::RealGrid { dims, comps: 1 }, 0.5, 1.5);
        // Both per-particle kernels: lanes (a segment of subgroup lanes per particle,
        // where the support fits the subgroup) and the workgroup-table kernels.
        for (w, extra) in WINDOWS {
            for lanes in ["auto", "off"] {
                let extra = with(extra, &format!(r#""lanes": "{lanes}""#));
                for variant in ["atomic", "portable"] {
                    let p = params(w, &extra, &lengths, &cells, variant);
                    // Hundreds of f32 atomic adds per cell, in any order.
                    assert_like_reference(
                        "spread",
                        &p,
                        &[("positions", pos.clone()), ("values", vals.clone())],
                        1e-5,
                        &format!("spread {w} {extra} {variant} {lengths:?}"),
                    );
                }
                let p = params(w, &extra, &lengths, &cells, "auto");
                assert_like_reference(
                    "interpolate",
                    &p,
                    &[("grid", field.clone()), ("positions", pos.clone())],
                    1e-5,
                    &format!("interpolate {w} {extra} {lengths:?}"),
                );
                assert_like_reference(
                    "interpolate",
                    &p,
                    &[
                        ("grid", field.clone()),
                        ("positions", pos.clone()),
                        ("weights", quad.clone()),
                    ],
                    1e-5,
                    &format!("interpolate {w} {extra} with weights"),
                );
            }
        }
    }
}

#[test]
fn more_than_four_components_go_in_chunks() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(41);
    let lengths = [10.0, 10.0, 10.0];
    let cells = [12u32, 12, 12];
    let pos = positions(&mut rng, 200, &lengths);
    for comps in [5u32, 9] {
        let vals = rng.array(ValueType::Particles { n: 200, k: comps }, -1.0, 1.0);
        let field = rng.array(
            ValueType::RealGrid {
                dims: [12, 12, 12],
                comps,
            },
            -1.0,
            1.0,
        );
        let p = params("peskin4", "", &lengths, &cells, "auto");
        assert_like_reference(
            "spread",
            &p,
            &[("positions", pos.clone()), ("values", vals)],
            1e-5,
            &format!("spread {comps} components"),
        );
        assert_like_reference(
            "interpolate",
            &p,
            &[("grid", field), ("positions", pos.clone())],
            1e-5,
            &format!("interpolate {comps} components"),
        );
    }
}

#[test]
fn atomic_and_portable_spreading_agree() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(3);
    let lengths = [8.0, 8.0, 8.0];
    let cells = [16u32, 16, 16];
    // Dense and overlapping: many particles in one spot, plus coincident pairs.
    let mut pos = positions(&mut rng, 500, &lengths);
    if let mesoflow::value::HostData::F32(v) = &mut pos.data {
        for i in 0..100 {
            v[3 * i] = 0.01;
            v[3 * i + 1] = 0.02;
            v[3 * i + 2] = -0.03;
        }
    }
    let vals = rng.array(ValueType::Particles { n: 500, k: 1 }, 0.0, 1.0);
    let p_atomic = params("peskin4", "", &lengths, &cells, "atomic");
    let p_cas = params("peskin4", "", &lengths, &cells, "portable");
    let (a, r) = run_node(
        "spread",
        &p_atomic,
        &[("positions", pos.clone()), ("values", vals.clone())],
    );
    let (b, _) = run_node("spread", &p_cas, &[("positions", pos), ("values", vals)]);
    let (err, _) = rel_max_err(&a, &r);
    assert!(err < 1e-5, "{err}");
    let (diff, at) = rel_max_err(&a, &mesoflow::value::RefArray::new(b.ty, b.data.to_f64()));
    assert!(
        diff < 1e-5,
        "variants differ by {diff:e} at {at} (f32 summation order only)"
    );
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

#[test]
fn spreading_conserves_and_interpolation_is_its_adjoint() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(23);
    let lengths = [12.0, 9.0, 15.0];
    let cells = [24u32, 18, 30];
    let dv: f64 = (0..3).map(|a| lengths[a] / cells[a] as f64).product();
    let n = 400;
    let pos = positions(&mut rng, n, &lengths);
    let f = rng.array(ValueType::Particles { n, k: 2 }, -1.0, 1.0);
    let g = rng.array(
        ValueType::RealGrid {
            dims: [24, 18, 30],
            comps: 2,
        },
        -1.0,
        1.0,
    );
    for (w, extra) in WINDOWS {
        let p = params(w, extra, &lengths, &cells, "auto");
        let (sf, _) = run_node(
            "spread",
            &p,
            &[("positions", pos.clone()), ("values", f.clone())],
        );
        let (jg, _) = run_node(
            "interpolate",
            &p,
            &[("grid", g.clone()), ("positions", pos.clone())],
        );
        let (sf, jg, fv, gv) = (
            sf.data.to_f64(),
            jg.data.to_f64(),
            f.data.to_f64(),
            g.data.to_f64(),
        );
        // <S f, g>_dV = <f, J g>: the same weights on both sides, so f32 rounding only.
        let lhs = dv * dot(&sf, &gv);
        let rhs = dot(&fv, &jg);
        let scale = dv * sf.iter().zip(&gv).map(|(x, y)| (x * y).abs()).sum::<f64>();
        assert!(
            (lhs - rhs).abs() < 1e-5 * scale,
            "{w}: <Sf,g> = {lhs}, <f,Jg> = {rhs}"
        );
        // Conservation per component: sum_j (S f)_j dV = sum_i f_i. Peskin windows have
        // unit discrete mass exactly; the Gaussian and ES windows to their tolerance.
        let cells_n = sf.len() / 2;
        for c in 0..2 {
            let grid_total: f64 = sf[c * cells_n..(c + 1) * cells_n].iter().sum::<f64>() * dv;
            let particle_total: f64 = fv.iter().skip(c).step_by(2).sum();
            let abs_total: f64 = fv.iter().skip(c).step_by(2).map(|x| x.abs()).sum();
            let tol = if w.starts_with("peskin") { 1e-6 } else { 2e-4 };
            assert!(
                (grid_total - particle_total).abs() < tol * abs_total,
                "{w} component {c}: grid {grid_total} vs particles {particle_total}"
            );
        }
    }
}

#[test]
fn unwrapped_positions_wrap_like_their_images() {
    if gpu().is_none() {
        return;
    }
    let lengths = [10.0, 10.0, 10.0];
    let cells = [20u32, 20, 20];
    let base = [1.3f32, -2.2, 4.9];
    let shifted: Vec<f32> = base
        .iter()
        .zip([3.0f32, -2.0, 7.0])
        .map(|(x, k)| x + k * 10.0)
        .collect();
    let vals = HostArray::f32(ValueType::Particles { n: 1, k: 1 }, vec![1.0]);
    let p = params("peskin6", "", &lengths, &cells, "auto");
    let (a, _) = run_node(
        "spread",
        &p,
        &[
            (
                "positions",
                HostArray::f32(ValueType::Particles { n: 1, k: 3 }, base.to_vec()),
            ),
            ("values", vals.clone()),
        ],
    );
    let (b, _) = run_node(
        "spread",
        &p,
        &[
            (
                "positions",
                HostArray::f32(ValueType::Particles { n: 1, k: 3 }, shifted),
            ),
            ("values", vals),
        ],
    );
    let (diff, at) = rel_max_err(&a, &mesoflow::value::RefArray::new(b.ty, b.data.to_f64()));
    assert!(diff < 1e-5, "images differ by {diff:e} at {at}");
}

#[test]
fn no_particles_give_an_empty_grid_and_no_values() {
    if gpu().is_none() {
        return;
    }
    let lengths = [4.0, 4.0, 4.0];
    let cells = [8u32, 8, 8];
    let p = params("peskin4", "", &lengths, &cells, "auto");
    let pos = HostArray::f32(ValueType::Particles { n: 0, k: 3 }, vec![]);
    let vals = HostArray::f32(ValueType::Particles { n: 0, k: 1 }, vec![]);
    let (g, _) = run_node(
        "spread",
        &p,
        &[("positions", pos.clone()), ("values", vals)],
    );
    assert!(g.data.to_f64().iter().all(|&x| x == 0.0));
    let field = HostArray::f32(
        ValueType::RealGrid {
            dims: [8, 8, 8],
            comps: 1,
        },
        vec![1.0; 512],
    );
    let (u, _) = run_node("interpolate", &p, &[("grid", field), ("positions", pos)]);
    assert!(u.data.is_empty());
}

#[test]
fn bad_spread_params_are_plan_errors() {
    let dir = tmpdir("spread-params");
    let pos = ValueType::Particles { n: 4, k: 3 };
    for (params, inputs, want) in [
        (
            r#"{"box": [4, 4, 4], "grid": [8, 8, 8], "window": "gaussian"}"#,
            [("positions", pos), ("values", pos)],
            "needs `width`",
        ),
        (
            r#"{"box": [4, 4, 4], "grid": [4, 4, 4], "window": "peskin6"}"#,
            [("positions", pos), ("values", pos)],
            "fewer than the window's support",
        ),
        (
            r#"{"box": [4, 4], "grid": [8, 8], "window": "peskin4"}"#,
            [("positions", pos), ("values", pos)],
            "has 3 columns but the box has 2 axes",
        ),
        (
            r#"{"box": [4, 4, 4], "grid": [8, 8, 8], "window": "gaussian", "width": 2, "tolerance": 1e-14}"#,
            [("positions", pos), ("values", pos)],
            "more than the 32 supported",
        ),
    ] {
        let path = write_graph(
            &dir,
            "g.json",
            &single_node_graph("spread", params, &inputs),
        );
        let e = mesoflow::plan::validate_file(crate::util::registry(), &path)
            .unwrap_err()
            .to_string();
        assert!(e.contains(want), "{params}: {e}");
    }
}

#[test]
fn folded_dispatches_serve_every_particle_once() {
    // More workgroups than one dispatch dimension holds fold over (x, y); the grid then
    // rounds up past the particle slots, and those extra slots must stay empty. A small
    // dimension cap makes a small problem take that path.
    let Some(mut gpu) = gpu() else { return };
    let mut rng = Rng::new(12);
    let lengths = [8.0, 8.0, 8.0];
    let cells = [16u32, 16, 16];
    // 54 particles: 13 runs of 5 slots, 65 slots, which 3-wide rows round up to 66.
    let pos = positions(&mut rng, 54, &lengths);
    let vals = rng.array(ValueType::Particles { n: 54, k: 1 }, 0.5, 1.5);
    let field = rng.array(
        ValueType::RealGrid {
            dims: [16, 16, 16],
            comps: 1,
        },
        -1.0,
        1.0,
    );
    let data_s: BTreeMap<String, HostArray> = [
        ("positions".into(), pos.clone()),
        ("values".into(), vals.clone()),
    ]
    .into_iter()
    .collect();
    let data_i: BTreeMap<String, HostArray> = [
        ("grid".into(), field.clone()),
        ("positions".into(), pos.clone()),
    ]
    .into_iter()
    .collect();
    for (w, extra) in [("peskin6", ""), ("peskin3", "")] {
        let p = params(w, extra, &lengths, &cells, "auto");
        let (s, i) = crate::util::with_caps(
            &mut gpu,
            |c| c.max_workgroups_per_dim = 3,
            |g| {
                (
                    crate::util::run_node(g, "spread", &p, &data_s),
                    crate::util::run_node(g, "interpolate", &p, &data_i),
                )
            },
        );
        let rs = reference("spread", &p, &[Some(&pos), Some(&vals)]).remove(0);
        let ri = reference("interpolate", &p, &[Some(&field), Some(&pos), None]).remove(0);
        assert!(
            rel_max_err(&s["out"], &rs).0 < 1e-5,
            "{w}: spread with folded dispatch"
        );
        assert!(
            rel_max_err(&i["out"], &ri).0 < 1e-5,
            "{w}: interpolate with folded dispatch"
        );
    }
}

#[test]
fn every_workgroup_size_gives_the_same_grid() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(77);
    let lengths = [12.0, 10.0, 8.0];
    let cells = [24u32, 20, 16];
    let pos = positions(&mut rng, 700, &lengths);
    let vals = rng.array(ValueType::Particles { n: 700, k: 2 }, -1.0, 1.0);
    let field = rng.array(
        ValueType::RealGrid {
            dims: [24, 20, 16],
            comps: 2,
        },
        -1.0,
        1.0,
    );
    for (w, extra) in WINDOWS {
        for wg in ["64", "128"] {
            let extra = with(extra, &format!(r#""workgroup": "{wg}""#));
            let p = params(w, &extra, &lengths, &cells, "auto");
            assert_like_reference(
                "spread",
                &p,
                &[("positions", pos.clone()), ("values", vals.clone())],
                1e-5,
                &format!("spread {w} workgroup {wg}"),
            );
            assert_like_reference(
                "interpolate",
                &p,
                &[("grid", field.clone()), ("positions", pos.clone())],
                1e-5,
                &format!("interpolate {w} workgroup {wg}"),
            );
        }
    }
}

/// Sorts particle rows by the Morton order of their cells (what cell_hash + sort give).
fn morton_sorted(pos: &HostArray, lengths: &[f64], cells: &[u32]) -> HostArray {
    let d = lengths.len();
    let v: Vec<f32> = match &pos.data {
        mesoflow::value::HostData::F32(v) => v.clone(),
        _ => unreachable!(),
    };
    let key = |row: &[f32]| -> u64 {
        let mut k = 0u64;
        for a in 0..d {
            let c = (((row[a] as f64 / lengths[a] + 0.5) * cells[a] as f64).floor() as i64)
                .rem_euclid(cells[a] as i64) as u64;
            for b in 0..16 {
                k |= ((c >> b) & 1) << (b * d + a);
            }
        }
        k
    };
    let mut rows: Vec<&[f32]> = v.chunks(d).collect();
    rows.sort_by_key(|r| key(r));
    HostArray::f32(pos.ty, rows.concat())
}

#[test]
fn sorted_input_spreading_matches_the_reference() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(58);
    // Sparse (boxes of 64 sorted particles often exceed 16 cells: the direct path) and
    // dense (boxes fit) placements, 3-D and 2-D.
    for (lengths, cells, n) in [
        (vec![20.0, 14.0, 9.0], vec![32u32, 20, 12], 1500),
        (vec![8.0, 9.0, 7.0], vec![16u32, 18, 14], 3000),
        (vec![30.0, 10.0], vec![48u32, 16], 1500),
    ] {
        let random = positions(&mut rng, n, &lengths);
        let sorted = morton_sorted(&random, &lengths, &cells);
        for comps in [1u32, 3, 5] {
            let vals = rng.array(ValueType::Particles { n, k: comps }, -1.0, 1.0);
            let field = rng.array(
                ValueType::RealGrid {
                    dims: [cells[0], cells[1], cells.get(2).copied().unwrap_or(1)],
                    comps,
                },
                -1.0,
                1.0,
            );
            for (w, extra) in WINDOWS {
                let extra = with(extra, r#""sorted_input": true"#);
                for variant in ["atomic", "portable"] {
                    let p = params(w, &extra, &lengths, &cells, variant);
                    // Interpolation takes no sorted_input: it serves sorted input with
                    // its usual kernel.
                    let p_interp = p
                        .replace(r#", "sorted_input": true"#, "")
                        .replace(r#""sorted_input": true, "#, "");
                    // Sorted (the box path) and random (mostly the direct path) input.
                    for pos in [&sorted, &random] {
                        assert_like_reference(
                            "spread",
                            &p,
                            &[("positions", pos.clone()), ("values", vals.clone())],
                            1e-5,
                            &format!("box spread {w} {variant} {comps} comps {lengths:?}"),
                        );
                        assert_like_reference(
                            "interpolate",
                            &p_interp,
                            &[("grid", field.clone()), ("positions", pos.clone())],
                            1e-5,
                            &format!(
                                "interpolate of sorted input {w} {variant} {comps} comps {lengths:?}"
                            ),
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn boxes_wrap_across_the_periodic_faces() {
    if gpu().is_none() {
        return;
    }
    // Particles on both sides of every face, in every workgroup, dense enough (about 1
    // per cell) to spread box by box: the box must use the minimal image of their cells,
    // or it would span the whole grid.
    let lengths = [8.0, 8.0, 8.0];
    let cells = [8u32, 8, 8];
    let n = 600;
    let mut v = Vec::new();
    for i in 0..n {
        let s = if i % 2 == 0 { 3.95 } else { -3.95 };
        let d = 0.001 * (i % 97) as f32;
        v.extend([s - d, -s + d, s - 0.5 * d]);
    }
    let pos = HostArray::f32(ValueType::Particles { n, k: 3 }, v);
    let vals = HostArray::f32(
        ValueType::Particles { n, k: 1 },
        (0..n).map(|i| 1.0 + (i % 13) as f32).collect(),
    );
    for (w, extra) in [
        ("peskin6", ""),
        ("gaussian", r#""width": 0.4, "tolerance": 1e-4"#),
    ] {
        let extra = with(extra, r#""sorted_input": true"#);
        let p = params(w, &extra, &lengths, &cells, "auto");
        assert_like_reference(
            "spread",
            &p,
            &[("positions", pos.clone()), ("values", vals.clone())],
            1e-5,
            w,
        );
    }
}

#[test]
fn interpolation_reductions_agree_on_every_segment_width() {
    if gpu().is_none() {
        return;
    }
    // Lane kernels (supports up to the subgroup width: several particles per subgroup,
    // one, and one column or several per lane), the workgroup-table kernel's segments of
    // 4 (support 2) to 64 threads (lanes off, and supports wider than the subgroup):
    // narrower than a subgroup (the shuffle-only path), wider (shuffles plus one
    // workgroup step), and the workgroup-memory tree of the portable variant.
    let mut rng = Rng::new(99);
    let lengths = [10.0, 10.0, 10.0];
    let cells = [20u32, 20, 20];
    let pos = positions(&mut rng, 400, &lengths);
    let field = rng.array(
        ValueType::RealGrid {
            dims: [20, 20, 20],
            comps: 3,
        },
        -1.0,
        1.0,
    );
    let windows = [
        ("gaussian", r#""width": 0.25, "support": 2"#),
        ("peskin3", ""),
        ("peskin4", ""),
        ("gaussian", r#""width": 0.6, "support": 8"#),
        ("gaussian", r#""width": 0.9, "support": 11"#),
    ];
    for (w, extra) in windows {
        for (variant, lanes) in [("auto", "auto"), ("auto", "off"), ("portable", "auto")] {
            for wg in ["64", "256"] {
                let extra = with(
                    extra,
                    &format!(r#""workgroup": "{wg}", "lanes": "{lanes}""#),
                );
                let p = params(w, &extra, &lengths, &cells, variant);
                assert_like_reference(
                    "interpolate",
                    &p,
                    &[("grid", field.clone()), ("positions", pos.clone())],
                    1e-5,
                    &format!("interpolate {w} {extra} {variant}"),
                );
            }
        }
    }
}

/// Window params of the tile tests: every window at a support of at most 8.
const TILE_WINDOWS: &[(&str, &str)] = &[
    ("gaussian", r#""width": 0.6, "support": 8"#),
    ("es", r#""support": 6"#),
    ("peskin3", ""),
    ("peskin4", ""),
    ("peskin6", ""),
];

#[test]
fn tiled_spreading_matches_the_reference() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(71);
    // Whole and partial tiles (20 cells: two and a half tiles of 8), and a grid smaller
    // than a padded tile (6 cells against 8 + 6 - 1: padded cells wrap onto the same grid
    // cell several times).
    for (lengths, cells, n) in [
        (vec![20.0, 14.0, 9.0], vec![32u32, 20, 12], 1500),
        (vec![8.0, 9.0, 7.0], vec![16u32, 18, 14], 3000),
        (vec![3.0, 3.0, 3.0], vec![6u32, 6, 6], 200),
    ] {
        let random = positions(&mut rng, n, &lengths);
        let sorted = morton_sorted(&random, &lengths, &cells);
        // 5 components go in several tile dispatches (as many as workgroup memory holds).
        for comps in [1u32, 5] {
            let vals = rng.array(ValueType::Particles { n, k: comps }, -1.0, 1.0);
            // Supports up to 8: the tiles need a subgroup lane per support cell (8 on
            // lavapipe).
            for (w, extra) in TILE_WINDOWS {
                if cells[0] < 8 && *w == "gaussian" {
                    continue; // support 8 > 6 cells
                }
                for variant in ["atomic", "portable"] {
                    let p = params(
                        w,
                        &with(extra, r#""tiles": "on""#),
                        &lengths,
                        &cells,
                        variant,
                    );
                    for pos in [&random, &sorted] {
                        assert_like_reference(
                            "spread",
                            &p,
                            &[("positions", pos.clone()), ("values", vals.clone())],
                            TOL,
                            &format!("tiled spread {w} {variant} {comps} comps {cells:?}"),
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn tiled_spreading_of_hard_placements() {
    if gpu().is_none() {
        return;
    }
    let lengths = [8.0, 8.0, 8.0];
    let cells = [16u32, 16, 16];
    let h = 0.5f32;
    // Particles exactly on cell faces and centres, on the box faces (-L/2 and +L/2, the
    // same place), coincident in numbers, and one alone: every tile's anchor edge cases.
    let mut v = Vec::new();
    for i in 0..64 {
        let f = i as f32;
        v.extend([-4.0 + h * f, -4.0 + 0.5 * h * f, 4.0 - h * (f % 5.0)]);
    }
    for _ in 0..300 {
        v.extend([1.25f32, -0.75, 2.0]);
    }
    v.extend([4.0f32, 4.0, 4.0, -4.0, -4.0, -4.0, 0.0, 0.0, 0.0]);
    let n = (v.len() / 3) as u32;
    let pos = HostArray::f32(ValueType::Particles { n, k: 3 }, v);
    let vals = HostArray::f32(
        ValueType::Particles { n, k: 2 },
        (0..2 * n).map(|i| ((i % 7) as f32 - 3.0) * 0.5).collect(),
    );
    for (w, extra) in [
        ("peskin4", ""),
        ("gaussian", r#""width": 0.5, "support": 8"#),
    ] {
        let p = params(
            w,
            &with(extra, r#""tiles": "on""#),
            &lengths,
            &cells,
            "auto",
        );
        assert_like_reference(
            "spread",
            &p,
            &[("positions", pos.clone()), ("values", vals.clone())],
            TOL,
            &format!("hard placements, {w}"),
        );
        // One particle, and a single value: the smallest tiles.
        let one = HostArray::f32(ValueType::Particles { n: 1, k: 3 }, vec![3.99, -4.0, 0.25]);
        let one_val = HostArray::f32(ValueType::Particles { n: 1, k: 1 }, vec![2.5]);
        assert_like_reference(
            "spread",
            &p,
            &[("positions", one), ("values", one_val)],
            TOL,
            &format!("one particle, {w}"),
        );
    }
}

#[test]
fn tiles_keep_small_and_extreme_values() {
    if gpu().is_none() {
        return;
    }
    let lengths = [8.0, 8.0, 8.0];
    let cells = [16u32, 16, 16];
    let mut rng = Rng::new(5);
    let n = 400;
    let pos = positions(&mut rng, n, &lengths);
    let p = params("peskin6", r#""tiles": "on""#, &lengths, &cells, "auto");
    // Values far below the fixed-point scale's floor (the tiles spread these directly with
    // grid atomics), far above any f32 sum of ordinary values, and all zero.
    for scale in [1e-35f32, 1e30, 0.0] {
        let vals = HostArray::f32(
            ValueType::Particles { n, k: 1 },
            (0..n).map(|i| scale * (1.0 + (i % 5) as f32)).collect(),
        );
        let (g, r) = run_node(
            "spread",
            &p,
            &[("positions", pos.clone()), ("values", vals)],
        );
        let (err, at) = rel_max_err(&g, &r);
        assert!(err < TOL, "values of {scale:e}: error {err:e} at {at}");
        if scale == 0.0 {
            assert!(
                g.data.to_f64().iter().all(|&x| x == 0.0),
                "zeros spread to nonzero"
            );
        }
    }
    // A NaN value reaches the grid (never a silently finite grid).
    let mut nan = vec![1.0f32; n as usize];
    nan[17] = f32::NAN;
    let vals = HostArray::f32(ValueType::Particles { n, k: 1 }, nan);
    let (g, _) = run_node("spread", &p, &[("positions", pos), ("values", vals)]);
    assert!(
        g.data.to_f64().iter().any(|x| x.is_nan()),
        "a NaN value vanished"
    );
}

#[test]
fn tiles_lose_at_most_their_documented_share_of_a_tile() {
    if gpu().is_none() {
        return;
    }
    // A heavy particle and a light one in the same tile (anchors 0 and 4 along each axis:
    // cells 0-3 and 4-7): the light one's cells are exact to 2^-30 of the tile's bound
    // B = PEAK x sum |v| (one add each, rounded to half a step of B / 2^30, and the f32
    // result), not to f32 rounding of their own values.
    let lengths = [8.0, 8.0, 8.0];
    let cells = [16u32, 16, 16];
    let pos = HostArray::f32(
        ValueType::Particles { n: 2, k: 3 },
        vec![-3.0, -3.0, -3.0, -0.85, -0.9, -0.95],
    );
    let vals = HostArray::f32(ValueType::Particles { n: 2, k: 1 }, vec![1e4, 1e-3]);
    let p = params("peskin4", r#""tiles": "on""#, &lengths, &cells, "auto");
    let (g, r) = run_node("spread", &p, &[("positions", pos), ("values", vals)]);
    // Peskin's 4-point window peaks at 1/2 per cell, over h = 0.5: 1 per axis.
    let peak = (0.5f64 / 0.5).powi(3);
    let step = peak * (1e4 + 1e-3) / (1u64 << 30) as f64;
    let g = g.data.to_f64();
    let mut light = 0;
    for (a, b) in g.iter().zip(&r.data) {
        if *b != 0.0 && b.abs() < 1.0 {
            light += 1;
            assert!(
                (a - b).abs() <= step,
                "light cell {a:e} against {b:e}: step {step:e}"
            );
        }
    }
    assert_eq!(light, 64, "the light particle's support");
}
