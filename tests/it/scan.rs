//! `scan` against its CPU reference on the GPU, on both kernel paths: u32 exactly
//! (sums wrap mod 2^32), f32 element-wise within the error bound of its addition tree.

use std::collections::BTreeMap;

use mesoflow::gpu::GpuContext;
use mesoflow::value::{HostArray, HostData, ValueType};

use crate::util::{
    ANY_U32, Rng, compile_error, gpu, indices, random_keys, reference, run_node, with_caps,
};

const PATHS: [&str; 2] = ["subgroup", "portable"];

/// Elements per tile of the scan kernels (nodes/scan.rs).
const TILE: u64 = 4096;

/// Depth of the f32 addition tree per level of tile sums, bounded: 3 adds inside a vec4,
/// 2 for a vec4's sum, 4 row carries, two subgroup operations of at most 31 adds each
/// (sequential, for subgroups of up to 32 lanes), 8 subgroup partials and the tile offset
/// make 80 on the subgroup path; 3 + 16 sequential adds, 8 Hillis-Steele steps and the
/// offset make 28 on the portable one. 128 covers both with room.
const DEPTH_PER_LEVEL: f64 = 128.0;

fn levels(len: u64) -> u32 {
    let mut l = 1;
    let mut m = len;
    while m > TILE {
        m = m.div_ceil(TILE);
        l += 1;
    }
    l
}

/// Runs `scan` on `x` with the given kernel path and compares with the CPU reference:
/// u32 exactly; f32 with |gpu_i - ref_i| <= D * levels * 2^-24 * sum_{j<i} |x_j|, the
/// first-order bound of a sum along an addition tree of depth D (Higham, Accuracy and
/// Stability of Numerical Algorithms, 4.2).
fn check_on(gpu: &GpuContext, x: &HostArray, path: &str) {
    let params = format!(r#"{{"variant": "{path}"}}"#);
    let inputs: BTreeMap<String, HostArray> = [("x".to_string(), x.clone())].into();
    let got = &run_node(gpu, "scan", &params, &inputs)["out"];
    let want = &reference("scan", &params, &[Some(x)])[0];
    assert_eq!(got.ty, x.ty);
    let what = format!("scan ({path}) of {}", x.ty);
    match (&got.data, &x.data) {
        (HostData::U32(g), HostData::U32(_)) => {
            let HostData::U32(w) = want.to_host().data else {
                unreachable!("the reference of an index array is an index array")
            };
            if let Some(i) = (0..g.len()).find(|&i| g[i] != w[i]) {
                panic!("{what}: element {i} is {}, expected {}", g[i], w[i]);
            }
        }
        (HostData::F32(g), HostData::F32(xs)) => {
            let tol = DEPTH_PER_LEVEL * levels(xs.len() as u64) as f64 * f32::EPSILON as f64 / 2.0;
            let mut magnitude = 0.0f64;
            for (i, (&gi, &xi)) in g.iter().zip(xs).enumerate() {
                let err = (gi as f64 - want.data[i]).abs();
                assert!(
                    err <= tol * magnitude,
                    "{what}: element {i} is {gi}, expected {} (error {err:e} > {:e})",
                    want.data[i],
                    tol * magnitude
                );
                magnitude += (xi as f64).abs();
            }
        }
        _ => panic!("{what}: element type changed"),
    }
}

fn check(x: &HostArray, path: &str) {
    if let Some(gpu) = gpu() {
        check_on(&gpu, x, path);
    }
}

/// `n` random full-range words (seeded).
fn random_u32(n: u64, seed: u64) -> HostArray {
    indices(&random_keys(n as usize, ANY_U32, seed))
}

#[test]
fn u32_scans_match_exactly_at_every_length() {
    let lens = [
        0,
        1,
        2,
        3,
        4,
        5,
        7,
        255,
        256,
        1023,
        TILE - 1,
        TILE,
        TILE + 1,
        2 * TILE,
        3 * TILE + 7,
        100_003,
    ];
    for path in PATHS {
        for (i, &n) in lens.iter().enumerate() {
            // Random full-range words: the sums wrap many times.
            check(&random_u32(n, i as u64), path);
        }
    }
}

#[test]
fn u32_scans_of_constant_arrays() {
    for path in PATHS {
        check(&indices(&vec![1; 100_003]), path);
        check(&indices(&vec![0; 5000]), path);
        check(&indices(&vec![u32::MAX; 9000]), path);
    }
}

#[test]
fn f32_scans_stay_within_their_error_bound() {
    let p = |n, k| ValueType::Particles { n, k };
    let types = [
        p(0, 3),
        p(1, 1),
        p(1, 3),
        p(1365, 3),
        p(33_334, 3),
        ValueType::RealGrid {
            dims: [16, 16, 16],
            comps: 2,
        },
        ValueType::Scalar,
    ];
    let mut rng = Rng::new(11);
    for path in PATHS {
        for ty in types {
            check(&rng.array(ty, 0.5, 2.0), path);
            check(&rng.array(ty, -1.0, 1.0), path);
        }
    }
}

#[test]
fn scans_fold_their_dispatches_past_the_workgroup_cap() {
    let Some(mut gpu) = gpu() else { return };
    // 11 tiles on a device that takes 3 workgroups per dimension: a 3 x 4 grid.
    let x = random_u32(10 * TILE + 1, 5);
    let y = Rng::new(6).array(ValueType::Particles { n: 12_000, k: 4 }, -1.0, 1.0);
    with_caps(
        &mut gpu,
        |c| c.max_workgroups_per_dim = 3,
        |gpu| {
            for path in PATHS {
                check_on(gpu, &x, path);
                check_on(gpu, &y, path);
            }
        },
    );
}

#[test]
fn scans_recurse_over_three_levels_of_tile_sums() {
    // TILE^2 + 1 elements: tile sums of tile sums before a single tile.
    let x = random_u32(TILE * TILE + 1, 9);
    assert_eq!(levels(TILE * TILE + 1), 3);
    check(&x, "subgroup");
}

#[test]
fn auto_runs_without_subgroups_and_subgroup_fails_clearly() {
    let Some(mut gpu) = gpu() else { return };
    let x = random_u32(3 * TILE + 3, 2);
    with_caps(
        &mut gpu,
        |c| c.subgroups = None,
        |gpu| {
            check_on(gpu, &x, "auto");
            let inputs = [("x".to_string(), x.clone())].into();
            let err = compile_error(gpu, "scan", r#"{"variant": "subgroup"}"#, &inputs);
            assert!(
                err.contains("variant `subgroup` cannot run")
                    && err.contains("no subgroup operations"),
                "{err}"
            );
        },
    );
}
