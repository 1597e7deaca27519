//! Philox random numbers: the GPU draws equal the Rust implementation bit for bit, do not
//! depend on dispatch shape or fusion, and pass statistical tests.

use std::collections::BTreeMap;

use mesoflow::nodes::random;
use mesoflow::value::HostArray;

use crate::util::{erfc, f32s, gpu, load, run_graph, tmpdir, u32s, write_graph};

fn graph(nodes: &str, outputs: &str) -> String {
    format!(r#"{{"mesoflow": 1, "nodes": [{nodes}], "outputs": {{{outputs}}}}}"#)
}

fn run(json: &str, steps: u64, fuse: bool) -> BTreeMap<String, HostArray> {
    let gpu = gpu().expect("checked by the caller");
    let dir = tmpdir("random");
    let g = load(&write_graph(&dir, "g.json", json));
    run_graph(&gpu, &g, &BTreeMap::new(), None, steps, fuse)
}

/// Seeds whose halves are NaN bit patterns as f32 (they travel through f32 params).
const SEEDS: [u64; 3] = [0, 42, random::MAX_SEED as u64];

#[test]
fn gpu_words_equal_rust_bit_for_bit() {
    if gpu().is_none() {
        return;
    }
    for seed in SEEDS {
        for (stream, steps) in [(0u32, 1u64), (7, 6), (u32::MAX, 2)] {
            let n = 4099; // not a multiple of 4 nor of the workgroup size
            let json = graph(
                &format!(
                    r#"{{"id": "r", "kind": "random_bits", "params": {{"seed": {seed}, "stream": {stream}, "count": {n}}}}}"#
                ),
                r#""w": "r.out""#,
            );
            let got = u32s(&run(&json, steps, true)["w"]);
            for (i, w) in got.iter().enumerate() {
                let want = random::bits(i as u64, steps - 1, seed, stream);
                assert_eq!(
                    *w,
                    want,
                    "seed {seed} stream {stream} step {} element {i}",
                    steps - 1
                );
            }
        }
    }
}

#[test]
fn uniforms_are_exact_and_normals_match_the_f64_reference() {
    if gpu().is_none() {
        return;
    }
    for seed in SEEDS {
        let json = graph(
            &format!(
                r#"{{"id": "u", "kind": "random_uniform", "params": {{"seed": {seed}, "stream": 3, "rows": 1001, "cols": 3}}}},
                   {{"id": "g", "kind": "random_normal", "params": {{"seed": {seed}, "stream": 4, "rows": 1001, "cols": 3, "mean": 1, "std": 2}}}}"#
            ),
            r#""u": "u.out", "g": "g.out""#,
        );
        let out = run(&json, 3, true);
        let step = 2;
        for (i, u) in f32s(&out["u"]).iter().enumerate() {
            // 24-bit uniforms are exact in f32.
            assert_eq!(
                *u as f64,
                random::uniform(i as u64, step, seed, 3),
                "uniform {i}"
            );
        }
        for (i, g) in f32s(&out["g"]).iter().enumerate() {
            let want = 1.0 + 2.0 * random::normal(i as u64, step, seed, 4);
            // f32 log, sqrt, cos and sin on the GPU: a few 1e-6 of the spread (std 2).
            assert!(
                (*g as f64 - want).abs() < 2e-5 * 2.0 * (1.0 + want.abs()),
                "normal {i}: {g} vs {want}"
            );
        }
    }
}

#[test]
fn draws_depend_on_step_and_stream_and_not_on_fusion() {
    if gpu().is_none() {
        return;
    }
    // The same normals alone and fused into an axpy; rerunning reproduces them exactly.
    let json = graph(
        r#"{"id": "g", "kind": "random_normal", "params": {"seed": 9, "rows": 777, "cols": 3}},
           {"id": "h", "kind": "random_normal", "params": {"seed": 9, "stream": 1, "rows": 777, "cols": 3}},
           {"id": "y", "kind": "axpy", "params": {"alpha": 1}, "inputs": {"x": "g.out", "y": "h.out"}}"#,
        r#""g": "g.out", "y": "y.out""#,
    );
    let fused = run(&json, 4, true);
    let unfused = run(&json, 4, false);
    assert_eq!(
        f32s(&fused["g"]),
        f32s(&unfused["g"]),
        "fusion changes no draw"
    );
    assert_eq!(f32s(&fused["y"]), f32s(&unfused["y"]));
    assert_eq!(
        f32s(&fused["g"]),
        f32s(&run(&json, 4, true)["g"]),
        "reruns reproduce"
    );
    assert_ne!(
        f32s(&fused["g"]),
        f32s(&run(&json, 3, true)["g"]),
        "steps differ"
    );
}

#[test]
fn normals_pass_statistical_tests() {
    if gpu().is_none() {
        return;
    }
    let n = 1_000_000u64;
    let json = graph(
        &format!(
            r#"{{"id": "a", "kind": "random_normal", "params": {{"seed": 123, "stream": 0, "rows": {n}}}}},
               {{"id": "b", "kind": "random_normal", "params": {{"seed": 123, "stream": 1, "rows": {n}}}}}"#
        ),
        r#""a": "a.out", "b": "b.out""#,
    );
    let out = run(&json, 1, true);
    let a: Vec<f64> = f32s(&out["a"]).iter().map(|&x| x as f64).collect();
    let b: Vec<f64> = f32s(&out["b"]).iter().map(|&x| x as f64).collect();
    let nf = n as f64;
    let mean = a.iter().sum::<f64>() / nf;
    let var = a.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (nf - 1.0);
    // Standard errors: 1/sqrt(n) for the mean, sqrt(2/n) for the variance; 5 sigma.
    assert!(mean.abs() < 5.0 / nf.sqrt(), "mean {mean}");
    assert!(
        (var - 1.0).abs() < 5.0 * (2.0 / nf).sqrt(),
        "variance {var}"
    );
    // Kolmogorov-Smirnov against the normal CDF; 1.95/sqrt(n) is the 0.1% critical value.
    let mut s = a.clone();
    s.sort_by(|x, y| x.total_cmp(y));
    let mut d: f64 = 0.0;
    for (i, x) in s.iter().enumerate() {
        let cdf = 0.5 * erfc(-x / std::f64::consts::SQRT_2);
        d = d
            .max((cdf - i as f64 / nf).abs())
            .max(((i + 1) as f64 / nf - cdf).abs());
    }
    eprintln!("normals: mean {mean:.2e}, variance {var:.6}, KS distance {d:.2e} (n = {n})");
    assert!(d < 1.95 / nf.sqrt(), "KS distance {d}");
    // Neighbouring streams, and neighbouring elements within a stream, are uncorrelated.
    let corr =
        |x: &[f64], y: &[f64]| x.iter().zip(y).map(|(p, q)| p * q).sum::<f64>() / x.len() as f64;
    let r_streams = corr(&a, &b);
    let r_lag1 = corr(&a[..a.len() - 1], &a[1..]);
    eprintln!("correlation between streams {r_streams:.2e}, lag 1 {r_lag1:.2e}");
    assert!(r_streams.abs() < 5.0 / nf.sqrt() && r_lag1.abs() < 5.0 / nf.sqrt());
}

/// Philox's high-half multiply: the portable form (16-bit halves) and the one 64-bit
/// multiply the engine swaps in on adapters with 64-bit integers give the exact high
/// words, checked against u64 products on the host.
#[test]
fn both_forms_of_the_philox_multiply_are_exact() {
    use mesoflow::gpu::{Binding, CompileCtx, KernelCache, KernelSpec, shaders};
    use wgpu::util::DeviceExt;
    let Some(gpu) = gpu() else {
        return;
    };
    let mut rng = crate::util::Rng::new(77);
    let mut pairs: Vec<u32> = vec![0, 0, 1, 1, u32::MAX, u32::MAX, 0xD2511F53, 0xCD9E8D57];
    for _ in 0..4000 {
        pairs.push((rng.uniform(0.0, 1.0) * 4294967296.0) as u32);
    }
    let n = pairs.len() / 2;
    let src = shaders::resolve(
        "#import common/philox.wgsl\n@group(0) @binding(0) var<storage, read> ab: array<u32>;\n@group(0) @binding(1) var<storage, read_write> hi: array<u32>;\n@compute @workgroup_size(64)\nfn main(@builtin(global_invocation_id) id: vec3<u32>) {\n    let i = id.x;\n    if (i < arrayLength(&hi)) { hi[i] = philox_mulhi(ab[2u * i], ab[2u * i + 1u]); }\n}\n",
    )
    .unwrap();
    let input = gpu
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: None,
            contents: bytemuck::cast_slice(&pairs),
            usage: wgpu::BufferUsages::STORAGE,
        });
    let clock = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: 16,
        usage: wgpu::BufferUsages::STORAGE,
        mapped_at_creation: false,
    });
    let mut kernels = KernelCache::default();
    for portable in [false, true] {
        let out = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: 4 * n as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let mut cx = CompileCtx {
            gpu: &gpu,
            kernels: &mut kernels,
            clock: &clock,
            allocated: Default::default(),
        };
        let mut spec = KernelSpec::new(
            "mulhi",
            src.clone(),
            &[Binding::StorageRead, Binding::StorageReadWrite],
        );
        if portable {
            spec = spec.portable();
        }
        let k = cx.kernel(&spec).unwrap();
        let d = cx.dispatch(&k, &[&input, &out], [(n as u32).div_ceil(64), 1, 1]);
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&d.kernel.pipeline);
            pass.set_bind_group(0, &d.bind_group, &[]);
            pass.dispatch_workgroups(d.workgroups[0], 1, 1);
        }
        gpu.wait(gpu.queue.submit([enc.finish()])).unwrap();
        let got: Vec<u32> =
            bytemuck::pod_collect_to_vec(&gpu.read_buffer(&out, 4 * n as u64).unwrap());
        for i in 0..n {
            let want = ((pairs[2 * i] as u64 * pairs[2 * i + 1] as u64) >> 32) as u32;
            assert_eq!(got[i], want, "portable {portable}: pair {i}");
        }
    }
    // The swap happens where the adapter has 64-bit integers, and only there.
    let specialised = shaders::specialise(&src, &gpu.caps);
    assert_eq!(gpu.caps.int64, specialised.contains("u64(a) * u64(b)"));
}
