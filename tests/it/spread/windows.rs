//! Every window against the f64 reference on every kernel path: single particles (the
//! separable product exactly), random particles in 2D and 3D, both variants, lanes and
//! workgroup tables, workgroup sizes, components in chunks, interpolation's segment
//! widths, sorted input spread box by box across the periodic faces.

use mesoflow::value::{HostArray, ValueType};

use crate::util::spread::{TOL, WINDOWS, morton_sorted, params, positions, with};
use crate::util::{Rng, assert_like_reference, gpu, rel_max_err, run_out};

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
    let (a, r) = run_out(
        "spread",
        &p_atomic,
        &[("positions", pos.clone()), ("values", vals.clone())],
    );
    let (b, _) = run_out("spread", &p_cas, &[("positions", pos), ("values", vals)]);
    let (err, _) = rel_max_err(&a, &r);
    assert!(err < 1e-5, "{err}");
    let (diff, at) = rel_max_err(&a, &mesoflow::value::RefArray::new(b.ty, b.data.to_f64()));
    assert!(
        diff < 1e-5,
        "variants differ by {diff:e} at {at} (f32 summation order only)"
    );
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

/// A support wider than the grid (a box of 3a under FCM's Gaussian: 5 cells, support 9)
/// wraps the window around the periodic grid more than once: every kernel path (lanes,
/// workgroup tables, boxes for dense sorted input, tiles; float atomics and
/// compare-and-swap) and interpolation agree with the f64 reference, which wraps each
/// support cell on its own. Before, the node refused such a grid ("cells along axis 0
/// are fewer than the window's support").
#[test]
fn supports_wider_than_the_grid_wrap_like_the_reference() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(91);
    for (lengths, cells) in [
        (vec![3.0, 3.5, 2.2], vec![5u32, 4, 3]),
        (vec![2.0, 3.0], vec![3u32, 4]),
        (vec![1.0, 1.0, 1.0], vec![1u32, 2, 1]),
    ] {
        let n = 200;
        let random = positions(&mut rng, n, &lengths);
        let sorted = morton_sorted(&random, &lengths, &cells);
        let vals = rng.array(ValueType::Particles { n, k: 3 }, -1.0, 1.0);
        let mut dims = [1u32; 3];
        dims[..cells.len()].copy_from_slice(&cells);
        let field = rng.array(ValueType::RealGrid { dims, comps: 3 }, -1.0, 1.0);
        for (w, extra) in [
            ("gaussian", r#""width": 0.56, "support": 9"#),
            ("gaussian", r#""width": 0.3, "support": 4"#),
            ("es", r#""support": 6"#),
            ("peskin6", ""),
        ] {
            let mut spreads = vec![
                with(extra, r#""lanes": "auto""#),
                with(extra, r#""lanes": "off""#),
                with(extra, r#""sorted_input": true"#),
            ];
            if lengths.len() == 3 && !extra.contains("\"support\": 9") {
                // Tiles take subgroups as wide as the support (8 lanes on lavapipe).
                spreads.push(with(extra, r#""tiles": "on""#));
            }
            for spread in &spreads {
                for variant in ["atomic", "portable"] {
                    let p = params(w, spread, &lengths, &cells, variant);
                    for pos in [&random, &sorted] {
                        assert_like_reference(
                            "spread",
                            &p,
                            &[("positions", pos.clone()), ("values", vals.clone())],
                            1e-5,
                            &format!("spread {w} {spread} {variant} on {cells:?}"),
                        );
                    }
                }
            }
            for lanes in ["auto", "off"] {
                let p = params(
                    w,
                    &with(extra, &format!(r#""lanes": "{lanes}""#)),
                    &lengths,
                    &cells,
                    "auto",
                );
                assert_like_reference(
                    "interpolate",
                    &p,
                    &[("grid", field.clone()), ("positions", random.clone())],
                    1e-5,
                    &format!("interpolate {w} {extra} lanes {lanes} on {cells:?}"),
                );
            }
        }
    }
}
