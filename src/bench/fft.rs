//! `mesoflow bench fft`: 3-D real transforms of `comps` components on cubic grids, rfft
//! then irfft, through the engine like any graph (the pair end to end, and each launch),
//! with the forward transform's error against rustfft in f64. `benches/torch_fft.py`
//! prints the same columns for cuFFT (through PyTorch, CUDA events around the pair of
//! calls) on the same machine: its "cuFFT ms" compares with "e2e ms" here.

use std::collections::BTreeMap;

use mesoflow::gpu::GpuContext;
use mesoflow::value::{HostArray, RefArray, ValueType, half_dims};

use super::{BenchError, end_to_end_clock, ms, node_reference, time_graph};

/// The graph: rfft -> (spectral_filter, folded into the rfft's last pass) -> irfft.
/// With the filter only the result is an output (a convolution), so the rfft's last
/// pass also runs the irfft's first.
fn graph(n: u32, comps: u32, filter: bool) -> String {
    let (spectrum, extra, outputs) = if filter {
        (
            "g.out",
            r#"{"id": "g", "kind": "spectral_filter", "params": {"sigma": 0.01}, "inputs": {"x": "f.out"}},"#,
            r#""y": "i.out""#,
        )
    } else {
        ("f.out", "", r#""spectrum": "f.out", "y": "i.out""#)
    };
    format!(
        r#"{{"mesoflow": 1, "doc": "rfft + irfft of {comps} x {n}^3",
  "inputs": {{"x": {{"type": "real_grid", "dims": [{n}, {n}, {n}], "comps": {comps}}}}},
  "nodes": [
    {{"id": "f", "kind": "rfft", "inputs": {{"x": "inputs.x"}}}},
    {extra}
    {{"id": "i", "kind": "irfft", "inputs": {{"x": "{spectrum}"}}}}
  ],
  "outputs": {{{outputs}}}}}"#
    )
}

/// Uniform values in [-1, 1) from a fixed xorshift sequence (reproducible inputs).
fn random(len: usize, seed: u64) -> Vec<f32> {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    (0..len)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            ((s >> 40) as f64 / (1u64 << 23) as f64 - 1.0) as f32
        })
        .collect()
}

fn rel_l2(got: impl Iterator<Item = f64>, want: impl Iterator<Item = f64>) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for (a, b) in got.zip(want) {
        num += (a - b) * (a - b);
        den += b * b;
    }
    (num / den.max(f64::MIN_POSITIVE)).sqrt()
}

/// Relative L2 error of component 0 of the GPU spectrum against rustfft (the components
/// are independent, and one keeps the host reference affordable).
fn forward_error(x: &[f32], spectrum: &HostArray, n: u32) -> Result<f64, BenchError> {
    let dims = [n, n, n];
    let cells = (n as usize).pow(3);
    let half = half_dims(dims);
    let half_words = 2 * (half[0] * half[1] * half[2]) as usize;
    let input = RefArray::new(
        ValueType::RealGrid { dims, comps: 1 },
        x[..cells].iter().map(|&v| v as f64).collect(),
    );
    let out = node_reference("rfft", &BTreeMap::new(), &[Some(input)])?;
    let gpu = spectrum.data.to_f64();
    Ok(rel_l2(
        gpu[..half_words].iter().copied(),
        out[0].data.iter().copied(),
    ))
}

/// Bytes a pass-per-axis transform pair moves: per component and direction, the x pass
/// reads the real grid and writes the half spectrum, the y and z passes read and write
/// the half spectrum.
fn bytes_moved(n: u32, comps: u32) -> f64 {
    let n = n as f64;
    let real = 4.0 * n * n * n;
    let half = 8.0 * ((n / 2.0).floor() + 1.0) * n * n;
    2.0 * comps as f64 * (real + 5.0 * half)
}

pub fn run(
    sizes: &[u32],
    comps: u32,
    reps: u64,
    max_ref: u32,
    filter: bool,
) -> Result<(), BenchError> {
    if sizes.is_empty() || comps == 0 || reps == 0 {
        return Err(BenchError::Args(
            "--sizes, --comps and --reps must be non-empty and positive".into(),
        ));
    }
    for &n in sizes {
        if n < 2 || !mesoflow::nodes::fft::is_friendly(n) {
            return Err(BenchError::Args(format!(
                "--sizes: {n} is not a product of 2, 3, 5, 7 (the next friendly size is {})",
                mesoflow::nodes::fft::next_friendly(n)
            )));
        }
    }
    let gpu = GpuContext::new()?;
    outln!("adapter: {}", gpu.caps.summary());
    outln!(
        "rfft + irfft over x, y, z of {comps} components (f32), median of {reps} runs{}; e2e: the \
         pair end to end ({}); launches: sum of the per-launch medians (rfft, irfft); GB/s from e2e",
        if filter {
            "; with a spectral_filter folded into the rfft"
        } else {
            ""
        },
        end_to_end_clock(&gpu)
    );
    outln!(
        "{:>6} {:>10} {:>12} {:>10} {:>10} {:>10} {:>14} {:>12}",
        "size",
        "e2e ms",
        "launches ms",
        "rfft ms",
        "irfft ms",
        "GB/s",
        "error vs f64",
        "round trip"
    );
    for &n in sizes {
        let ty = ValueType::RealGrid {
            dims: [n, n, n],
            comps,
        };
        let x = random(ty.words() as usize, n as u64);
        let inputs = [("x".to_string(), HostArray::f32(ty, x.clone()))]
            .into_iter()
            .collect();
        let timed = time_graph(&gpu, &graph(n, comps, filter), &inputs, reps, true)?;
        let launch_ms = |label: &str| {
            timed
                .timings
                .iter()
                .find(|t| t.label == label || t.label.starts_with(&format!("{label} +")))
                .map(|t| ms(t.median))
                .unwrap_or(f64::NAN)
        };
        let e2e = ms(timed.end_to_end());
        let error = match timed.outputs.get("spectrum") {
            Some(spectrum) if n <= max_ref => format!("{:.2e}", forward_error(&x, spectrum, n)?),
            _ => "-".into(),
        };
        let y = timed
            .outputs
            .get("y")
            .ok_or_else(|| BenchError::Wrong("the transform graph gave no output `y`".into()))?;
        let round_trip = if filter {
            "-".into()
        } else {
            format!(
                "{:.2e}",
                rel_l2(y.data.to_f64().into_iter(), x.iter().map(|&v| v as f64))
            )
        };
        outln!(
            "{n:>6} {e2e:>10.4} {:>12.4} {:>10.4} {:>10.4} {:>10.1} {error:>14} {round_trip:>12}",
            ms(timed.launch_sum()),
            launch_ms("f"),
            launch_ms("i"),
            bytes_moved(n, comps) / (e2e * 1e-3) / 1e9,
        );
        for t in &timed.timings {
            out!("{}", t.breakdown());
        }
    }
    outln!(
        "GB/s: bytes a pass-per-axis scheme moves (each pass reads and writes the grid once) over the time"
    );
    Ok(())
}
