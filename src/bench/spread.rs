//! `mesoflow bench spread`: spreading and interpolation per particle on a 128^3 grid,
//! Gaussian support 8 (and 4), densities 1 and 0.1 particles per cell, random and
//! pre-sorted positions, 1 and 3 components (the setups of UAMMD's benchmark), for each
//! workgroup size asked for. Spreading and interpolation are graphs of their own, each
//! timed end to end (the figure UAMMD's per-call times compare with) and per launch.

use std::collections::BTreeMap;

use mesoflow::expr::ParamValue;
use mesoflow::gpu::GpuContext;
use mesoflow::value::{HostArray, RefArray, ValueType};

use super::{BenchError, end_to_end_clock, ms, node_reference, time_graph};

/// (support, particles per cell, sorted, components)
const CASES: [(u32, f64, bool, u32); 8] = [
    (8, 1.0, false, 1),
    (8, 1.0, true, 1),
    (8, 0.1, false, 1),
    (8, 0.1, true, 1),
    (4, 1.0, false, 1),
    (4, 1.0, true, 1),
    (8, 1.0, false, 3),
    (8, 1.0, true, 3),
];

/// One timed variant of a row: its label (the `wg` column), params of both nodes, params
/// of spreading only, and the sort node the graph runs first.
struct Variant {
    label: String,
    params: String,
    spread_only: &'static str,
    sort_first: Option<&'static str>,
}

/// One row's data: positions (sorted in Morton order of cells for the sorted rows),
/// values, a field to interpolate, and the sum of the values (the grid's mass).
struct RowData {
    n: u32,
    positions: HostArray,
    values: HostArray,
    field: HostArray,
    mass: f64,
}

pub fn run(n_cells: u32, reps: u64, workgroups: &[u32], cases: &[usize]) -> Result<(), BenchError> {
    if let Some(bad) = cases.iter().find(|&&c| c >= CASES.len()) {
        return Err(BenchError::Args(format!(
            "--cases: no row {bad} (rows 0 to {})",
            CASES.len() - 1
        )));
    }
    let gpu = GpuContext::new()?;
    outln!("adapter: {}", gpu.caps.summary());
    outln!(
        "{n_cells}^3 grid (h = 1); support 8: Gaussian, support 4: Peskin 4-point; median of {reps} \
         runs; e2e: the operation's graph end to end ({}), ns/part. from it; launches: sum of \
         per-launch medians",
        end_to_end_clock(&gpu)
    );
    outln!(
        "{:>7} {:>7} {:>9} {:>6} {:>5} {:>9} {:>10} {:>11} {:>9} {:>10} {:>11} {:>9}",
        "support",
        "density",
        "N",
        "sorted",
        "comps",
        "wg",
        "spread e2e",
        "launches ms",
        "ns/part.",
        "interp e2e",
        "launches ms",
        "ns/part."
    );
    let mut s = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    for (row, &case) in CASES.iter().enumerate() {
        if !cases.is_empty() && !cases.contains(&row) {
            continue;
        }
        let data = row_data(n_cells, case, &mut next);
        let (_, _, sorted, _) = case;
        // The interpolation check's inputs, the same for every kernel of this row.
        let check = InterpolationCheck::new(&data.positions, &data.field);
        for variant in variants(workgroups, sorted) {
            time_variant(&gpu, n_cells, reps, case, &data, &check, &variant)?;
        }
    }
    Ok(())
}

