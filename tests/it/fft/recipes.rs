//! FFT plans without a GPU: size rules, recipes that fit the device, generated passes
//! validated by naga, the recipe as `inspect` prints it.

use mesoflow::gpu::DeviceCaps;
use mesoflow::nodes::fft::{codegen, next_friendly, plan};
use mesoflow::plan::PlanOptions;
use mesoflow::value::ValueType;

use crate::util::fft::{caps_with, chain};
use crate::util::{load, single_node_graph, tmpdir, validate_wgsl, validation_error, write_graph};

#[test]
fn unfriendly_sizes_are_plan_errors_naming_the_next_friendly_size() {
    let e = validation_error(
        "fft",
        "{}",
        &[(
            "x",
            ValueType::ComplexGrid {
                dims: [16, 97, 8],
                comps: 1,
            },
        )],
    );
    assert!(
        e.contains("node `n`, port `x`")
            && e.contains(
                "size 97 along y is not a product of 2, 3, 5, 7; the next friendly size is 98"
            ),
        "{e}"
    );
    let e = validation_error(
        "irfft",
        "{}",
        &[(
            "x",
            ValueType::HalfComplexGrid {
                dims: [11, 4, 4],
                comps: 1,
            },
        )],
    );
    assert!(e.contains("size 11 along x") && e.contains("is 12"), "{e}");
    let e = validation_error(
        "rfft",
        "{}",
        &[(
            "x",
            ValueType::RealGrid {
                dims: [8, 8, 5000],
                comps: 1,
            },
        )],
    );
    assert!(e.contains("size 5000 along z is longer than 4096"), "{e}");
    // An axis that is not transformed may have any size.
    let dir = tmpdir("fft-errors");
    let path = write_graph(
        &dir,
        "g.json",
        &single_node_graph(
            "fft",
            r#"{"axes": "xy"}"#,
            &[(
                "x",
                ValueType::ComplexGrid {
                    dims: [16, 12, 97],
                    comps: 1,
                },
            )],
        ),
    );
    mesoflow::plan::validate_file(crate::util::registry(), &path).unwrap();
    assert_eq!(next_friendly(97), 98);
    assert_eq!(next_friendly(1025), 1029);
}

fn recipe(kind: plan::Kind, dims: [u32; 3], spectral: bool, c: &DeviceCaps) -> plan::Recipe {
    let key = plan::Key {
        kind,
        dims,
        comps: 3,
        axes: [true; 3],
        spectral,
        inverse_after: false,
        limits: plan::Limits::of(c),
    };
    (*plan::recipe(&key).unwrap()).clone()
}

#[test]
fn recipes_fit_the_device_and_read_and_write_each_line_once_per_axis() {
    let nvidia = caps_with(48 << 10, 1024);
    let lavapipe = caps_with(32 << 10, 1024);
    for n in [64, 81, 96, 128, 162, 189, 216, 256, 336, 375, 384, 432, 512] {
        for c in [&nvidia, &lavapipe] {
            for kind in [plan::Kind::RealForward, plan::Kind::RealInverse] {
                let r = recipe(kind, [n, n, n], false, c);
                assert_eq!(r.passes.len(), 3, "one pass per axis");
                for p in &r.passes {
                    assert!(8 * p.shared <= c.max_workgroup_storage, "{n}: {p:?}");
                    assert!(p.threads() <= c.max_invocations, "{n}: {p:?}");
                    assert!(p.registers <= 32, "{n}: {p:?}");
                    assert_eq!(p.radices.iter().product::<u32>(), p.n);
                }
            }
        }
        // Folding a 3-component spectral node keeps the last pass on chip.
        let r = recipe(plan::Kind::RealForward, [n, n, n], true, &nvidia);
        let last = r.passes.last().unwrap();
        assert!(last.spectral && last.comps_per_line() == 3, "{n}: {last:?}");
    }
    // Lines longer than the device's workgroup memory are a clear error.
    let key = plan::Key {
        kind: plan::Kind::Forward,
        dims: [4096, 1, 1],
        comps: 1,
        axes: [true; 3],
        spectral: false,
        inverse_after: false,
        limits: plan::Limits::of(&DeviceCaps::baseline()),
    };
    let e = plan::recipe(&key).unwrap_err();
    assert!(
        e.contains("1 4096-point line along x needs 32768 bytes of workgroup memory")
            && e.contains("this device has 16384 bytes"),
        "{e}"
    );
    // The inverse real transform goes through scratch (its input stays intact).
    let r = recipe(plan::Kind::RealInverse, [64, 64, 64], false, &nvidia);
    assert_eq!(r.scratch, 8 * 33 * 64 * 64 * 3);
    assert_eq!(r.passes[0].src, plan::Buf::Input);
    assert_eq!(r.passes[2].dst, plan::Buf::Output);
}

