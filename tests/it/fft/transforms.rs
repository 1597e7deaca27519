//! FFT nodes against rustfft in f64 (through their CPU references), round trips, and the
//! Hermitian consistency of the real transforms. Data-driven: one `check` line per case.

use mesoflow::value::{HostArray, ValueType};

use crate::util::fft::{chain, seed};
use crate::util::{
    Rng, gpu, load, load_single_node, reference, rel_l2, run_cached, single_node_graph, tmpdir,
    write_graph,
};

fn grid(kind: &str, dims: [u32; 3], comps: u32) -> ValueType {
    match kind {
        "fft" | "ifft" => ValueType::ComplexGrid { dims, comps },
        "rfft" => ValueType::RealGrid { dims, comps },
        _ => ValueType::HalfComplexGrid { dims, comps },
    }
}

/// f32 transforms: the relative L2 error grows like eps log2(N) (about 1e-7 here); the
/// bounds are the issue's: 2e-6 up to 256 points per axis, 5e-6 up to 512 (and beyond).
fn tolerance(dims: [u32; 3]) -> f64 {
    if dims.iter().all(|&d| d <= 256) {
        2e-6
    } else {
        5e-6
    }
}

/// Transform `kind` over `axes` of seeded random data (uniform in [-1, 1)) against its
/// f64 reference.
fn check(kind: &str, axes: &str, dims: [u32; 3], comps: u32) {
    let Some(gpu) = gpu() else { return };
    let params = format!(r#"{{"axes": "{axes}"}}"#);
    let ty = grid(kind, dims, comps);
    let (dir, g) = load_single_node(kind, &params, &[("x", ty)]);
    let x = Rng::new(seed(dims, comps)).array(ty, -1.0, 1.0);
    let data = [("x".to_string(), x.clone())].into_iter().collect();
    let (out, _) = run_cached(&gpu, &g, &data, None, 1, true);
    let _ = std::fs::remove_dir_all(&dir);
    let want = &reference(kind, &params, &[Some(&x)])[0];
    let e = rel_l2(&out["out"].data.to_f64(), &want.data);
    let tol = tolerance(dims);
    assert!(
        e <= tol,
        "{kind} axes={axes} dims={dims:?} comps={comps}: relative L2 error {e:e} > {tol:e}"
    );
}

/// Every radix alone and mixed, odd and even lengths, up to the longest line. Kept short
/// for lavapipe, which compiles each pipeline in about 0.2 to 1 s; `mesoflow bench fft`
/// checks the large sizes on the GPU machine.
const LENGTHS: &[u32] = &[
    1, 2, 3, 4, 5, 7, 8, 12, 15, 16, 21, 27, 32, 35, 49, 60, 64, 96, 125, 189, 256, 375, 512, 4096,
];

#[test]
fn one_dimensional_transforms_match_rustfft() {
    for &n in LENGTHS {
        check("fft", "x", [n, 1, 1], 2);
    }
    for n in [7, 16, 35, 64] {
        check("ifft", "x", [n, 1, 1], 1);
    }
    // Odd lengths transform whole lines; even ones n/2 packed pairs (n = 2: one pair).
    for n in [1, 2, 15, 16, 27, 98, 120, 250] {
        check("rfft", "x", [n, 1, 1], 2);
    }
    for n in [1, 2, 3, 16, 21, 60, 64, 81] {
        check("irfft", "x", [n, 1, 1], 1);
    }
    // Lines along y and z alone (strided passes), several components.
    check("fft", "xyz", [1, 60, 1], 3);
    check("irfft", "xyz", [1, 1, 81], 2);
}

#[test]
fn multidimensional_transforms_match_rustfft() {
    let cases: &[(&str, &str, [u32; 3], u32)] = &[
        ("fft", "xy", [12, 15, 1], 2),
        ("rfft", "xy", [15, 12, 1], 3),
        ("irfft", "xy", [16, 21, 1], 2),
        ("fft", "xyz", [16, 12, 10], 3),
        ("ifft", "xyz", [9, 5, 8], 2),
        ("rfft", "xyz", [15, 12, 7], 3),
        ("irfft", "xyz", [15, 12, 7], 3),
        ("rfft", "xyz", [2, 3, 2], 1),
        ("rfft", "xyz", [64, 64, 64], 3),
        ("irfft", "xyz", [64, 48, 20], 3),
        // Fewer axes than the grid has: lines along x only, or x and y only.
        ("fft", "x", [16, 6, 5], 2),
        ("rfft", "xy", [10, 12, 3], 2),
    ];
    for &(kind, axes, dims, comps) in cases {
        check(kind, axes, dims, comps);
    }
}

#[test]
fn round_trips_return_the_input() {
    let Some(gpu) = gpu() else { return };
    let cases: &[(&str, &str, [u32; 3], &str)] = &[
        ("fft", "ifft", [12, 10, 7], "xyz"),
        ("rfft", "irfft", [20, 9, 6], "xyz"),
        ("rfft", "irfft", [27, 16, 1], "xy"),
        ("rfft", "irfft", [1, 5, 8], "xyz"),
    ];
    for &(fwd, inv, dims, axes) in cases {
        let ty = grid(fwd, dims, 2);
        let dir = tmpdir("fft-roundtrip");
        let g = load(&write_graph(&dir, "g.json", &chain(fwd, inv, ty, axes)));
        let x = Rng::new(seed(dims, 2)).array(ty, -1.0, 1.0);
        let data = [("x".to_string(), x.clone())].into_iter().collect();
        let (out, _) = run_cached(&gpu, &g, &data, None, 1, true);
        let e = rel_l2(&out["b"].data.to_f64(), &x.data.to_f64());
        // Two f32 transforms: twice the one-way bound.
        assert!(e <= 4e-6, "{fwd} -> {inv} {dims:?}: {e:e}");
    }
}

#[test]
fn real_transforms_are_the_half_of_complex_ones() {
    let Some(gpu) = gpu() else { return };
    for dims in [[16, 6, 5], [15, 4, 3]] {
        let real = ValueType::RealGrid { dims, comps: 2 };
        let x = Rng::new(seed(dims, 7)).array(real, -1.0, 1.0);
        let complex: Vec<f32> = x
            .data
            .to_f64()
            .iter()
            .flat_map(|&v| [v as f32, 0.0])
            .collect();
        let cty = ValueType::ComplexGrid { dims, comps: 2 };
        let dir = tmpdir("fft-hermitian");
        let outputs = |kind: &str, input: HostArray| {
            let g = load(&write_graph(
                &dir,
                "g.json",
                &single_node_graph(kind, "{}", &[("x", input.ty)]),
            ));
            let data = [("x".to_string(), input)].into_iter().collect();
            run_cached(&gpu, &g, &data, None, 1, true)
                .0
                .remove("out")
                .unwrap()
                .data
                .to_f64()
        };
        let half = outputs("rfft", x);
        let full = outputs("fft", HostArray::f32(cty, complex));
        let h = dims[0] as usize / 2 + 1;
        let first_half: Vec<f64> = full
            .chunks_exact(2 * dims[0] as usize)
            .flat_map(|row| row[..2 * h].to_vec())
            .collect();
        // Same f32 inputs, different algorithms (packed pairs vs full lines).
        let e = rel_l2(&half, &first_half);
        assert!(e <= 2e-6, "{dims:?}: {e:e}");
        // The full spectrum of a real grid is Hermitian: X[-k] = conj(X[k]).
        let (nx, ny, nz) = (dims[0] as usize, dims[1] as usize, dims[2] as usize);
        let at = |c: usize, x: usize, y: usize, z: usize| 2 * (((c * nz + z) * ny + y) * nx + x);
        let mut worst = 0.0f64;
        for c in 0..2 {
            for z in 0..nz {
                for y in 0..ny {
                    for x in 0..nx {
                        let a = at(c, x, y, z);
                        let b = at(c, (nx - x) % nx, (ny - y) % ny, (nz - z) % nz);
                        worst = worst
                            .max((full[a] - full[b]).abs())
                            .max((full[a + 1] + full[b + 1]).abs());
                    }
                }
            }
        }
        let scale = full.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(
            worst <= 1e-5 * scale,
            "{dims:?}: asymmetry {worst:e} of {scale:e}"
        );
    }
}
