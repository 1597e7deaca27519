//! FFT nodes against rustfft in f64 (through their CPU references), round trips, Hermitian
//! consistency of the real transforms, size rules, plans, and folding a spectral node
//! into a transform. Data-driven: one `check` line per case.

use std::collections::BTreeMap;

use mesoflow::value::{HostArray, RefArray, ValueType};

use crate::util::{
    Rng, gpu, load, reference, registry, run_graph, single_node_graph, tmpdir, write_graph,
};

/// Relative L2 error of `got` against `want`: |got - want| / |want|.
fn rel_l2(got: &[f64], want: &[f64]) -> f64 {
    assert_eq!(got.len(), want.len());
    let num: f64 = got.iter().zip(want).map(|(a, b)| (a - b) * (a - b)).sum();
    let den: f64 = want.iter().map(|b| b * b).sum();
    (num / den.max(f64::MIN_POSITIVE)).sqrt()
}

fn grid(kind: &str, dims: [u32; 3], comps: u32) -> ValueType {
    match kind {
        "fft" | "ifft" => ValueType::ComplexGrid { dims, comps },
        "rfft" => ValueType::RealGrid { dims, comps },
        _ => ValueType::HalfComplexGrid { dims, comps },
    }
}

/// Runs transform `kind` over `axes` on seeded random data of `dims` x `comps` and
/// returns the relative L2 error against the f64 reference.
fn error(kind: &str, axes: &str, dims: [u32; 3], comps: u32) -> f64 {
    let Some(gpu) = gpu() else { return 0.0 };
    let params = format!(r#"{{"axes": "{axes}"}}"#);
    let ty = grid(kind, dims, comps);
    let dir = tmpdir(&format!("fft-{kind}"));
    let path = write_graph(&dir, "g.json", &single_node_graph(kind, &params, &[("x", ty)]));
    let g = load(&path);
    let mut rng = Rng::new(dims.iter().map(|&d| d as u64).product::<u64>() + comps as u64);
    let x = rng.array(ty, -1.0, 1.0);
    let data: BTreeMap<String, HostArray> = [("x".to_string(), x.clone())].into_iter().collect();
    let out = run_graph(&gpu, &g, &data, None, 1, true);
    let want = &reference(kind, &params, &[Some(&x)])[0];
    rel_l2(&out["out"].data.to_f64(), &want.data)
}

/// f32 FFTs: relative L2 error grows like eps log2(N); the issue's bounds.
fn tolerance(dims: [u32; 3]) -> f64 {
    if dims.iter().all(|&d| d <= 256) {
        2e-6
    } else {
        5e-6
    }
}

fn check(kind: &str, axes: &str, dims: [u32; 3], comps: u32) {
    let e = error(kind, axes, dims, comps);
    let tol = tolerance(dims);
    assert!(
        e <= tol,
        "{kind} axes={axes} dims={dims:?} comps={comps}: relative L2 error {e:e} > {tol:e}"
    );
}

#[test]
fn smoke() {
    for n in [1, 2, 3, 4, 5, 7, 8, 16, 12, 15, 64] {
        check("fft", "x", [n, 1, 1], 1);
    }
}

#[test]
fn scan_errors() {
    let mut bad = Vec::new();
    for kind in ["fft", "ifft", "rfft", "irfft"] {
        for n in [1u32, 2, 3, 4, 5, 6, 7, 8, 9, 10, 12, 14, 15, 16, 21, 27, 32, 35, 49, 60, 64, 81, 96, 125, 128, 162, 189, 243, 256, 343, 375, 512] {
            let e = error(kind, "x", [n, 1, 1], 2);
            if !(e <= 2e-6) { bad.push(format!("{kind} {n}: {e:e}")); }
        }
        for d in [[4u32, 6, 1], [12, 15, 1], [15, 12, 7], [16, 16, 16], [9, 5, 8], [2, 3, 2], [1, 8, 8], [8, 1, 8]] {
            let e = error(kind, "xyz", d, 3);
            if !(e <= 2e-6) { bad.push(format!("{kind} {d:?}: {e:e}")); }
        }
    }
    assert!(bad.is_empty(), "{bad:#?}");
}

#[test]
fn print_some() {
    for (kind, d) in [("fft", [64u32, 1, 1]), ("rfft", [64, 1, 1]), ("irfft", [15, 12, 7]), ("rfft", [16, 16, 16]), ("fft", [512,1,1]), ("irfft", [96, 1, 1])] {
        let t = std::time::Instant::now();
        let e = error(kind, "xyz", d, 2);
        eprintln!("{kind} {d:?}: {e:e} in {:?}", t.elapsed());
    }
}