#[test]
fn generated_passes_validate_with_naga() {
    let body = mesoflow::transform::SpectralBody {
        body: "return v;".into(),
        ..Default::default()
    };
    let nvidia = caps_with(48 << 10, 1024);
    let mut n = 0;
    for (kind, dims) in [
        (plan::Kind::Forward, [8, 6, 5]),
        (plan::Kind::Inverse, [1, 1, 1]),
        (plan::Kind::RealForward, [96, 7, 375]),
        (plan::Kind::RealInverse, [81, 10, 4]),
        (plan::Kind::RealInverse, [2, 1, 1]),
    ] {
        for spectral in [false, true] {
            let r = recipe(kind, dims, spectral, &nvidia);
            let fold = codegen::Fold {
                body: &body,
                dims,
                stored: r.spectrum_dims(),
                half: matches!(kind, plan::Kind::RealForward | plan::Kind::RealInverse),
            };
            for p in &r.passes {
                let src = codegen::source(p, spectral.then_some(&fold));
                validate_wgsl("generated pass", &src, naga::valid::Capabilities::empty());
                n += 1;
            }
        }
    }
    // Last passes that transform their lines back (the inverse's first pass folded in).
    for dims in [[96, 7, 375], [81, 10, 4], [16, 12, 1]] {
        let key = plan::Key {
            kind: plan::Kind::RealForward,
            dims,
            comps: 3,
            axes: [true; 3],
            spectral: true,
            inverse_after: true,
            limits: plan::Limits::of(&nvidia),
        };
        let r = plan::recipe(&key).unwrap();
        let last = r.passes.last().unwrap();
        assert!(
            last.inverse_after && last.seq_comps == 3,
            "{dims:?}: {last:?}"
        );
        let fold = codegen::Fold {
            body: &body,
            dims,
            stored: r.spectrum_dims(),
            half: true,
        };
        let src = codegen::source(last, Some(&fold));
        validate_wgsl("generated pass", &src, naga::valid::Capabilities::empty());
        n += 1;
    }
    assert!(n > 18);
}

#[test]
fn inspect_shows_the_recipe() {
    let dir = tmpdir("fft-inspect");
    let ty = ValueType::RealGrid {
        dims: [64, 48, 20],
        comps: 3,
    };
    let g = load(&write_graph(
        &dir,
        "g.json",
        &chain("rfft", "irfft", ty, "xyz"),
    ));
    let opts = PlanOptions {
        outputs: None,
        inputs: [("x".to_string(), ty)].into_iter().collect(),
        fuse: true,
        in_place: true,
    };
    let p = mesoflow::plan::plan(&g, &opts, &caps_with(48 << 10, 1024)).unwrap();
    let text = mesoflow::plan::to_text(&g, &p);
    for want in [
        "forward, e^(-2 pi i k.x/n), unnormalised; radices x 8x4 (32 packed pairs), y 4x4x3, z 4x5",
        "inverse, e^(+2 pi i k.x/n), times 1/61440",
        "pass 1: x forward real -> half spectrum, 32-point on packed pairs + unfold, radices 8x4",
        "pass 3: x inverse half spectrum -> real, fold + 32-point on packed pairs",
        "scale 1/61440",
        "(scratch 0)",
    ] {
        assert!(text.contains(want), "missing `{want}` in\n{text}");
    }
}
