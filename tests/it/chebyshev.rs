//! The Chebyshev nodes along z (`chebyshev`, `chebyshev_derivative`): against their f64
//! references on random real, complex and half-complex grids, and against Chebyshev
//! polynomials written here (T_m at the Gauss-Lobatto points transforms to the unit
//! vector e_m; T_m' = m U_{m-1}; the inverse undoes the forward transform).

use std::f64::consts::PI;

use mesoflow::value::{HostArray, ValueType};

use crate::util::{Rng, gpu, rel_max_err, run_out};

fn grid(dims: [u32; 3], comps: u32, values: &[f64]) -> HostArray {
    HostArray::f32(
        ValueType::RealGrid { dims, comps },
        values.iter().map(|&v| v as f32).collect(),
    )
}

/// Both nodes against their references on every grid kind, n from 2 to 65.
#[test]
fn chebyshev_nodes_match_their_references() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(41);
    for ty in [
        ValueType::RealGrid {
            dims: [5, 3, 17],
            comps: 2,
        },
        ValueType::ComplexGrid {
            dims: [4, 4, 9],
            comps: 1,
        },
        ValueType::HalfComplexGrid {
            dims: [8, 6, 33],
            comps: 3,
        },
        ValueType::RealGrid {
            dims: [2, 2, 2],
            comps: 1,
        },
        ValueType::RealGrid {
            dims: [1, 1, 65],
            comps: 1,
        },
    ] {
        let x = rng.array(ty, -1.0, 1.0);
        for (kind, params, tol) in [
            ("chebyshev", r#"{"direction": "forward"}"#, 2e-6),
            ("chebyshev", r#"{"direction": "inverse"}"#, 2e-6),
            ("chebyshev_derivative", r#"{"height": 3.0}"#, 2e-6),
        ] {
            let (got, want) = run_out(kind, params, &[("x", x.clone())]);
            let (err, at) = rel_max_err(&got, &want);
            assert!(err <= tol, "{kind} {params} on {ty}: {err:e} at {at}");
        }
    }
}

/// T_m sampled at the Gauss-Lobatto points transforms to e_m, and back.
#[test]
fn chebyshev_polynomials_transform_to_unit_vectors() {
    if gpu().is_none() {
        return;
    }
    let n = 13usize;
    // One line per m: the grid [n, 1, n] holds T_m(xi_j) at x = m.
    let mut values = vec![0.0; n * n];
    for m in 0..n {
        for j in 0..n {
            values[j * n + m] = (m as f64 * PI * j as f64 / (n - 1) as f64).cos();
        }
    }
    let x = grid([n as u32, 1, n as u32], 1, &values);
    let (c, _) = run_out(
        "chebyshev",
        r#"{"direction": "forward"}"#,
        &[("x", x.clone())],
    );
    let c = c.data.to_f64();
    for m in 0..n {
        for k in 0..n {
            let want = if k == m { 1.0 } else { 0.0 };
            assert!(
                (c[k * n + m] - want).abs() < 2e-6,
                "T_{m}: c_{k} = {}",
                c[k * n + m]
            );
        }
    }
    let (back, _) = run_out(
        "chebyshev",
        r#"{"direction": "inverse"}"#,
        &[("x", grid([n as u32, 1, n as u32], 1, &c))],
    );
    for (a, b) in back.data.to_f64().iter().zip(&values) {
        assert!((a - b).abs() < 4e-6, "round trip {a} vs {b}");
    }
}

/// The derivative of T_m on [zmin, zmax] is (2 / H) m U_{m-1}(xi), checked at the points.
#[test]
fn derivatives_of_chebyshev_polynomials() {
    if gpu().is_none() {
        return;
    }
    let (n, height) = (12usize, 4.0);
    // Coefficients: line m holds e_m.
    let mut coeffs = vec![0.0; n * n];
    for m in 0..n {
        coeffs[m * n + m] = 1.0;
    }
    let (d, _) = run_out(
        "chebyshev_derivative",
        &format!(r#"{{"height": {height}}}"#),
        &[("x", grid([n as u32, 1, n as u32], 1, &coeffs))],
    );
    let (values, _) = run_out("chebyshev", r#"{"direction": "inverse"}"#, &[("x", d)]);
    let values = values.data.to_f64();
    for m in 1..n {
        for j in 1..n - 1 {
            let theta = PI * j as f64 / (n - 1) as f64;
            // U_{m-1}(cos t) = sin(m t) / sin t.
            let want = 2.0 / height * m as f64 * (m as f64 * theta).sin() / theta.sin();
            let got = values[j * n + m];
            assert!(
                (got - want).abs() < 2e-5 * (m * m) as f64,
                "T_{m}' at point {j}: {got} vs {want}"
            );
        }
    }
}

/// Other values than grids, and a single point along z, are refused by name.
#[test]
fn chebyshev_nodes_refuse_what_they_cannot_transform() {
    let e = crate::util::validation_error(
        "chebyshev",
        "{}",
        &[("x", ValueType::Particles { n: 4, k: 3 })],
    );
    assert!(e.contains("expects a real or complex grid"), "{e}");
    let e = crate::util::validation_error(
        "chebyshev_derivative",
        "{}",
        &[(
            "x",
            ValueType::RealGrid {
                dims: [4, 4, 1],
                comps: 1,
            },
        )],
    );
    assert!(e.contains("at least 2"), "{e}");
}

/// `chebyshev_bvp` against its f64 reference (a dense solve of the whole system per k),
/// with and without boundary values, on several grids.
#[test]
fn the_bvp_node_matches_its_dense_reference() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(43);
    for (dims, comps, zmax) in [
        ([8u32, 6, 17], 1u32, 3.0),
        ([4, 4, 9], 2, 1.0),
        ([6, 5, 33], 1, 10.0),
    ] {
        let f = rng.array(ValueType::HalfComplexGrid { dims, comps }, -1.0, 1.0);
        let params = format!(r#"{{"box": [12, 9], "zmin": -2, "zmax": {zmax}}}"#);
        let (got, want) = run_out("chebyshev_bvp", &params, &[("f", f.clone())]);
        let (err, at) = rel_max_err(&got, &want);
        assert!(err <= 2e-5, "bvp {dims:?} x {comps}: {err:e} at {at}");
        let b = rng.array(
            ValueType::HalfComplexGrid {
                dims: [dims[0], dims[1], 2],
                comps,
            },
            -1.0,
            1.0,
        );
        let (got, want) = run_out("chebyshev_bvp", &params, &[("f", f), ("boundary", b)]);
        let (err, at) = rel_max_err(&got, &want);
        assert!(
            err <= 2e-5,
            "bvp with boundary {dims:?} x {comps}: {err:e} at {at}"
        );
    }
}

/// A manufactured solution through the GPU: y(z) = cos(z) + z^2 on [-1, 2] for every k of a
/// small spectrum, f = y'' - k^2 y and the Robin values of y itself, recovered at the
/// Gauss-Lobatto points (k = 0: the Dirichlet values).
#[test]
fn the_bvp_node_recovers_a_manufactured_solution() {
    if gpu().is_none() {
        return;
    }
    let (zmin, zmax, n) = (-1.0f64, 2.0f64, 20usize);
    let (lx, ly) = (6.0, 5.0);
    let dims = [4u32, 3, n as u32];
    let hx = dims[0] / 2 + 1;
    let nk = (hx * dims[1]) as usize;
    let ks: Vec<f64> = (0..dims[1])
        .flat_map(|y| {
            let fy = if y <= dims[1] / 2 {
                y as f64
            } else {
                y as f64 - dims[1] as f64
            };
            (0..hx).map(move |x| {
                let kx = 2.0 * PI * x as f64 / lx;
                let ky = 2.0 * PI * fy / ly;
                (kx * kx + ky * ky).sqrt()
            })
        })
        .collect();
    let zs: Vec<f64> = (0..n)
        .map(|j| 0.5 * (zmin + zmax) + 0.5 * (zmax - zmin) * (PI * j as f64 / (n - 1) as f64).cos())
        .collect();
    let y = |z: f64| z.cos() + z * z;
    let dy = |z: f64| -z.sin() + 2.0 * z;
    let d2y = |z: f64| -z.cos() + 2.0;
    // f at the points, real part only, then to coefficients with the chebyshev node.
    let mut fv = vec![0.0; 2 * n * nk];
    let mut bv = vec![0.0; 2 * 2 * nk];
    for (ki, &k) in ks.iter().enumerate() {
        for (j, &z) in zs.iter().enumerate() {
            fv[2 * (j * nk + ki)] = d2y(z) - k * k * y(z);
        }
        let (alpha, beta) = if k == 0.0 {
            (y(zmax), y(zmin))
        } else {
            (dy(zmax) + k * y(zmax), dy(zmin) - k * y(zmin))
        };
        bv[2 * ki] = alpha;
        bv[2 * (nk + ki)] = beta;
    }
    let spectrum = |dims: [u32; 3], v: &[f64]| {
        HostArray::f32(
            ValueType::HalfComplexGrid { dims, comps: 1 },
            v.iter().map(|&x| x as f32).collect(),
        )
    };
    let (fc, _) = run_out(
        "chebyshev",
        r#"{"direction": "forward"}"#,
        &[("x", spectrum(dims, &fv))],
    );
    let params = format!(r#"{{"box": [{lx}, {ly}], "zmin": {zmin}, "zmax": {zmax}}}"#);
    let (yc, _) = run_out(
        "chebyshev_bvp",
        &params,
        &[
            ("f", fc),
            ("boundary", spectrum([dims[0], dims[1], 2], &bv)),
        ],
    );
    let (values, _) = run_out("chebyshev", r#"{"direction": "inverse"}"#, &[("x", yc)]);
    let values = values.data.to_f64();
    for ki in 0..nk {
        for (j, &z) in zs.iter().enumerate() {
            let got = values[2 * (j * nk + ki)];
            assert!(
                (got - y(z)).abs() < 2e-4,
                "k {}: y({z}) = {got}, want {}",
                ks[ki],
                y(z)
            );
            assert!(values[2 * (j * nk + ki) + 1].abs() < 1e-5);
        }
    }
}
