//! Every node kind against its f64 CPU reference on the GPU, through single-node graph
//! files (data-driven: one `check` call per case).

use mesoflow::value::{HostArray, ValueType};

use crate::util::{
    Rng, gpu, load_single_node, registry, rel_max_err, run_node_and_reference, validation_error,
};

/// Runs `kind` with `params` on random inputs of the given types and compares every
/// output with the CPU reference, relative to the output's largest magnitude.
fn check(kind: &str, params: &str, inputs: &[(&str, ValueType)], tol: f64) {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(kind.len() as u64 * 7919 + inputs.len() as u64);
    let data: Vec<(&str, HostArray)> = inputs
        .iter()
        .map(|(n, t)| (*n, rng.array(*t, 0.5, 2.0)))
        .collect();
    let (out, refs) = run_node_and_reference(kind, params, &data);
    let ports = registry().get(kind).expect("a registered kind").outputs();
    for (port, r) in ports.iter().zip(&refs) {
        let got = &out[port.name];
        let (err, at) = rel_max_err(got, r);
        assert!(
            err <= tol,
            "{kind} {params} output {}: relative error {err:e} at element {at} (tolerance {tol:e})",
            port.name
        );
    }
}

type Case<'a> = (&'a str, &'a str, &'a [(&'a str, ValueType)]);

const P: fn(u32, u32) -> ValueType = |n, k| ValueType::Particles { n, k };

/// f32 element-wise arithmetic: a few ulps of the result.
const ELEMENTWISE_TOL: f64 = 4.0 * f32::EPSILON as f64;

#[test]
fn pointwise_kinds_match_their_references() {
    let cases: &[Case] = &[
        ("scale", r#"{"factor": -2.5}"#, &[("x", P(1000, 3))]),
        ("add", "{}", &[("a", P(257, 3)), ("b", P(257, 3))]),
        ("add", "{}", &[("a", P(257, 3))]),
        ("add", "{}", &[("a", P(33, 2)), ("b", ValueType::Scalar)]),
        ("sub", "{}", &[("a", ValueType::Scalar), ("b", P(33, 2))]),
        ("multiply", "{}", &[("a", P(100, 1)), ("b", P(100, 1))]),
        // One column broadcast over the other's columns (charges times fields).
        ("multiply", "{}", &[("a", P(100, 1)), ("b", P(100, 3))]),
        ("multiply", "{}", &[("a", P(100, 3)), ("b", P(100, 1))]),
        ("divide", "{}", &[("a", P(100, 4)), ("b", P(100, 4))]),
        (
            "axpy",
            r#"{"alpha": 0.3}"#,
            &[("x", P(513, 3)), ("y", P(513, 3))],
        ),
        (
            "axpby",
            r#"{"alpha": 0.3, "beta": -1.7}"#,
            &[("x", P(5, 3)), ("y", P(5, 3))],
        ),
        ("affine", r#"{"scale": 3, "offset": -1}"#, &[("x", P(7, 2))]),
        // Steps of up to 1.5 in boxes of 1 and 1.2: wrapped, and an open axis.
        (
            "unwrap",
            r#"{"box": [1.0, 1.2]}"#,
            &[
                ("unwrapped", P(300, 2)),
                ("before", P(300, 2)),
                ("after", P(300, 2)),
            ],
        ),
        (
            "unwrap",
            r#"{"box": [0.9, 0, 1.1]}"#,
            &[
                ("unwrapped", P(300, 3)),
                ("before", P(300, 3)),
                ("after", P(300, 3)),
            ],
        ),
        (
            "scale_components",
            r#"{"factors": [1, -2, 0.5]}"#,
            &[("x", P(65, 3))],
        ),
        (
            "offset_components",
            r#"{"offsets": [1, -2, 0.5, 4]}"#,
            &[("x", P(65, 4))],
        ),
        (
            "scale",
            r#"{"factor": 2}"#,
            &[(
                "x",
                ValueType::RealGrid {
                    dims: [8, 4, 3],
                    comps: 2,
                },
            )],
        ),
        (
            "scale_components",
            r#"{"factors": [2, 3]}"#,
            &[(
                "x",
                ValueType::RealGrid {
                    dims: [4, 4, 4],
                    comps: 2,
                },
            )],
        ),
        ("scale", r#"{"factor": 2}"#, &[("x", ValueType::Scalar)]),
        // Real-linear kinds on spectra (real and imaginary parts alike).
        ("add", "{}", &[("a", H), ("b", H)]),
        (
            "axpby",
            r#"{"alpha": 0.5, "beta": -2}"#,
            &[("x", H), ("y", H)],
        ),
        ("scale", r#"{"factor": -3}"#, &[("x", H)]),
    ];
    for (kind, params, inputs) in cases {
        check(kind, params, inputs, ELEMENTWISE_TOL);
    }
    // Walls at 0.3 and 2.2 with a range of 0.56: particles (in [0.5, 2)) within it of
    // either wall, some closer than sigma / 2 (clamped), the others force-free. The
    // twelfth power costs a few more roundings than plain arithmetic.
    let walls: Case = (
        "wall_force",
        r#"{"bottom": 0.3, "top": 2.2, "epsilon": 0.7, "sigma": 0.5}"#,
        &[("x", P(999, 3))],
    );
    check(walls.0, walls.1, walls.2, 64.0 * f32::EPSILON as f64);
}

/// Columns taken apart and put together, against their references (raw word copies:
/// exact).
#[test]
fn columns_and_concat_match_their_references() {
    let cases: &[Case] = &[
        (
            "columns",
            r#"{"first": 3, "count": 3}"#,
            &[("x", P(301, 6))],
        ),
        ("columns", r#"{"first": 1, "count": 1}"#, &[("x", P(5, 4))]),
        ("columns", r#"{"first": 0, "count": 3}"#, &[("x", P(7, 3))]),
        ("concat", "{}", &[("a", P(301, 3)), ("b", P(301, 3))]),
        (
            "concat",
            r#"{"cols": 4}"#,
            &[("a", P(9, 1)), ("b", P(9, 3))],
        ),
        ("concat", r#"{"cols": 6}"#, &[("a", P(33, 3))]),
        ("concat", "{}", &[("a", P(33, 2))]),
    ];
    for (kind, params, inputs) in cases {
        check(kind, params, inputs, 0.0);
    }
}

const H: ValueType = ValueType::HalfComplexGrid {
    dims: [6, 5, 4],
    comps: 3,
};

#[test]
fn spectra_take_no_scalar_broadcast() {
    let (dir, g) = load_single_node("add", "{}", &[("a", H), ("b", ValueType::Scalar)]);
    let opts = mesoflow::plan::PlanOptions {
        outputs: None,
        inputs: [("a".to_string(), H), ("b".to_string(), ValueType::Scalar)]
            .into_iter()
            .collect(),
        fuse: true,
        in_place: true,
    };
    let e = mesoflow::plan::plan(&g, &opts, &mesoflow::gpu::DeviceCaps::baseline())
        .unwrap_err()
        .to_string();
    let _ = std::fs::remove_dir_all(&dir);
    assert!(e.contains("cannot be broadcast"), "{e}");
}

/// Generators and recorders with no or trivial inputs, against their references.
#[test]
fn stokes_noise_and_record_match_their_references() {
    // Even and odd sizes: the Hermitian pairs on the planes kx = 0 and kx = nx/2.
    check(
        "stokes_noise",
        r#"{"box": [2, 1.5, 1], "grid": [8, 6, 5], "viscosity": 0.8, "noise": 0.3, "seed": 9, "stream": 4}"#,
        &[],
        2e-6,
    );
    check(
        "stokes_noise",
        r#"{"box": [1, 1, 1], "grid": [7, 4, 6], "viscosity": 1.0, "seed": 1}"#,
        &[],
        2e-6,
    );
    check(
        "record",
        r#"{"every": 1, "frames": 3}"#,
        &[("x", P(17, 3))],
        0.0,
    );
}

#[test]
fn pointwise_kinds_handle_empty_and_single_element_arrays() {
    for n in [0, 1] {
        check(
            "axpy",
            r#"{"alpha": 2}"#,
            &[("x", P(n, 3)), ("y", P(n, 3))],
            ELEMENTWISE_TOL,
        );
        check(
            "scale_components",
            r#"{"factors": [1, 2, 3]}"#,
            &[("x", P(n, 3))],
            ELEMENTWISE_TOL,
        );
    }
}

#[test]
fn per_component_values_must_match_the_components() {
    let err = validation_error(
        "scale_components",
        r#"{"factors": [1, 2]}"#,
        &[("x", P(4, 3))],
    );
    assert!(
        err.contains("2 per-component values given for a value with 3 components"),
        "{err}"
    );
}
