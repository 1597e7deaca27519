//! Spectral nodes folded into a transform: the same results as unfolded and as the f64
//! references, the inverse's first pass folded where it can be, and no folding where
//! the spectrum has other readers.

use std::collections::BTreeMap;

use mesoflow::plan::{Launch, PlanOptions, TransformFold};
use mesoflow::value::{HostArray, ValueType};

use crate::util::fft::{caps_with, seed};
use crate::util::{Rng, gpu, input_decl, load, reference, rel_l2, run_cached, tmpdir, write_graph};

/// rfft -> spectral node -> irfft (or fft -> ... -> ifft), with the outputs of every node.
fn convolution(fwd: &str, spectral: &str, params: &str, inv: &str, ty: ValueType) -> String {
    format!(
        r#"{{"mesoflow": 1, "inputs": {{"x": {}}},
          "nodes": [
            {{"id": "f", "kind": "{fwd}", "inputs": {{"x": "inputs.x"}}}},
            {{"id": "g", "kind": "{spectral}", "params": {params}, "inputs": {{"x": "f.out"}}}},
            {{"id": "i", "kind": "{inv}", "inputs": {{"x": "g.out"}}}}
          ],
          "outputs": {{"y": "i.out", "spectrum": "g.out"}}}}"#,
        input_decl(&ty)
    )
}