/// A row's inputs, drawn from `next` (uniform in [0, 1)) in a fixed order.
fn row_data(
    n_cells: u32,
    (_, density, sorted, comps): (u32, f64, bool, u32),
    next: &mut impl FnMut() -> f64,
) -> RowData {
    let l = n_cells as f64;
    let n = (density * l * l * l) as u32;
    let mut pos: Vec<[f32; 3]> = (0..n)
        .map(|_| [0, 1, 2].map(|_| ((next() - 0.5) * l) as f32))
        .collect();
    if sorted {
        // Morton order of the cells: what cell_hash (order morton) + sort produce.
        let cell = |p: &[f32; 3]| {
            let i = |x: f32| {
                (((x as f64 / l + 0.5) * n_cells as f64).floor() as u64).min(n_cells as u64 - 1)
            };
            let mut k = 0u64;
            for (a, c) in [i(p[0]), i(p[1]), i(p[2])].into_iter().enumerate() {
                for b in 0..11 {
                    k |= ((c >> b) & 1) << (3 * b + a);
                }
            }
            k
        };
        pos.sort_by_key(cell);
    }
    let vals: Vec<f32> = (0..n * comps).map(|_| (next() - 0.5) as f32).collect();
    let field: Vec<f32> = (0..n_cells.pow(3) * comps)
        .map(|_| (next() - 0.5) as f32)
        .collect();
    RowData {
        n,
        mass: vals.iter().map(|&v| v as f64).sum(),
        positions: HostArray::f32(ValueType::Particles { n, k: 3 }, pos.concat()),
        values: HostArray::f32(ValueType::Particles { n, k: comps }, vals),
        field: HostArray::f32(
            ValueType::RealGrid {
                dims: [n_cells; 3],
                comps,
            },
            field,
        ),
    }
}

