//! Deterministic spreading (`DeviceCaps::deterministic`): every kernel's `grid_add` goes
//! to 64-bit fixed-point integers (shaders/spread/add_fixed.wgsl) in a scratch grid of two
//! u32 words per cell, so that float atomics adding in whatever order the threads run
//! cannot change a bit; then one kernel converts the sums to the f32 grid.
//!
//! The scale is a power of two chosen on the GPU from the data, so no finite input can
//! overflow it: `fixed_max.wgsl` takes the largest |value| spread (its f32 exponent e:
//! 2^e <= max < 2^(e + 1)), the host bounds one cell's total weight by
//! PEAK x N x wraps <= 2^exp (PEAK the window's largest weight per cell, N the particles,
//! wraps the times one particle's support can cover a cell), and each add w v is rounded
//! to a multiple of the unit 2^(e + exp - 60). A cell's sum of |w v| is then below
//! 2^61 units (the words hold 2^63), and each add is off by at most half a unit: less
//! than 2^-60 (9e-19) of the bound B = PEAK x N x wraps x max |v| on any cell's sum, so
//! N adds into one cell stay below N x 9e-19 of B, against the 6e-8 relative rounding of
//! f32 that the result takes once (and the float-atomic path at every add). Values that are NaN or
//! infinite, or adds beyond that range, never wrap: they set a flag and the grid is NaN.

use crate::gpu::{Binding, CompileCtx, CompileError, Dispatch, KernelSpec, WG_1D};

use super::{GridWindow, tilegen};

/// Smallest exponent of the weight bound: `add_fixed.wgsl` scales by ldexp in two halves
/// of at most 127, so 60 - e - exp must stay within 254 for every f32 exponent e.
const MIN_EXP: i32 = -60;

/// Largest: beyond it the shift could pass -254 for the largest f32 values (a window
/// whose peak weight per cell is itself outside f32).
const MAX_EXP: i32 = 187;

/// log2 of the bound on one cell's total weight from `n` particles (PEAK x N x wraps),
/// rounded up: the `FIXED_EXP` of the kernels. An error where the window's weights are
/// beyond what f32 arithmetic carries.
pub fn weight_exponent(gw: &GridWindow, n: u32) -> Result<i32, String> {
    let ns = gw.window.support();
    let (peak, wraps) = (0..gw.dims()).fold((1.0, 1.0), |(p, w), a| {
        (
            p * tilegen::peak_weight(&gw.window, gw.h(a)),
            w * ns.div_ceil(gw.cells[a]) as f64,
        )
    });
    bound_exponent(peak, n, wraps)
}

/// log2 of PEAK x N x wraps rounded up (`FIXED_EXP`), for any spreading kernel that adds
/// through add_fixed.wgsl: `peak` its largest weight on one grid word, `wraps` the times
/// one particle's support can cover a word.
pub fn bound_exponent(peak: f64, n: u32, wraps: f64) -> Result<i32, String> {
    let bound = peak * n.max(1) as f64 * wraps;
    let exp = bound.log2().ceil();
    if exp.is_nan() || exp > MAX_EXP as f64 {
        return Err(format!(
            "deterministic spreading: the window's peak weight per cell ({peak:e}) times {n} particles is beyond the range of f32 arithmetic (2^{exp} > 2^{MAX_EXP}); a finer or larger window, or fewer particles"
        ));
    }
    Ok((exp as i32).max(MIN_EXP))
}

/// Words of the fixed-point grid for `words` f32 grid words: two per word, then the
/// largest |value| (f32 bits) and the overflow flag.
pub fn fixed_words(words: u64) -> u64 {
    2 * words + 2
}

/// A kernel's spec with the constants `add_fixed.wgsl` (and `fixed_finish.wgsl`) read,
/// for a grid of `words` f32 words.
pub fn with_constants(spec: KernelSpec, words: u64, exp: i32) -> KernelSpec {
    spec.constant("FIXED_WORDS", (2 * words) as f64)
        .constant("FIXED_EXP", exp as f64)
}

/// Before the spreading kernels: clear the fixed-point grid, then its max word from the
/// `values` (n x comps f32).
pub fn begin(
    cx: &mut CompileCtx<'_>,
    fixed: &wgpu::Buffer,
    values: &wgpu::Buffer,
    value_words: u64,
    grid_words: u64,
) -> Result<Vec<Dispatch>, CompileError> {
    let mut out = vec![cx.fill(fixed, fixed_words(grid_words), 0)?];
    if value_words == 0 {
        return Ok(out);
    }
    let count = u32::try_from(value_words).map_err(|_| {
        CompileError::Unsupported(format!("spread of {value_words} values: at most 2^32 - 1"))
    })?;
    let spec = KernelSpec::new(
        "spread (deterministic): largest |value|",
        cx.shader("spread/fixed_max.wgsl")?,
        &[
            Binding::StorageRead,
            Binding::StorageReadWrite,
            Binding::Uniform,
        ],
    )
    .constant("FIXED_WORDS", (2 * grid_words) as f64);
    let kernel = cx.kernel(&spec)?;
    let shape = cx.uniform("spread fixed count", bytemuck::bytes_of(&count));
    out.push(cx.dispatch(
        &kernel,
        &[values, fixed, &shape],
        cx.grid_1d(value_words, WG_1D),
    ));
    Ok(out)
}

/// After the spreading kernels: the f32 grid from the fixed-point sums.
pub fn finish(
    cx: &mut CompileCtx<'_>,
    fixed: &wgpu::Buffer,
    grid: &wgpu::Buffer,
    grid_words: u64,
    exp: i32,
) -> Result<Dispatch, CompileError> {
    let count = u32::try_from(grid_words).map_err(|_| {
        CompileError::Unsupported(format!("a grid of {grid_words} words: at most 2^32 - 1"))
    })?;
    let spec = with_constants(
        KernelSpec::new(
            "spread (deterministic): to f32",
            cx.shader("spread/fixed_finish.wgsl")?,
            &[
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::Uniform,
            ],
        ),
        grid_words,
        exp,
    );
    let kernel = cx.kernel(&spec)?;
    let shape = cx.uniform("spread fixed count", bytemuck::bytes_of(&count));
    Ok(cx.dispatch(
        &kernel,
        &[fixed, grid, &shape],
        cx.grid_1d(grid_words, WG_1D),
    ))
}
