//! The Chebyshev nodes along z (`chebyshev`, `chebyshev_derivative`): against their f64
//! references on random real, complex and half-complex grids, and against Chebyshev
//! polynomials written here (T_m at the Gauss-Lobatto points transforms to the unit
//! vector e_m; T_m' = m U_{m-1}; the inverse undoes the forward transform).

use std::f64::consts::PI;

use mesoflow::value::{HostArray, ValueType};

use crate::util::{
    Rng, compile_cached, compile_error, erfc, f32s, flat_particles, gpu, load_single_node, named,
    plan_graph, reference, rel_max_err, run_node, run_out, types_of, with_caps,
};

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
        // Long lines: several chunks of outputs a line.
        ValueType::RealGrid {
            dims: [3, 2, 300],
            comps: 2,
        },
        // Many lines: the derivative by its recurrence (DerivativePlan).
        ValueType::RealGrid {
            dims: [128, 128, 5],
            comps: 2,
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
    let e = crate::util::validation_error(
        "chebyshev_derivative",
        r#"{"first": 2, "count": 2}"#,
        &[(
            "x",
            ValueType::RealGrid {
                dims: [4, 4, 5],
                comps: 3,
            },
        )],
    );
    assert!(e.contains("components 2 to 3 cannot be taken"), "{e}");
}