/// The variants a row times. Sorted input also runs the box kernels (sorted_input), shown
/// as wg "box"; random input runs them after sorting in the graph (Morton order of 4-cell
/// blocks, whole blocks of about 64 particles at 1 per cell: one box run), shown as
/// "sort+box" (the radix sort) and "bin+box" (the counting sort, bin_sort), the sort and
/// the gathers included in the spreading times, the scatter back in the interpolation's
/// (which takes the sorted positions the spreading graph gives).
fn variants(workgroups: &[u32], sorted: bool) -> Vec<Variant> {
    let variant = |label: &str, params: &str, spread_only, sort_first| Variant {
        label: label.into(),
        params: params.into(),
        spread_only,
        sort_first,
    };
    let mut runs: Vec<Variant> = workgroups
        .iter()
        .map(|wg| {
            variant(
                &format!("lanes {wg}"),
                &format!(r#""workgroup": "{wg}""#),
                r#", "tiles": "off""#,
                None,
            )
        })
        .collect();
    // The workgroup-table kernels the lane kernels replaced, for comparison.
    runs.push(variant(
        "tables",
        r#""workgroup": "256", "lanes": "off""#,
        r#", "tiles": "off""#,
        None,
    ));
    // Tiled spreading (tilegen.rs: its counting sort by tile included), any order.
    runs.push(variant(
        "tiles",
        r#""workgroup": "256""#,
        r#", "tiles": "on""#,
        None,
    ));
    let sorts: &[(&str, Option<&'static str>)] = if sorted {
        &[("box", None)]
    } else {
        &[("sort+box", Some("sort")), ("bin+box", Some("bin_sort"))]
    };
    for &(label, sort) in sorts {
        runs.push(variant(
            label,
            r#""order": "contiguous""#,
            r#", "sorted_input": true, "tiles": "off""#,
            sort,
        ));
    }
    if sorted {
        // The per-particle kernels serving sorted input in its own order (cache reuse
        // between neighbouring particles, which interleaved runs give up).
        runs.push(variant(
            "contig",
            r#""order": "contiguous""#,
            r#", "tiles": "off""#,
            None,
        ));
    }
    runs
}

/// Times one variant of a row (spreading, then interpolation, each its own graph), checks
/// both (the grid's mass, the first particles' interpolated values) and prints its line.
fn time_variant(
    gpu: &GpuContext,
    n_cells: u32,
    reps: u64,
    (support, density, sorted, comps): (u32, f64, bool, u32),
    data: &RowData,
    check: &InterpolationCheck,
    variant: &Variant,
) -> Result<(), BenchError> {
    let l = n_cells as f64;
    let n = data.n;
    let Variant {
        label: wg,
        params: extra,
        spread_only,
        sort_first,
    } = variant;
    // Gaussian sigma = 0.9375 h with tolerance 1e-4 gives support 8 (UAMMD's rule); the
    // support-4 rows use Peskin's 4-point window (unit discrete mass, so the mass check
    // below stays exact; the window's cost is 12 evaluations per particle either way).
    let window = if support == 8 {
        r#""window": "gaussian", "width": 0.9375, "tolerance": 1e-4"#
    } else {
        r#""window": "peskin4""#
    };
    // The sorts' Morton blocks of 4 cells a side, and their key bits.
    let blocks = n_cells.div_ceil(4);
    let bits = 3 * (blocks as f64).log2().ceil().max(1.0) as u32;
    let interp_params = format!(
        r#"{{"box": [{l}, {l}, {l}], "grid": [{n_cells}, {n_cells}, {n_cells}], {window}, {extra}}}"#
    );
    let params = format!(
        r#"{{"box": [{l}, {l}, {l}], "grid": [{n_cells}, {n_cells}, {n_cells}], {window}, {extra}{spread_only}}}"#
    );
    let interpolate = format!(
        r#"{{"id": "interpolate", "kind": "interpolate", "params": {interp_params}, "inputs": {{"grid": "inputs.field", "positions": "inputs.positions"}}}}"#
    );
    // Sorted first: the sorting nodes before spreading, which also gives the sorted
    // positions and the permutation; the interpolation graph reads them and scatters its
    // values back to input order.
    let (spreading, spread_in, sorted_outputs, interpolation, perm_input, u) = match sort_first {
        Some(sort) => (
            sorting_nodes(sort, l, blocks, bits),
            r#""positions": "sorted_positions.out", "values": "sorted_values.out""#,
            r#", "sorted_positions": "sorted_positions.out", "perm": "order.perm""#,
            format!(
                r#"{interpolate},
                        {{"id": "back", "kind": "scatter", "params": {{"permutation": true}}, "inputs": {{"values": "interpolate.out", "index": "inputs.perm"}}}}"#
            ),
            r#", "perm": {"type": "indices"}"#,
            "back.out",
        ),
        None => (
            String::new(),
            r#""positions": "inputs.positions", "values": "inputs.values""#,
            "",
            interpolate,
            "",
            "interpolate.out",
        ),
    };
    let spread_graph = format!(
        r#"{{"mesoflow": 1,
                  "inputs": {{"positions": {{"type": "particles", "cols": 3}}, "values": {{"type": "particles", "cols": {comps}}}}},
                  "nodes": [
                    {spreading}
                    {{"id": "spread", "kind": "spread", "params": {params}, "inputs": {{{spread_in}}}}}
                  ],
                  "outputs": {{"grid": "spread.out"{sorted_outputs}}}}}"#
    );
    let spread_inputs: BTreeMap<String, HostArray> = [
        ("positions".to_string(), data.positions.clone()),
        ("values".to_string(), data.values.clone()),
    ]
    .into_iter()
    .collect();
    let spread_run = time_graph(gpu, &spread_graph, &spread_inputs, reps, true)?;
    let mut interp_inputs: BTreeMap<String, HostArray> =
        [("field".to_string(), data.field.clone())]
            .into_iter()
            .collect();
    match sort_first {
        Some(_) => {
            for (name, output) in [("positions", "sorted_positions"), ("perm", "perm")] {
                let value = spread_run.outputs.get(output).ok_or_else(|| {
                    BenchError::Wrong(format!("the spreading graph gave no `{output}`"))
                })?;
                interp_inputs.insert(name.to_string(), value.clone());
            }
        }
        None => {
            interp_inputs.insert("positions".to_string(), data.positions.clone());
        }
    }
    let interp_graph = format!(
        r#"{{"mesoflow": 1,
                  "inputs": {{"positions": {{"type": "particles", "cols": 3}},
                             "field": {{"type": "real_grid", "dims": [{n_cells}, {n_cells}, {n_cells}], "comps": {comps}}}{perm_input}}},
                  "nodes": [{interpolation}],
                  "outputs": {{"u": "{u}"}}}}"#
    );
    let interp_run = time_graph(gpu, &interp_graph, &interp_inputs, reps, true)?;
    let (ts, ti) = (spread_run.end_to_end(), interp_run.end_to_end());
    // Mass check: the grid integrates to the sum of the values (a wrong kernel fails).
    let want = data.mass;
    let total: f64 = spread_run.outputs["grid"].data.to_f64().iter().sum();
    let mut mass = if (total - want).abs() > 1e-3 * want.abs().max(1.0) + 1e-2 {
        "  MASS MISMATCH"
    } else {
        ""
    };
    // Interpolation check: the first particles against the node's f64 reference.
    let err = check.error(&interp_params, &interp_run.outputs["u"])?;
    if err > 1e-4 {
        mass = "  INTERPOLATION MISMATCH";
    }
    outln!(
        "{support:>7} {density:>7} {n:>9} {sorted:>6} {comps:>5} {wg:>9} {:>10.4} {:>11.4} {:>9.3} {:>10.4} {:>11.4} {:>9.3}{mass}",
        ms(ts),
        ms(spread_run.launch_sum()),
        ts.as_secs_f64() * 1e9 / n as f64,
        ms(ti),
        ms(interp_run.launch_sum()),
        ti.as_secs_f64() * 1e9 / n as f64
    );
    for timing in spread_run.timings.iter().chain(&interp_run.timings) {
        out!("{}", timing.breakdown());
    }
    Ok(())
}

