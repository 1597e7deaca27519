//! Spreading and interpolation (tests/it/spread/): the windows and params the tests run,
//! random and Morton-sorted positions.

use mesoflow::value::{HostArray, ValueType};

use super::{Rng, f32s, random_points};

/// Window params used across the tests: (name, extra params).
pub const WINDOWS: &[(&str, &str)] = &[
    ("gaussian", r#""width": 0.6, "tolerance": 1e-4"#),
    ("es", r#""support": 6"#),
    // The half-width a length (dpstokes.json's): a different number of cells per axis on
    // the tests' non-cubic grids. Wide and steep enough for TOL: its jump at the edge is
    // e^-beta of the peak, and f32's rounding of r grows by beta / (half-width in cells).
    ("es", r#""width": 2.2, "beta": 13.8"#),
    ("peskin3", ""),
    ("peskin4", ""),
    ("peskin6", ""),
];

/// f32 window weights and accumulation against f64: relative to the largest value.
pub const TOL: f64 = 2e-6;

/// Params of spread and interpolate: box, grid, window with its `extra` params (possibly
/// empty), variant.
pub fn params(window: &str, extra: &str, lengths: &[f64], cells: &[u32], variant: &str) -> String {
    let sep = if extra.is_empty() { "" } else { ", " };
    format!(
        r#"{{"box": {lengths:?}, "grid": {cells:?}, "window": "{window}"{sep}{extra}, "variant": "{variant}"}}"#
    )
}

/// Window params `extra` (possibly empty) with `more` params appended.
pub fn with(extra: &str, more: &str) -> String {
    if extra.is_empty() {
        more.to_string()
    } else {
        format!("{extra}, {more}")
    }
}

/// `n` random positions in the box of side `lengths` (2 or 3 axes).
pub fn positions(rng: &mut Rng, n: u32, lengths: &[f64]) -> HostArray {
    let v = random_points(rng, n as usize, lengths)
        .into_iter()
        .map(|x| x as f32)
        .collect();
    HostArray::f32(
        ValueType::Particles {
            n,
            k: lengths.len() as u32,
        },
        v,
    )
}

/// Sorts particle rows by the Morton order of their cells (what cell_hash + sort give).
pub fn morton_sorted(pos: &HostArray, lengths: &[f64], cells: &[u32]) -> HostArray {
    let d = lengths.len();
    let v = f32s(pos);
    let key = |row: &[f32]| -> u64 {
        let mut k = 0u64;
        for a in 0..d {
            let c = (((row[a] as f64 / lengths[a] + 0.5) * cells[a] as f64).floor() as i64)
                .rem_euclid(cells[a] as i64) as u64;
            for b in 0..16 {
                k |= ((c >> b) & 1) << (b * d + a);
            }
        }
        k
    };
    let mut rows: Vec<&[f32]> = v.chunks(d).collect();
    rows.sort_by_key(|r| key(r));
    HostArray::f32(pos.ty, rows.concat())
}
