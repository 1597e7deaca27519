//! FFT nodes against rustfft in f64 (through their CPU references), round trips, Hermitian
//! consistency of the real transforms, size rules, recipes, generated WGSL, and spectral
//! nodes folded into a transform. Data-driven: one `check` line per case.

use std::collections::BTreeMap;
use std::sync::{Mutex, OnceLock};

use mesoflow::exec::{Profile, Program, RunOptions};
use mesoflow::gpu::{DeviceCaps, GpuContext, KernelCache};
use mesoflow::graph::Graph;
use mesoflow::nodes::fft::{codegen, next_friendly, plan};
use mesoflow::plan::{Launch, PlanOptions, TransformFold};
use mesoflow::value::{HostArray, ValueType};

use crate::util::{Rng, gpu, load, reference, single_node_graph, tmpdir, write_graph};

/// Relative L2 error of `got` against `want`: |got - want| / |want|.
fn rel_l2(got: &[f64], want: &[f64]) -> f64 {
    assert_eq!(got.len(), want.len());
    let num: f64 = got.iter().zip(want).map(|(a, b)| (a - b) * (a - b)).sum();
    let den: f64 = want.iter().map(|b| b * b).sum();
    (num / den.max(f64::MIN_POSITIVE)).sqrt()
}

/// Runs a graph with one kernel cache for the whole module: the cases share many passes
/// (and lavapipe compiles pipelines slowly).
fn run(
    gpu: &GpuContext,
    g: &Graph,
    inputs: &BTreeMap<String, HostArray>,
    fuse: bool,
) -> (BTreeMap<String, HostArray>, mesoflow::plan::Plan) {
    run_outputs(gpu, g, inputs, fuse, None)
}

/// `run` for the named outputs only (None: all).
fn run_outputs(
    gpu: &GpuContext,
    g: &Graph,
    inputs: &BTreeMap<String, HostArray>,
    fuse: bool,
    outputs: Option<&[&str]>,
) -> (BTreeMap<String, HostArray>, mesoflow::plan::Plan) {
    static CACHE: OnceLock<Mutex<KernelCache>> = OnceLock::new();
    let mut cache = CACHE
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|p| p.into_inner());
    let opts = PlanOptions {
        outputs: outputs.map(|o| o.iter().map(|s| s.to_string()).collect()),
        inputs: inputs.iter().map(|(k, v)| (k.clone(), v.ty)).collect(),
        fuse,
    };
    let p = mesoflow::plan::plan(g, &opts, &gpu.caps).unwrap_or_else(|e| panic!("{e}"));
    let mut program = Program::compile(gpu, g, &p, &mut cache).unwrap_or_else(|e| panic!("{e}"));
    program.upload(inputs).unwrap();
    program
        .run(&RunOptions {
            steps: 1,
            profile: Profile::Off,
            progress: false,
        })
        .unwrap_or_else(|e| panic!("{e}"));
    let out = program.read_outputs().unwrap().into_iter().collect();
    (out, p)
}

fn grid(kind: &str, dims: [u32; 3], comps: u32) -> ValueType {
    match kind {
        "fft" | "ifft" => ValueType::ComplexGrid { dims, comps },
        "rfft" => ValueType::RealGrid { dims, comps },
        _ => ValueType::HalfComplexGrid { dims, comps },
    }
}

fn seed(dims: [u32; 3], comps: u32) -> u64 {
    dims.iter().map(|&d| d as u64).product::<u64>() * 31 + comps as u64
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
    let dir = tmpdir("fft-check");
    let path = write_graph(
        &dir,
        "g.json",
        &single_node_graph(kind, &params, &[("x", ty)]),
    );
    let g = load(&path);
    let x = Rng::new(seed(dims, comps)).array(ty, -1.0, 1.0);
    let data = [("x".to_string(), x.clone())].into_iter().collect();
    let (out, _) = run(&gpu, &g, &data, true);
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

/// A two-node graph: `first` then `second`, both over `axes`.
fn chain(first: &str, second: &str, ty: ValueType, axes: &str) -> String {
    format!(
        r#"{{"mesoflow": 1, "inputs": {{"x": {}}},
          "nodes": [
            {{"id": "a", "kind": "{first}", "params": {{"axes": "{axes}"}}, "inputs": {{"x": "inputs.x"}}}},
            {{"id": "b", "kind": "{second}", "params": {{"axes": "{axes}"}}, "inputs": {{"x": "a.out"}}}}
          ],
          "outputs": {{"a": "a.out", "b": "b.out"}}}}"#,
        crate::util::input_decl(&ty)
    )
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
        let (out, _) = run(&gpu, &g, &data, true);
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
            run(&gpu, &g, &data, true)
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

fn plan_error(kind: &str, params: &str, ty: ValueType) -> String {
    let dir = tmpdir("fft-errors");
    let path = write_graph(
        &dir,
        "g.json",
        &single_node_graph(kind, params, &[("x", ty)]),
    );
    mesoflow::plan::validate_file(crate::util::registry(), &path)
        .unwrap_err()
        .to_string()
}

#[test]
fn unfriendly_sizes_are_plan_errors_naming_the_next_friendly_size() {
    let e = plan_error(
        "fft",
        "{}",
        ValueType::ComplexGrid {
            dims: [16, 97, 8],
            comps: 1,
        },
    );
    assert!(
        e.contains("node `n`, port `x`")
            && e.contains(
                "size 97 along y is not a product of 2, 3, 5, 7; the next friendly size is 98"
            ),
        "{e}"
    );
    let e = plan_error(
        "irfft",
        "{}",
        ValueType::HalfComplexGrid {
            dims: [11, 4, 4],
            comps: 1,
        },
    );
    assert!(e.contains("size 11 along x") && e.contains("is 12"), "{e}");
    let e = plan_error(
        "rfft",
        "{}",
        ValueType::RealGrid {
            dims: [8, 8, 5000],
            comps: 1,
        },
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

fn caps(shared: u32, threads: u32) -> DeviceCaps {
    DeviceCaps {
        max_workgroup_storage: shared,
        max_invocations: threads,
        ..DeviceCaps::baseline()
    }
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
    let nvidia = caps(48 << 10, 1024);
    let lavapipe = caps(32 << 10, 1024);
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

/// Parses and validates a generated pass with naga (panics with the located error).
fn naga_validate(src: &str) {
    let module =
        naga::front::wgsl::parse_str(src).unwrap_or_else(|e| panic!("{}", e.emit_to_string(src)));
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::empty(),
    )
    .validate(&module)
    .unwrap_or_else(|e| panic!("{}", e.emit_to_string(src)));
}

#[test]
fn generated_passes_validate_with_naga() {
    let body = mesoflow::transform::SpectralBody {
        body: "return v;".into(),
        ..Default::default()
    };
    let nvidia = caps(48 << 10, 1024);
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
                naga_validate(&src);
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
        naga_validate(&src);
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
    };
    let p = mesoflow::plan::plan(&g, &opts, &caps(48 << 10, 1024)).unwrap();
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
        crate::util::input_decl(&ty)
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
        let (fused, fused_plan) = run(&gpu, &g, &data, true);
        let (plain, plain_plan) = run(&gpu, &g, &data, false);
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
        let (conv, conv_plan) = run_outputs(&gpu, &g, &data, true, Some(&["y"]));
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
    };
    let p = mesoflow::plan::plan(&g, &opts, &caps(48 << 10, 1024)).unwrap();
    assert_eq!(p.step.len(), 3);
    assert!(p.step.iter().all(|l| !matches!(
        l,
        Launch::Transform {
            fold: TransformFold::Hosts(_),
            ..
        }
    )));
}