#[test]
fn spectral_nodes_fold_into_the_forward_transform() {
    let Some(gpu) = gpu() else { return };
    let cases: &[(&str, &str, &str, &str, ValueType)] = &[
        (
            "rfft",
            "spectral_filter",
            r#"{"sigma": 0.05, "box": [1.0, 1.5, 2.0]}"#,
            "irfft",
            ValueType::RealGrid {
                dims: [16, 12, 10],
                comps: 2,
            },
        ),
        (
            "rfft",
            "solenoidal_projection",
            r#"{"box": [1.0, 2.0, 0.5]}"#,
            "irfft",
            ValueType::RealGrid {
                dims: [15, 8, 6],
                comps: 3,
            },
        ),
        (
            "fft",
            "solenoidal_projection",
            r#"{"box": [2.0, 1.0, 1.0]}"#,
            "ifft",
            ValueType::ComplexGrid {
                dims: [8, 6, 5],
                comps: 3,
            },
        ),
        (
            "rfft",
            "spectral_filter",
            r#"{"sigma": 0.1}"#,
            "irfft",
            ValueType::RealGrid {
                dims: [16, 1, 1],
                comps: 3,
            },
        ),
        // Even sizes on every axis: the curl's unpaired Nyquist planes.
        (
            "rfft",
            "curl",
            r#"{"box": [1.0, 1.5, 2.0], "scale": 0.5}"#,
            "irfft",
            ValueType::RealGrid {
                dims: [16, 12, 10],
                comps: 3,
            },
        ),
        (
            "rfft",
            "stokes",
            r#"{"box": [1.0, 1.5, 2.0], "viscosity": 0.7}"#,
            "irfft",
            ValueType::RealGrid {
                dims: [16, 12, 9],
                comps: 3,
            },
        ),
        // With Fourier-space noise (the clock is bound to the folded pass).
        (
            "rfft",
            "stokes",
            r#"{"box": [2.0, 1.0, 1.5], "viscosity": 1.3, "noise": 0.4, "seed": 77, "stream": 2}"#,
            "irfft",
            ValueType::RealGrid {
                dims: [12, 10, 8],
                comps: 3,
            },
        ),
        (
            "rfft",
            "spectral_filter",
            r#"{"sigma": 0.1}"#,
            "irfft",
            ValueType::RealGrid {
                dims: [15, 1, 1],
                comps: 2,
            },
        ),
    ];
    for &(fwd, spectral, params, inv, ty) in cases {
        let dir = tmpdir("fft-fold");
        let g = load(&write_graph(
            &dir,
            "g.json",
            &convolution(fwd, spectral, params, inv, ty),
        ));
        let x = Rng::new(seed([1, 2, 3], 4)).array(ty, -1.0, 1.0);
        let data: BTreeMap<String, HostArray> =
            [("x".to_string(), x.clone())].into_iter().collect();
        let (fused, fused_plan) = run_cached(&gpu, &g, &data, None, 1, true);
        let (plain, plain_plan) = run_cached(&gpu, &g, &data, None, 1, false);
        // Folded: two launches (the spectral node runs inside the forward transform).
        assert_eq!(fused_plan.step.len(), 2, "{spectral}");
        assert!(
            matches!(
                &fused_plan.step[0],
                Launch::Transform {
                    fold: TransformFold::Hosts(_),
                    ..
                }
            ),
            "{spectral}"
        );
        assert_eq!(plain_plan.step.len(), 3);
        // The same f32 operations on the same values, folded or not.
        for out in ["y", "spectrum"] {
            let e = rel_l2(&fused[out].data.to_f64(), &plain[out].data.to_f64());
            assert!(e <= 1e-6, "{spectral} {out}: folded vs unfolded {e:e}");
        }
        // Against the f64 references of the three nodes in a row.
        let s = &reference(fwd, "{}", &[Some(&x)])[0].to_host();
        let f = &reference(spectral, params, &[Some(s)])[0];
        let y = &reference(inv, "{}", &[Some(&f.to_host())])[0];
        let e = rel_l2(&fused["spectrum"].data.to_f64(), &f.data);
        assert!(e <= 2e-6, "{spectral} spectrum vs reference: {e:e}");
        let e = rel_l2(&fused["y"].data.to_f64(), &y.data);
        assert!(e <= 4e-6, "{spectral} y vs reference: {e:e}");
        // With the spectrum not asked for, a real transform over y or z also runs the
        // inverse's first pass in the forward's last (the complex inverse starts along
        // x, the forward ends along z: not folded; 1-D: one pass each).
        let (conv, conv_plan) = run_cached(&gpu, &g, &data, Some(&["y"]), 1, true);
        let inverse_folded = conv_plan.step.iter().any(|l| {
            matches!(
                l,
                Launch::Transform {
                    fold: TransformFold::Hosts(mesoflow::plan::FoldedSpectral {
                        inverse: Some(_),
                        ..
                    }),
                    ..
                }
            )
        });
        let after = conv_plan.step.iter().any(|l| {
            matches!(
                l,
                Launch::Transform {
                    fold: TransformFold::FirstPassElsewhere,
                    ..
                }
            )
        });
        let dims = match ty {
            ValueType::RealGrid { dims, .. } | ValueType::ComplexGrid { dims, .. } => dims,
            _ => unreachable!("grid cases"),
        };
        let expect = fwd == "rfft" && dims[1..].iter().any(|&d| d > 1);
        assert_eq!((inverse_folded, after), (expect, expect), "{spectral} {ty}");
        let e = rel_l2(&conv["y"].data.to_f64(), &plain["y"].data.to_f64());
        assert!(
            e <= 1e-6,
            "{spectral}: y with the inverse's first pass folded {e:e}"
        );
    }
}

#[test]
fn a_spectrum_with_other_readers_is_not_folded() {
    let dir = tmpdir("fft-nofold");
    let ty = ValueType::RealGrid {
        dims: [16, 16, 16],
        comps: 3,
    };
    let json = convolution("rfft", "spectral_filter", r#"{"sigma": 0.1}"#, "irfft", ty)
        .replace(r#""spectrum": "g.out""#, r#""spectrum": "f.out""#);
    let g = load(&write_graph(&dir, "g.json", &json));
    let opts = PlanOptions {
        outputs: None,
        inputs: [("x".to_string(), ty)].into_iter().collect(),
        fuse: true,
        in_place: true,
    };
    let p = mesoflow::plan::plan(&g, &opts, &caps_with(48 << 10, 1024)).unwrap();
    assert_eq!(p.step.len(), 3);
    assert!(p.step.iter().all(|l| !matches!(
        l,
        Launch::Transform {
            fold: TransformFold::Hosts(_),
            ..
        }
    )));
}
