//! `sort` against its CPU reference (a stable sort by the low `bits` bits) on the GPU, with
//! every variant: sorted keys and permutation must match exactly.

use std::collections::BTreeMap;

use mesoflow::gpu::GpuContext;
use mesoflow::value::HostArray;

use crate::util::{
    ANY_U32, Rng, compile_error, gpu, indices, random_keys, reference, run_node, with_caps,
};

/// Every variant but `auto` (which runs one of them).
const PATHS: [&str; 4] = ["tile4096", "tile2048", "subgroup", "portable"];

/// Lengths at tile boundaries: keys per tile of the variants (nodes/sort.rs) and 3072.
const TILES: [usize; 4] = [4096, 3072, 2048, 3840];
const SUBGROUP_TILE: usize = 3840;

/// Sorts `keys` by their low `bits` bits on the given path and compares keys and
/// permutation with the reference, element by element.
fn check_on(gpu: &GpuContext, keys: &[u32], bits: u32, path: &str) {
    let params = format!(r#"{{"bits": {bits}, "variant": "{path}"}}"#);
    let x = indices(keys);
    let inputs: BTreeMap<String, HostArray> = [("keys".to_string(), x.clone())].into();
    let got = run_node(gpu, "sort", &params, &inputs);
    let want = reference("sort", &params, &[Some(&x)]);
    for (port, w) in ["keys", "perm"].iter().zip(&want) {
        let g = &got[*port];
        let w = w.to_host();
        assert_eq!(g.ty, w.ty, "{port}");
        if g.data != w.data {
            let (mesoflow::value::HostData::U32(g), mesoflow::value::HostData::U32(w)) =
                (&g.data, &w.data)
            else {
                panic!("sort outputs are index arrays");
            };
            let i = (0..g.len()).find(|&i| g[i] != w[i]).unwrap_or(0);
            panic!(
                "sort ({path}, bits {bits}) of {} keys: {port}[{i}] is {}, expected {}",
                keys.len(),
                g[i],
                w[i]
            );
        }
    }
}

fn check(keys: &[u32], bits: u32, path: &str) {
    if let Some(gpu) = gpu() {
        check_on(&gpu, keys, bits, path);
    }
}

#[test]
fn random_keys_at_every_tile_boundary() {
    let mut sizes = vec![0, 1, 2, 3, 100, 1000];
    for tile in TILES {
        for k in [1, 2, 3] {
            sizes.extend([k * tile - 1, k * tile, k * tile + 1]);
        }
    }
    for path in PATHS {
        for (i, &n) in sizes.iter().enumerate() {
            check(&random_keys(n, ANY_U32, i as u64), 32, path);
        }
    }
}

#[test]
fn equal_keys_keep_their_input_order() {
    for path in PATHS {
        for key in [0, 7, u32::MAX] {
            check(&vec![key; 10_000], 32, path);
        }
        // One tile's worth of equal keys, then a lone smaller one: every earlier key moves.
        let mut shifted = vec![9; 4096];
        shifted.push(3);
        check(&shifted, 32, path);
        // Few distinct keys: long runs of equal ones in every tile.
        let few: Vec<u32> = random_keys(50_000, ANY_U32, 3)
            .iter()
            .map(|k| k % 5)
            .collect();
        check(&few, 32, path);
    }
}

#[test]
fn extreme_sorted_and_reversed_keys() {
    let mut rng = Rng::new(4);
    let extremes: Vec<u32> = (0..5000)
        .map(|_| [0, 1, u32::MAX - 1, u32::MAX][(rng.next_u64() % 4) as usize])
        .collect();
    let ascending: Vec<u32> = (0..9000).collect();
    let descending: Vec<u32> = (0..9000).rev().map(|k| k * 477_211).collect();
    for path in PATHS {
        check(&extremes, 32, path);
        check(&ascending, 32, path);
        check(&descending, 32, path);
        check(&[u32::MAX, 0], 32, path);
    }
}

#[test]
fn fewer_bits_sort_by_the_low_bits_only() {
    // Full-range keys: the bits above `bits` are set and must be ignored, yet kept.
    let keys = random_keys(20_000, ANY_U32, 5);
    for path in PATHS {
        for bits in [1, 3, 4, 5, 8, 9, 20, 31] {
            check(&keys, bits, path);
        }
    }
}

#[test]
fn many_tiles() {
    for path in PATHS {
        check(&random_keys(300_000, ANY_U32, 6), 32, path);
    }
    // A cell-hash-like sort: 22-bit keys, many particles per cell.
    let cells: Vec<u32> = random_keys(200_000, ANY_U32, 7)
        .iter()
        .map(|k| k >> 14)
        .collect();
    check(&cells, 22, "auto");
}

#[test]
fn sorts_fold_their_dispatches_past_the_workgroup_cap() {
    let Some(mut gpu) = gpu() else { return };
    // 7 to 14 tiles on 3 workgroups per dimension (and 256 `offsets` workgroups).
    let keys = random_keys(7 * SUBGROUP_TILE + 5, ANY_U32, 8);
    with_caps(
        &mut gpu,
        |c| c.max_workgroups_per_dim = 3,
        |gpu| {
            for path in PATHS {
                check_on(gpu, &keys, 32, path);
                check_on(gpu, &keys, 12, path);
            }
        },
    );
}

#[test]
fn auto_runs_without_subgroups_and_subgroup_fails_clearly() {
    let Some(mut gpu) = gpu() else { return };
    let keys = random_keys(5000, ANY_U32, 9);
    with_caps(
        &mut gpu,
        |c| c.subgroups = None,
        |gpu| {
            check_on(gpu, &keys, 32, "auto");
            let inputs = [("keys".to_string(), indices(&keys))].into();
            for v in ["subgroup", "tile4096"] {
                let params = format!(r#"{{"variant": "{v}"}}"#);
                let err = compile_error(gpu, "sort", &params, &inputs);
                assert!(
                    err.contains(&format!("variant `{v}` cannot run"))
                        && err.contains("no subgroup operations"),
                    "{err}"
                );
            }
        },
    );
}

#[test]
fn the_subgroup_path_follows_the_reported_subgroup_sizes() {
    let Some(mut gpu) = gpu() else { return };
    let Some((min, _)) = gpu.caps.subgroups else {
        return;
    };
    let keys = random_keys(3 * SUBGROUP_TILE + 17, ANY_U32, 10);
    // Subgroups that may be wider than 32 lanes: four-word ballot masks, same result.
    with_caps(
        &mut gpu,
        |c| c.subgroups = Some((min, 128)),
        |gpu| {
            for path in ["tile4096", "tile2048", "subgroup"] {
                check_on(gpu, &keys, 32, path);
            }
        },
    );
    // Too little workgroup memory for the counters of 4-lane subgroups: auto falls back.
    with_caps(
        &mut gpu,
        |c| {
            c.subgroups = Some((4, 128));
            c.max_workgroup_storage = 32 << 10;
        },
        |gpu| {
            check_on(gpu, &keys, 32, "auto");
            let inputs = [("keys".to_string(), indices(&keys))].into();
            for v in ["subgroup", "tile4096"] {
                let params = format!(r#"{{"variant": "{v}"}}"#);
                let err = compile_error(gpu, "sort", &params, &inputs);
                assert!(err.contains("bytes of workgroup memory"), "{err}");
            }
        },
    );
}

#[test]
fn the_bench_times_and_checks_every_variant() {
    let bench = |args: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_mesoflow"))
            .args(args)
            .env("XDG_RUNTIME_DIR", std::env::temp_dir())
            .output()
            .expect("run mesoflow")
    };
    let o = bench(&["bench", "sort", "--variant", "tile1"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("expected all or one of auto, tile4096"),
        "{err}"
    );

    // Holding the shared context keeps the other GPU tests off the CPU meanwhile.
    let Some(_gpu) = gpu() else { return };
    let o = bench(&[
        "bench",
        "sort",
        "--n",
        "5000",
        "--reps",
        "2",
        "--variant",
        "all",
    ]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{out}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    for v in PATHS.iter().chain(&["auto"]) {
        assert!(
            out.contains(&format!("sort u32 keys + perm ({v})")),
            "{v}:\n{out}"
        );
    }
}