/// `chebyshev_derivative` of some components only (`first`, `count`), by both strategies
/// (the dense product on few lines, the recurrence on many), against its reference.
#[test]
fn the_derivative_of_some_components_matches_its_reference() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(47);
    for (dims, comps) in [([6u32, 5, 9], 3u32), ([256, 128, 5], 2)] {
        let x = rng.array(ValueType::RealGrid { dims, comps }, -1.0, 1.0);
        for params in [
            r#"{"height": 3.0, "first": 1, "count": 1}"#,
            r#"{"height": 3.0, "first": 1}"#,
        ] {
            let (got, want) = run_out("chebyshev_derivative", params, &[("x", x.clone())]);
            assert_eq!(got.ty, want.ty, "{params}");
            assert_eq!(
                got.ty,
                ValueType::RealGrid {
                    dims,
                    comps: comps - 1 - u32::from(comps == 3 && params.contains("count")),
                },
                "{params}"
            );
            let (err, at) = rel_max_err(&got, &want);
            assert!(
                err <= 2e-6,
                "{params} on {dims:?} x {comps}: {err:e} at {at}"
            );
        }
    }
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
        // Long lines: chebyshev_bvp in its private array beyond registers.
        ([4, 3, 300], 1, 10.0),
    ] {
        let f = rng.array(ValueType::HalfComplexGrid { dims, comps }, -1.0, 1.0);
        // Both thread orders (auto takes `components` at these sizes).
        for order in ["components", "waves"] {
            let params =
                format!(r#"{{"box": [12, 9], "zmin": -2, "zmax": {zmax}, "order": "{order}"}}"#);
            let (got, want) = run_out("chebyshev_bvp", &params, &[("f", f.clone())]);
            let (err, at) = rel_max_err(&got, &want);
            assert!(
                err <= 2e-5,
                "bvp {dims:?} x {comps} {order}: {err:e} at {at}"
            );
        }
        let params = format!(r#"{{"box": [12, 9], "zmin": -2, "zmax": {zmax}}}"#);
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

// ---- spread_chebyshev and interpolate_chebyshev -----------------------------------

/// The params of a Chebyshev grid test: box 8 x 6 on 16 x 12 cells (h = 0.5), z in
/// [-2, 3] on 33 points, the window and walls given.
fn cheb_params(window: &str, walls: &str) -> String {
    cheb_params_in("[8, 6]", window, walls)
}

/// The same on another box (16 x 12 cells).
fn cheb_params_in(box_: &str, window: &str, walls: &str) -> String {
    format!(
        r#"{{"box": {box_}, "grid": [16, 12], "zmin": -2, "zmax": 3, "points": 33, {window}, "walls": "{walls}"}}"#
    )
}

const GAUSSIAN: &str = r#""window": "gaussian", "width": 0.5, "tolerance": 1e-6"#;
const ES: &str = r#""window": "es", "support": 6, "beta": 13.8"#;
/// ES with its half-width a length (dpstokes.json's): 5.2 cells of x, 4.33 of y on the
/// 8 x 7.2 box. The shape steep enough that its jump at the edge, e^-beta of the peak,
/// is below the comparison's 2e-6: a point at the edge within f32 rounding may fall on
/// either side in the kernel and the f64 reference.
const ES_LENGTH: &str = r#""window": "es", "width": 1.3, "beta": 13.8"#;

/// The kernels of spread_chebyshev and interpolate_chebyshev (their `kernel` param).
const CHEB_KERNELS: [&str; 2] = ["workgroup", "lanes"];

/// `params` (a JSON object) with `kernel` set.
fn with_kernel(params: &str, kernel: &str) -> String {
    let rest = params
        .trim_start()
        .strip_prefix('{')
        .expect("a JSON object");
    format!(r#"{{"kernel": "{kernel}", {rest}"#)
}

/// Positions in the domain with the hard places: on the bottom and top walls, a radius
/// from them, at mid-height, on the periodic faces and a grid point.
fn cheb_positions(rng: &mut Rng) -> Vec<f64> {
    let mut x = vec![
        0.3, 0.2, -2.0, // on the bottom
        -4.0, 3.0, 3.0, // on the top, on two periodic faces
        0.25, 0.25, 0.5, // mid-height, a cell centre in x and y
        3.99, -2.99, -1.5, // near a face, half a width above the bottom
        1.1, 0.4, 2.6,
    ];
    for _ in 0..20 {
        x.push(rng.uniform(-4.0, 4.0));
        x.push(rng.uniform(-3.0, 3.0));
        x.push(rng.uniform(-2.0, 3.0));
    }
    x
}

/// Both nodes against their f64 references, every wall mode, Gaussian and ES windows (one
/// with its half-width a length, on cells longer in y than in x).
#[test]
fn chebyshev_spreading_and_interpolation_match_their_references() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(8);
    let pos = cheb_positions(&mut rng);
    let n = pos.len() / 3;
    let vals: Vec<f64> = (0..3 * n).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let field = rng.array(
        ValueType::RealGrid {
            dims: [16, 12, 33],
            comps: 3,
        },
        -1.0,
        1.0,
    );
    for (box_, window) in [
        ("[8, 6]", GAUSSIAN),
        ("[8, 6]", ES),
        ("[8, 7.2]", ES_LENGTH),
    ] {
        for (walls, kernel) in ["none", "bottom", "slit"]
            .into_iter()
            .flat_map(|w| CHEB_KERNELS.map(|k| (w, k)))
        {
            let p = with_kernel(&cheb_params_in(box_, window, walls), kernel);
            let (got, want) = run_out(
                "spread_chebyshev",
                &p,
                &[
                    ("positions", flat_particles(&pos, 3)),
                    ("values", flat_particles(&vals, 3)),
                ],
            );
            let (err, at) = rel_max_err(&got, &want);
            assert!(
                err <= 2e-6,
                "spread {window} {walls} {kernel}: {err:e} at {at}"
            );
            let (got, want) = run_out(
                "interpolate_chebyshev",
                &p,
                &[
                    ("grid", field.clone()),
                    ("positions", flat_particles(&pos, 3)),
                ],
            );
            let (err, at) = rel_max_err(&got, &want);
            assert!(
                err <= 2e-6,
                "interpolate {window} {walls} {kernel}: {err:e} at {at}"
            );
        }
    }
}

/// Physics of the kernel, against closed forms written here: interpolating a field of
/// ones integrates delta~ over the domain by the quadrature. Away from walls that is 1
/// (the window is normalised); a bottom wall's image takes away the part mirrored below
/// it, erf(d / (sigma sqrt 2)) for a Gaussian at height d (0 on the wall); the slit takes
/// both walls' images.
#[test]
fn chebyshev_kernel_integrates_to_the_closed_forms() {
    if gpu().is_none() {
        return;
    }
    let sigma = 0.5;
    let erf = |x: f64| 1.0 - erfc(x);
    let heights = [0.0, 0.1, 0.25, 0.5, 1.0, 2.5];
    let mut pos = Vec::new();
    for (i, d) in heights.iter().enumerate() {
        pos.extend([0.37 * i as f64 - 2.0, 0.21 * i as f64, -2.0 + d]);
    }
    let n = heights.len() as u32;
    let ones = HostArray::f32(
        ValueType::RealGrid {
            dims: [16, 12, 65],
            comps: 1,
        },
        vec![1.0; 16 * 12 * 65],
    );
    for (walls, kernel) in ["none", "bottom", "slit"]
        .into_iter()
        .flat_map(|w| CHEB_KERNELS.map(|k| (w, k)))
    {
        let p = format!(
            r#"{{"box": [8, 6], "grid": [16, 12], "zmin": -2, "zmax": 3, "points": 65, {GAUSSIAN}, "walls": "{walls}", "kernel": "{kernel}"}}"#
        );
        let (got, _) = run_out(
            "interpolate_chebyshev",
            &p,
            &[
                ("grid", ones.clone()),
                ("positions", flat_particles(&pos, 3)),
            ],
        );
        let got = got.data.to_f64();
        assert_eq!(got.len(), n as usize);
        for (d, g) in heights.iter().zip(&got) {
            // The part of the Gaussian inside [zmin, zmax], minus its images' parts.
            let inside = |q: f64| {
                0.5 * (erf((3.0 - q) / (sigma * 2f64.sqrt()))
                    - erf((-2.0 - q) / (sigma * 2f64.sqrt())))
            };
            let q = -2.0 + d;
            let want = match walls {
                "none" => inside(q),
                "bottom" => inside(q) - inside(-4.0 - q),
                _ => inside(q) - inside(-4.0 - q) - inside(6.0 - q),
            };
            assert!(
                (g - want).abs() < 2e-5,
                "{walls} {kernel}, height {d}: {g} against {want}"
            );
        }
    }
}

/// Interpolation is the adjoint of spreading in the quadrature's inner product:
/// sum_grid W S(F) . u = sum_i F_i . J(u)_i, for random F and u, both from the GPU; the
/// weights W (Clenshaw-Curtis, h_x h_y H/2) written here.
#[test]
fn chebyshev_interpolation_is_the_adjoint_of_spreading() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(9);
    let pos = cheb_positions(&mut rng);
    let n = pos.len() / 3;
    let f: Vec<f64> = (0..3 * n).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let u = rng.array(
        ValueType::RealGrid {
            dims: [16, 12, 33],
            comps: 3,
        },
        -1.0,
        1.0,
    );
    // Clenshaw-Curtis on 33 points by its defining property: the weights that integrate
    // T_0 .. T_32 exactly, solved here from the moments (a Vandermonde-free form: the
    // cosine sums of Trefethen's clencurt are the closed form of that solve).
    let m = 32usize;
    let w: Vec<f64> = (0..=m)
        .map(|i| {
            let theta = PI * i as f64 / m as f64;
            let c = if i == 0 || i == m { 0.5 } else { 1.0 };
            let s: f64 = (0..=m / 2)
                .map(|k| {
                    let b = if k == 0 || k == m / 2 { 0.5 } else { 1.0 };
                    b * 2.0 / (1.0 - 4.0 * (k * k) as f64) * (2.0 * k as f64 * theta).cos()
                })
                .sum();
            c * 2.0 / m as f64 * s
        })
        .collect();
    assert!((w.iter().sum::<f64>() - 2.0).abs() < 1e-12);
    for (walls, kernel) in ["none", "bottom", "slit"]
        .into_iter()
        .flat_map(|w| CHEB_KERNELS.map(|k| (w, k)))
    {
        let p = with_kernel(&cheb_params(GAUSSIAN, walls), kernel);
        let (spread, _) = run_out(
            "spread_chebyshev",
            &p,
            &[
                ("positions", flat_particles(&pos, 3)),
                ("values", flat_particles(&f, 3)),
            ],
        );
        let (interp, _) = run_out(
            "interpolate_chebyshev",
            &p,
            &[("grid", u.clone()), ("positions", flat_particles(&pos, 3))],
        );
        let (s, uu) = (spread.data.to_f64(), u.data.to_f64());
        let plane = 16 * 12;
        let cell = 0.5 * 0.5 * 2.5;
        let lhs: f64 = (0..3)
            .map(|c| {
                (0..33 * plane)
                    .map(|i| w[i / plane] * cell * s[c * 33 * plane + i] * uu[c * 33 * plane + i])
                    .sum::<f64>()
            })
            .sum();
        let rhs: f64 = f.iter().zip(interp.data.to_f64()).map(|(a, b)| a * b).sum();
        assert!(
            (lhs - rhs).abs() < 1e-5 * lhs.abs().max(rhs.abs()),
            "{walls} {kernel}: {lhs} against {rhs}"
        );
    }
}

/// A particle on a wall spreads nothing; one outside [zmin, zmax] is refused by row.
#[test]
fn chebyshev_walls_take_particles_on_them_and_refuse_those_through() {
    if gpu().is_none() {
        return;
    }
    let p = cheb_params(GAUSSIAN, "slit");
    let on = [0.3, 0.1, -2.0, -1.0, 2.0, 3.0];
    for kernel in CHEB_KERNELS {
        let (got, _) = run_out(
            "spread_chebyshev",
            &with_kernel(&p, kernel),
            &[
                ("positions", flat_particles(&on, 3)),
                ("values", flat_particles(&[1.0; 6], 3)),
            ],
        );
        assert!(
            got.data.to_f64().iter().all(|&v| v == 0.0),
            "a particle on a wall spread something ({kernel})"
        );
    }
    let data = named(&[
        (
            "positions",
            flat_particles(&[0.0, 0.0, 1.0, 0.5, 0.5, -2.5], 3),
        ),
        ("values", flat_particles(&[1.0; 6], 3)),
    ]);
    let types: Vec<(&str, ValueType)> = data.iter().map(|(k, v)| (k.as_str(), v.ty)).collect();
    let (dir, g) = load_single_node("spread_chebyshev", &p, &types);
    let gpu = gpu().expect("checked above");
    let plan = plan_graph(&gpu.caps, &g, types_of(&data), None, true);
    let mut program = compile_cached(&gpu, &g, &plan);
    let err = program.upload(&data).unwrap_err().to_string();
    let _ = std::fs::remove_dir_all(&dir);
    assert!(
        err.contains("row 1") && err.contains("outside") && err.contains("slit"),
        "{err}"
    );
}

/// Deterministic runs add in fixed point: the spread grid is the same bits whatever the
/// particles' order, and the f64 reference's within f32 rounding.
#[test]
fn deterministic_chebyshev_spreading_does_not_depend_on_the_order() {
    let Some(mut gpu) = gpu() else { return };
    let mut rng = Rng::new(10);
    let pos = cheb_positions(&mut rng);
    let n = pos.len() / 3;
    let vals: Vec<f64> = (0..3 * n).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let reverse = |v: &[f64]| -> Vec<f64> { v.chunks(3).rev().flatten().copied().collect() };
    let p = cheb_params(ES, "bottom");
    let forward = named(&[
        ("positions", flat_particles(&pos, 3)),
        ("values", flat_particles(&vals, 3)),
    ]);
    let backward = named(&[
        ("positions", flat_particles(&reverse(&pos), 3)),
        ("values", flat_particles(&reverse(&vals), 3)),
    ]);
    let (a, b, c) = with_caps(
        &mut gpu,
        |c| c.deterministic = true,
        |gpu| {
            let lanes = with_kernel(&p, "lanes");
            let workgroup = with_kernel(&p, "workgroup");
            (
                run_node(gpu, "spread_chebyshev", &lanes, &forward)
                    .remove("out")
                    .unwrap(),
                run_node(gpu, "spread_chebyshev", &lanes, &backward)
                    .remove("out")
                    .unwrap(),
                run_node(gpu, "spread_chebyshev", &workgroup, &backward)
                    .remove("out")
                    .unwrap(),
            )
        },
    );
    assert_eq!(f32s(&a), f32s(&b), "the two orders differ");
    // The same weights: the two kernels' fixed-point sums are the same bits.
    assert_eq!(f32s(&a), f32s(&c), "the two kernels differ");
    let want = &reference(
        "spread_chebyshev",
        &p,
        &[forward.get("positions"), forward.get("values")],
    )[0];
    let (err, at) = rel_max_err(&a, want);
    assert!(err <= 2e-6, "{err:e} at {at}");
}

/// Every kernel against the references at 1, 3 and 4 components, every wall mode, the
/// windows wider than a segment's lanes (the lane kernels' column blocks, and z ranges
/// longer than a segment), particles on walls and periodic faces: the workgroup kernels,
/// the lane kernels with the adapter's segment and with one narrower than its subgroup
/// (several particles per subgroup), and `auto` on an adapter without subgroups (the
/// workgroup kernels).
#[test]
fn chebyshev_kernels_match_their_references_at_every_component_count() {
    let Some(mut gpu) = gpu() else { return };
    let mut rng = Rng::new(11);
    let pos = cheb_positions(&mut rng);
    let n = pos.len() / 3;
    type Subgroups = Option<Option<(u32, u32)>>;
    let setups: [(&str, Subgroups); 4] = [
        ("workgroup", None),
        ("lanes", None),
        ("lanes", Some(Some((4, 4)))),
        ("auto", Some(None)),
    ];
    for comps in [1u32, 3, 4] {
        let vals: Vec<f64> = (0..comps as usize * n)
            .map(|_| rng.uniform(-1.0, 1.0))
            .collect();
        let field = rng.array(
            ValueType::RealGrid {
                dims: [16, 12, 33],
                comps,
            },
            -1.0,
            1.0,
        );
        let spread_in = named(&[
            ("positions", flat_particles(&pos, 3)),
            ("values", flat_particles(&vals, comps)),
        ]);
        let interp_in = named(&[("grid", field), ("positions", flat_particles(&pos, 3))]);
        for (box_, window) in [("[8, 6]", GAUSSIAN), ("[8, 7.2]", ES_LENGTH)] {
            for walls in ["none", "bottom", "slit"] {
                let p = cheb_params_in(box_, window, walls);
                let want_spread = reference(
                    "spread_chebyshev",
                    &p,
                    &[spread_in.get("positions"), spread_in.get("values")],
                )
                .remove(0);
                let want_interp = reference(
                    "interpolate_chebyshev",
                    &p,
                    &[interp_in.get("grid"), interp_in.get("positions")],
                )
                .remove(0);
                for (kernel, subgroups) in setups {
                    let pk = with_kernel(&p, kernel);
                    let (spread, interp) = with_caps(
                        &mut gpu,
                        |c| {
                            if let Some(s) = subgroups {
                                c.subgroups = s;
                            }
                        },
                        |gpu| {
                            (
                                run_node(gpu, "spread_chebyshev", &pk, &spread_in)
                                    .remove("out")
                                    .unwrap(),
                                run_node(gpu, "interpolate_chebyshev", &pk, &interp_in)
                                    .remove("out")
                                    .unwrap(),
                            )
                        },
                    );
                    let what = format!("{comps} comps, {window}, {walls}, {kernel} {subgroups:?}");
                    let (err, at) = rel_max_err(&spread, &want_spread);
                    assert!(err <= 2e-6, "spread, {what}: {err:e} at {at}");
                    let (err, at) = rel_max_err(&interp, &want_interp);
                    assert!(err <= 2e-6, "interpolate, {what}: {err:e} at {at}");
                }
            }
        }
    }
}

/// `kernel: lanes` on an adapter without subgroups is refused when the kernels are built.
#[test]
fn chebyshev_lanes_need_subgroups() {
    let Some(mut gpu) = gpu() else { return };
    let p = with_kernel(&cheb_params(ES, "bottom"), "lanes");
    let data = named(&[
        ("positions", flat_particles(&[0.0, 0.0, 1.0], 3)),
        ("values", flat_particles(&[1.0; 3], 3)),
    ]);
    let err = with_caps(
        &mut gpu,
        |c| c.subgroups = None,
        |gpu| compile_error(gpu, "spread_chebyshev", &p, &data),
    );
    assert!(err.contains("subgroups"), "{err}");
}
