//! Tiled spreading (fixed-point sums per tile in workgroup memory) against the f64
//! reference: whole and partial tiles, grids smaller than a padded tile, hard placements,
//! tiny, huge, zero and NaN values, and the documented precision.

use mesoflow::value::{HostArray, ValueType};

use crate::util::spread::{TOL, morton_sorted, params, positions, with};
use crate::util::{Rng, assert_like_reference, gpu, rel_max_err, run_out};

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
        let (g, r) = run_out(
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
    let (g, _) = run_out("spread", &p, &[("positions", pos), ("values", vals)]);
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
    let (g, r) = run_out("spread", &p, &[("positions", pos), ("values", vals)]);
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
