//! `mesoflow bench spread`: spreading and interpolation per particle on a 128^3 grid,
//! Gaussian support 8 (and 4), densities 1 and 0.1 particles per cell, random and
//! pre-sorted positions, 1 and 3 components (the setups of UAMMD's benchmark), for each
//! workgroup size asked for.

use std::collections::BTreeMap;

use super::{node_reference, runtime, time_graph};
use crate::cli::CliError;
use crate::gpu::GpuContext;
use crate::value::{HostArray, RefArray, ValueType};

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

pub fn run(n_cells: u32, reps: u64, workgroups: &[u32], cases: &[usize]) -> Result<(), CliError> {
    if let Some(bad) = cases.iter().find(|&&c| c >= CASES.len()) {
        return Err(CliError::Input(format!(
            "--cases: no row {bad} (rows 0 to {})",
            CASES.len() - 1
        )));
    }
    let gpu = GpuContext::new().map_err(runtime)?;
    let l = n_cells as f64;
    println!("adapter: {}", gpu.caps.summary());
    println!(
        "{n_cells}^3 grid (h = 1); support 8: Gaussian, support 4: Peskin 4-point; median GPU time of {reps} runs per launch"
    );
    println!(
        "{:>7} {:>7} {:>9} {:>6} {:>5} {:>9} {:>11} {:>11} {:>11} {:>11}",
        "support",
        "density",
        "N",
        "sorted",
        "comps",
        "wg",
        "spread ms",
        "ns/part.",
        "interp ms",
        "ns/part."
    );
    let mut s = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    for (row, &(support, density, sorted, comps)) in CASES.iter().enumerate() {
        if !cases.is_empty() && !cases.contains(&row) {
            continue;
        }
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
        let want: f64 = vals.iter().map(|&v| v as f64).sum();
        let inputs: BTreeMap<String, HostArray> = [
            (
                "positions".to_string(),
                HostArray::f32(ValueType::Particles { n, k: 3 }, pos.concat()),
            ),
            (
                "values".to_string(),
                HostArray::f32(ValueType::Particles { n, k: comps }, vals),
            ),
            (
                "field".to_string(),
                HostArray::f32(
                    ValueType::RealGrid {
                        dims: [n_cells; 3],
                        comps,
                    },
                    field,
                ),
            ),
        ]
        .into_iter()
        .collect();
        // Gaussian sigma = 0.9375 h with tolerance 1e-4 gives support 8 (UAMMD's rule); the
        // support-4 rows use Peskin's 4-point window (unit discrete mass, so the mass check
        // below stays exact; the window's cost is 12 evaluations per particle either way).
        let window = if support == 8 {
            r#""window": "gaussian", "width": 0.9375, "tolerance": 1e-4"#
        } else {
            r#""window": "peskin4""#
        };
        // Sorted input also runs the box kernels (sorted_input), shown as wg "box";
        // random input runs them after sorting in the graph (Morton order of 4-cell
        // blocks, whole blocks of about 64 particles at 1 per cell: one box run), shown
        // as "sort+box" (the radix sort) and "bin+box" (the counting sort, bin_sort), the
        // sort, the gathers and the scatter back included in the times.
        // (label, params of both nodes, params of spreading only, sort node in the graph
        // first)
        let mut runs: Vec<(String, String, &str, Option<&str>)> = workgroups
            .iter()
            .map(|wg| {
                (
                    format!("lanes {wg}"),
                    format!(r#""workgroup": "{wg}""#),
                    r#", "tiles": "off""#,
                    None,
                )
            })
            .collect();
        // The workgroup-table kernels the lane kernels replaced, for comparison.
        runs.push((
            "tables".into(),
            r#""workgroup": "256", "lanes": "off""#.into(),
            r#", "tiles": "off""#,
            None,
        ));
        // Tiled spreading (tilegen.rs: its counting sort by tile included), any order.
        runs.push((
            "tiles".into(),
            r#""workgroup": "256""#.into(),
            r#", "tiles": "on""#,
            None,
        ));
        let sorts: &[(&str, Option<&str>)] = if sorted {
            &[("box", None)]
        } else {
            &[("sort+box", Some("sort")), ("bin+box", Some("bin_sort"))]
        };
        for &(label, sort) in sorts {
            runs.push((
                label.into(),
                r#""order": "contiguous""#.into(),
                r#", "sorted_input": true, "tiles": "off""#,
                sort,
            ));
        }
        if sorted {
            // The per-particle kernels serving sorted input in its own order (cache
            // reuse between neighbouring particles, which interleaved runs give up).
            runs.push((
                "contig".into(),
                r#""order": "contiguous""#.into(),
                r#", "tiles": "off""#,
                None,
            ));
        }
        // The interpolation check's inputs, the same for every kernel of this row.
        let check = InterpolationCheck::new(&inputs);
        // The sorts' Morton blocks of 4 cells a side, and their key bits.
        let blocks = n_cells.div_ceil(4);
        let bits = 3 * (blocks as f64).log2().ceil().max(1.0) as u32;
        for (wg, extra, spread_only, sort_first) in runs {
            let interp_params = format!(
                r#"{{"box": [{l}, {l}, {l}], "grid": [{n_cells}, {n_cells}, {n_cells}], {window}, {extra}}}"#
            );
            let params = format!(
                r#"{{"box": [{l}, {l}, {l}], "grid": [{n_cells}, {n_cells}, {n_cells}], {window}, {extra}{spread_only}}}"#
            );
            let (sorting, spread_in, interp_in, u) = if let Some(sort) = sort_first {
                let sort_params = if sort == "sort" {
                    format!(r#""bits": {bits}"#)
                } else {
                    format!(r#""bins": {}"#, 1u64 << bits)
                };
                (
                    format!(
                        r#"{{"id": "hash", "kind": "cell_hash", "params": {{"box": [{l}, {l}, {l}], "cells": [{blocks}, {blocks}, {blocks}], "order": "morton"}}, "inputs": {{"positions": "inputs.positions"}}}},
                    {{"id": "order", "kind": "{sort}", "params": {{{sort_params}}}, "inputs": {{"keys": "hash.out"}}}},
                    {{"id": "sorted_positions", "kind": "gather", "inputs": {{"values": "inputs.positions", "index": "order.perm"}}}},
                    {{"id": "sorted_values", "kind": "gather", "inputs": {{"values": "inputs.values", "index": "order.perm"}}}},
                    {{"id": "back", "kind": "scatter", "params": {{"permutation": true}}, "inputs": {{"values": "interpolate.out", "index": "order.perm"}}}},"#
                    ),
                    r#""positions": "sorted_positions.out", "values": "sorted_values.out""#,
                    r#""positions": "sorted_positions.out""#,
                    "back.out",
                )
            } else {
                (
                    String::new(),
                    r#""positions": "inputs.positions", "values": "inputs.values""#,
                    r#""positions": "inputs.positions""#,
                    "interpolate.out",
                )
            };
            let graph = format!(
                r#"{{"mesoflow": 1,
                  "inputs": {{"positions": {{"type": "particles", "cols": 3}}, "values": {{"type": "particles", "cols": {comps}}},
                             "field": {{"type": "real_grid", "dims": [{n_cells}, {n_cells}, {n_cells}], "comps": {comps}}}}},
                  "nodes": [
                    {sorting}
                    {{"id": "spread", "kind": "spread", "params": {params}, "inputs": {{{spread_in}}}}},
                    {{"id": "interpolate", "kind": "interpolate", "params": {interp_params}, "inputs": {{"grid": "inputs.field", {interp_in}}}}}
                  ],
                  "outputs": {{"grid": "spread.out", "u": "{u}"}}}}"#
            );
            let run = time_graph(&gpu, &graph, &inputs, reps, true)?;
            let t = |label: &str| {
                run.timings
                    .iter()
                    .find(|t| t.label == label)
                    .map(|t| t.median.as_secs_f64())
                    .unwrap_or(f64::NAN)
            };
            let (mut ts, mut ti) = (t("spread"), t("interpolate"));
            if sort_first.is_some() {
                ts += t("hash") + t("order") + t("sorted_positions") + t("sorted_values");
                ti += t("back");
            }
            // Mass check: the grid integrates to the sum of the values (a wrong kernel fails).
            let total: f64 = run.outputs["grid"].data.to_f64().iter().sum();
            let mut mass = if (total - want).abs() > 1e-3 * want.abs().max(1.0) + 1e-2 {
                "  MASS MISMATCH"
            } else {
                ""
            };
            // Interpolation check: the first particles against the node's f64 reference.
            let err = check.error(&interp_params, &run.outputs["u"])?;
            if err > 1e-4 {
                mass = "  INTERPOLATION MISMATCH";
            }
            println!(
                "{support:>7} {density:>7} {n:>9} {sorted:>6} {comps:>5} {wg:>9} {:>11.4} {:>11.3} {:>11.4} {:>11.3}{mass}",
                ts * 1e3,
                ts * 1e9 / n as f64,
                ti * 1e3,
                ti * 1e9 / n as f64
            );
            for timing in &run.timings {
                print!("{}", timing.breakdown());
            }
        }
    }
    Ok(())
}

/// The interpolation check of a row: the first `CHECKED` particles and the field as f64
/// reference inputs.
struct InterpolationCheck {
    inputs: [Option<RefArray>; 3],
    values: usize,
}

impl InterpolationCheck {
    const CHECKED: u32 = 256;

    fn new(inputs: &BTreeMap<String, HostArray>) -> Self {
        let pos = &inputs["positions"];
        let field = inputs["field"].to_ref();
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
    fn error(&self, params: &str, got: &HostArray) -> Result<f64, CliError> {
        let raw: BTreeMap<String, serde_json::Value> =
            serde_json::from_str(params).map_err(runtime)?;
        let params = raw
            .into_iter()
            .map(|(n, v)| crate::expr::ParamValue::from_json(&v).map(|v| (n, v)))
            .collect::<Result<_, _>>()
            .map_err(runtime)?;
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