/// The nodes that sort random input before spreading: the positions hashed to Morton
/// blocks, sorted (`sort`: the radix sort, `bin_sort`: the counting sort) and gathered with
/// the values.
fn sorting_nodes(sort: &str, l: f64, blocks: u32, bits: u32) -> String {
    let sort_params = if sort == "sort" {
        format!(r#""bits": {bits}"#)
    } else {
        format!(r#""bins": {}"#, 1u64 << bits)
    };
    format!(
        r#"{{"id": "hash", "kind": "cell_hash", "params": {{"box": [{l}, {l}, {l}], "cells": [{blocks}, {blocks}, {blocks}], "order": "morton"}}, "inputs": {{"positions": "inputs.positions"}}}},
        {{"id": "order", "kind": "{sort}", "params": {{{sort_params}}}, "inputs": {{"keys": "hash.out"}}}},
        {{"id": "sorted_positions", "kind": "gather", "inputs": {{"values": "inputs.positions", "index": "order.perm"}}}},
        {{"id": "sorted_values", "kind": "gather", "inputs": {{"values": "inputs.values", "index": "order.perm"}}}},"#
    )
}

/// The interpolation check of a row: the first `CHECKED` particles and the field as f64
/// reference inputs.
struct InterpolationCheck {
    inputs: [Option<RefArray>; 3],
    values: usize,
}

impl InterpolationCheck {
    const CHECKED: u32 = 256;

    fn new(pos: &HostArray, field: &HostArray) -> Self {
        let field = field.to_ref();
        let (ValueType::Particles { n, k }, ValueType::RealGrid { comps, .. }) = (pos.ty, field.ty)
        else {
            unreachable!("the bench's own inputs")
        };
        let m = n.min(Self::CHECKED);
        let mut first = pos.to_ref();
        first.data.truncate((m * k) as usize);
        first.ty = ValueType::Particles { n: m, k };
        InterpolationCheck {
            inputs: [Some(field), Some(first), None],
            values: (m * comps) as usize,
        }
    }

    /// Largest error of the interpolated values `got` (their first rows) against the
    /// interpolate node's f64 reference for `params`, relative to the largest reference
    /// value.
    fn error(&self, params: &str, got: &HostArray) -> Result<f64, BenchError> {
        let bad = |message: String| BenchError::Reference {
            kind: "interpolate".into(),
            message,
        };
        let raw: BTreeMap<String, serde_json::Value> =
            serde_json::from_str(params).map_err(|e| bad(e.to_string()))?;
        let params = raw
            .into_iter()
            .map(|(n, v)| ParamValue::from_json(&v).map(|v| (n, v)))
            .collect::<Result<_, _>>()
            .map_err(|e| bad(e.to_string()))?;
        let want = node_reference("interpolate", &params, &self.inputs)?
            .remove(0)
            .data;
        let got = got.data.to_f64();
        let scale = want.iter().fold(f64::MIN_POSITIVE, |a, x| a.max(x.abs()));
        Ok(want
            .iter()
            .zip(&got[..self.values])
            .map(|(w, g)| (w - g).abs() / scale)
            .fold(0.0, f64::max))
    }
}
