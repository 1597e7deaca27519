//! Reductions against f64 references: every kind, edge sizes, segments, and the accuracy
//! of blocked and compensated sums on 10^6 elements of mixed magnitude.

use mesoflow::value::{HostArray, ValueType};

use crate::util::{Rng, assert_like_reference, gpu, run_node_and_reference};

/// Compares a node with its reference on the given inputs (relative to the largest
/// reference magnitude).
fn check(kind: &str, params: &str, inputs: &[(&str, HostArray)], tol: f64) {
    let sizes: Vec<String> = inputs.iter().map(|(_, a)| a.ty.to_string()).collect();
    assert_like_reference(
        kind,
        params,
        inputs,
        tol,
        &format!("{kind} {params} on {sizes:?}"),
    );
}

fn p(n: u32, k: u32) -> ValueType {
    ValueType::Particles { n, k }
}

#[test]
fn reductions_match_their_references() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(77);
    // Sizes around the vec4 tail and several workgroups; values in [-1, 1).
    for n in [0u32, 1, 2, 3, 5, 1023, 4099, 70_001] {
        let x = rng.array(p(n, 1), -1.0, 1.0);
        let y = rng.array(p(n, 1), -1.0, 1.0);
        // Blocked f32 sums of n terms of size 1: error below ~n^(1/2) eps relative to the
        // terms; measured relative to the result's magnitude, allow 1e-4 at these sizes.
        let tol = if n > 1000 { 1e-4 } else { 1e-6 };
        if n > 0 {
            check("sum", "{}", &[("x", x.clone())], tol);
            check("sum", r#"{"compensated": true}"#, &[("x", x.clone())], 1e-6);
            check("dot", "{}", &[("a", x.clone()), ("b", y.clone())], tol);
            check("norm", "{}", &[("x", x.clone())], 1e-6);
        }
        check("max", "{}", &[("x", x.clone())], 0.0);
        check("min", "{}", &[("x", x)], 0.0);
    }
    // Grids and scalars reduce over every word.
    let g = rng.array(
        ValueType::RealGrid {
            dims: [6, 5, 4],
            comps: 2,
        },
        -1.0,
        1.0,
    );
    check("sum", r#"{"compensated": true}"#, &[("x", g.clone())], 1e-6);
    check("max", "{}", &[("x", g)], 0.0);
    check(
        "norm",
        "{}",
        &[("x", rng.array(ValueType::Scalar, -1.0, 1.0))],
        1e-7,
    );
}

#[test]
fn empty_reductions_give_their_identities() {
    if gpu().is_none() {
        return;
    }
    let empty = HostArray::f32(p(0, 3), vec![]);
    for (kind, want) in [
        ("sum", 0.0),
        ("norm", 0.0),
        ("max", f64::NEG_INFINITY),
        ("min", f64::INFINITY),
    ] {
        let (out, refs) = run_node_and_reference(kind, "{}", &[("x", empty.clone())]);
        assert_eq!(out["out"].data.to_f64()[0], want, "{kind} of nothing");
        assert_eq!(refs[0].data[0], want);
    }
}

#[test]
fn column_reductions_match_their_references() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(5);
    for (n, k) in [(1u32, 1u32), (7, 3), (1000, 3), (4097, 4), (20_000, 2)] {
        let x = rng.array(p(n, k), -1.0, 1.0);
        for op in ["sum", "mean"] {
            check(
                "column_reduce",
                &format!(r#"{{"op": "{op}", "compensated": true}}"#),
                &[("x", x.clone())],
                1e-5,
            );
            check(
                "column_reduce",
                &format!(r#"{{"op": "{op}"}}"#),
                &[("x", x.clone())],
                2e-4,
            );
        }
        for op in ["max", "min"] {
            check(
                "column_reduce",
                &format!(r#"{{"op": "{op}"}}"#),
                &[("x", x.clone())],
                0.0,
            );
        }
    }
}

#[test]
fn segment_reductions_match_their_references() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(9);
    let n = 1000u32;
    let values = rng.array(p(n, 3), -1.0, 1.0);
    // Segments of random lengths including empty ones, the last running to the end.
    let mut starts = Vec::new();
    let mut at = 0u32;
    while at < n {
        starts.push(at);
        at += (rng.uniform(0.0, 1.0) * 12.0) as u32; // 0..11 rows: some segments empty
    }
    starts.push(n); // an empty last segment
    let starts = HostArray::u32(
        ValueType::Indices {
            n: starts.len() as u32,
        },
        starts,
    );
    for op in ["sum", "mean", "max", "min"] {
        for comp in [false, true] {
            let params = format!(r#"{{"op": "{op}", "compensated": {comp}}}"#);
            let (out, refs) = run_node_and_reference(
                "segment_reduce",
                &params,
                &[("values", values.clone()), ("starts", starts.clone())],
            );
            let got = out["out"].data.to_f64();
            for (i, (g, r)) in got.iter().zip(&refs[0].data).enumerate() {
                let ok = if r.is_infinite() {
                    g == r
                } else {
                    (g - r).abs() <= 1e-6 * (1.0 + r.abs())
                };
                assert!(ok, "segment_reduce {params}: element {i}: {g} vs {r}");
            }
        }
    }
}

#[test]
fn sums_of_a_million_mixed_magnitudes() {
    if gpu().is_none() {
        return;
    }
    // Magnitudes spread over six decades with random signs: a sum with cancellation.
    let mut rng = Rng::new(2024);
    let n = 1_000_000u32;
    let values: Vec<f32> = (0..n)
        .map(|_| {
            let sign = if rng.uniform(0.0, 1.0) < 0.5 {
                -1.0
            } else {
                1.0
            };
            (sign * 10f64.powf(rng.uniform(-3.0, 3.0))) as f32
        })
        .collect();
    let exact: f64 = values.iter().map(|&x| x as f64).sum();
    let abs_sum: f64 = values.iter().map(|&x| (x as f64).abs()).sum();
    let naive_f32 = values.iter().fold(0f32, |a, &x| a + x) as f64;
    let x = HostArray::f32(p(n, 1), values);
    let blocked = run_node_and_reference("sum", "{}", &[("x", x.clone())]).0["out"]
        .data
        .to_f64()[0];
    let compensated =
        run_node_and_reference("sum", r#"{"compensated": true}"#, &[("x", x)]).0["out"]
            .data
            .to_f64()[0];
    let rel = |v: f64| (v - exact).abs() / abs_sum;
    eprintln!(
        "sum of 1e6 mixed magnitudes, error relative to sum|x| = {abs_sum:.4e} (sum = {exact:.6e}): \
         sequential f32 {:.2e}, blocked {:.2e}, compensated {:.2e}",
        rel(naive_f32),
        rel(blocked),
        rel(compensated)
    );
    // Blocked: ~(n/threads + log2 n) eps at worst; compensated: the final f32 rounding.
    assert!(rel(blocked) < 2e-6, "blocked error {}", rel(blocked));
    assert!(
        (compensated - exact).abs() <= 1.0 * f32::EPSILON as f64 * exact.abs() + 1e-12 * abs_sum,
        "compensated {compensated} vs {exact}"
    );
    assert!(
        rel(blocked) < rel(naive_f32),
        "blocked beats a sequential f32 loop"
    );
}

#[test]
fn compensation_recovers_what_f32_rounding_loses() {
    if gpu().is_none() {
        return;
    }
    // 1e8 followed by ones: in f32, 1e8 + 1 == 1e8 (the spacing there is 8), so every
    // thread that starts from the big value drops its ones; TwoSum keeps them.
    let n = 1_000_000u32;
    let mut v = vec![1f32; n as usize];
    v[0] = 1e8;
    let exact = 1e8 + (n - 1) as f64;
    let x = HostArray::f32(p(n, 1), v.clone());
    let blocked = run_node_and_reference("sum", "{}", &[("x", x.clone())]).0["out"]
        .data
        .to_f64()[0];
    let compensated =
        run_node_and_reference("sum", r#"{"compensated": true}"#, &[("x", x)]).0["out"]
            .data
            .to_f64()[0];
    eprintln!(
        "1e8 + (1e6 - 1) ones: blocked {blocked} (error {}), compensated {compensated} (error {})",
        blocked - exact,
        compensated - exact
    );
    assert!(blocked != exact, "the case defeats plain f32 summation");
    assert!(
        (compensated - exact).abs() <= 8.0,
        "compensated within one f32 spacing: {compensated}"
    );

    // The same per column.
    let rows: Vec<f32> = v.iter().flat_map(|&x| [x, x]).collect();
    let cols = HostArray::f32(p(n, 2), rows);
    let c = run_node_and_reference("column_reduce", r#"{"compensated": true}"#, &[("x", cols)]).0["out"]
        .data
        .to_f64();
    assert!(
        c.iter().all(|s| (s - exact).abs() <= 8.0),
        "column sums {c:?}"
    );

    // And per segment, where one thread adds a whole segment in order. The segment stays
    // under 65535 loop iterations per invocation: lavapipe (llvmpipe) stops longer loops.
    let m = 30_000u32;
    let rows: Vec<f32> = (0..m)
        .flat_map(|i| if i == 0 { [1e8, 1e8] } else { [1.0, 1.0] })
        .collect();
    let seg = HostArray::f32(p(m, 2), rows);
    let starts = HostArray::u32(ValueType::Indices { n: 1 }, vec![0]);
    let exact = 1e8 + (m - 1) as f64;
    let plain = run_node_and_reference(
        "segment_reduce",
        "{}",
        &[("values", seg.clone()), ("starts", starts.clone())],
    )
    .0["out"]
        .data
        .to_f64();
    let s = run_node_and_reference(
        "segment_reduce",
        r#"{"compensated": true}"#,
        &[("values", seg), ("starts", starts)],
    )
    .0["out"]
        .data
        .to_f64();
    assert!(
        plain.iter().all(|&x| x == 1e8),
        "a sequential f32 sum drops every one: {plain:?}"
    );
    assert!(
        s.iter().all(|s| (s - exact).abs() <= 8.0),
        "segment sums {s:?}"
    );
}
