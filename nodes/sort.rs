//! `sort`: stable LSD radix sort of u32 keys, returning the sorted keys and the
//! permutation that sorts them (`perm[i]` is the input index of the i-th sorted key), as
//! needed to order particles by cell hash. Gathering other arrays by `perm` is left to
//! other nodes.
//!
//! Each pass sorts by one digit: `histogram` counts each tile's digits, the counts are
//! scanned in digit-major order (the `scan` kernels: every (digit, tile) learns where its
//! keys go), and `scatter` ranks every key stably inside its tile and writes key and
//! payload there. The first pass reads the input keys and makes the identity payload on
//! the fly; passes alternate between the outputs and one scratch pair so that the last
//! one lands in the outputs. Per key and pass: 4 bytes read for the histogram, 8 read and
//! 8 written by the scatter (16 bytes of them in the first pass), so 76 bytes per key for
//! 32-bit keys on the subgroup path (4 passes of 8 bits); the portable path needs 8
//! passes of 4 bits.
//!
//! Only the low `bits` bits are sorted (fewer passes: cell hashes use 20 to 30 bits).
//! Keys with higher bits set are ordered by their low bits alone and come out unchanged,
//! in input order among keys with equal low bits.

use crate::gpu::{Binding, CompileCtx, CompileError, Dispatch, KernelSpec, NodeIo};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamSpec, Params, PortError, PortSpec, RefCtx, Registry,
    Signature,
};
use crate::nodes::scan::{self, Path, ScanKernels, Variant};
use crate::value::{Elem, PortType, RefArray, ValueType};

/// Keys per tile and digit width of the subgroup path (`TILE` in
/// shaders/sort/scatter_subgroup.wgsl: 256 threads x 15 keys).
const SUBGROUP_TILE: u32 = 3840;
const SUBGROUP_DIGIT_BITS: u32 = 8;
/// The same for the portable path (shaders/sort/scatter_portable.wgsl: 256 x 8 keys).
const PORTABLE_TILE: u32 = 2048;
const PORTABLE_DIGIT_BITS: u32 = 4;

/// Workgroup memory of the subgroup scatter kernel in u32 words, for subgroups of at
/// least `min` lanes: 128 counter words per subgroup, the tile, 64 subgroup totals.
fn subgroup_scatter_words(min: u32) -> u32 {
    128 * (256 / min) + SUBGROUP_TILE + 64
}

/// Histogram words for `n` keys, whichever path runs (its size must be known before the
/// device is: scratch sizes come from `infer`).
fn hist_words(n: u64) -> u64 {
    let per_path = |tile: u32, bits: u32| (1u64 << bits) * n.div_ceil(tile as u64);
    per_path(SUBGROUP_TILE, SUBGROUP_DIGIT_BITS).max(per_path(PORTABLE_TILE, PORTABLE_DIGIT_BITS))
}

/// Scratch layout: histogram and its scan, a ping-pong pair for keys and payload when
/// there can be more than one pass, then the scan's own scratch.
fn scratch_bytes(n: u64, bits: u32) -> Vec<u64> {
    let h = hist_words(n);
    let mut s = vec![4 * h, 4 * h];
    if bits > PORTABLE_DIGIT_BITS.min(SUBGROUP_DIGIT_BITS) {
        s.extend([4 * n, 4 * n]);
    }
    s.extend(scan::scratch_bytes(h));
    s
}

pub struct SortKind;

impl NodeKind for SortKind {
    fn name(&self) -> &'static str {
        "sort"
    }

    fn doc(&self) -> &'static str {
        "stable radix sort of u32 keys by their low `bits` bits, with the sorting permutation"
    }

    fn inputs(&self) -> Vec<PortSpec> {
        vec![PortSpec::new("keys", PortType::Indices, "keys to sort")]
    }

    fn outputs(&self) -> Vec<PortSpec> {
        vec![
            PortSpec::new(
                "keys",
                PortType::Indices,
                "the keys in ascending order of their low `bits` bits (equal ones in input order)",
            ),
            PortSpec::new(
                "perm",
                PortType::Indices,
                "input index of each sorted key: keys_out[i] = keys[perm[i]]",
            ),
        ]
    }

    fn params(&self) -> Vec<ParamSpec> {
        vec![
            ParamSpec::integer(
                "bits",
                Some(32.0),
                1.0,
                32.0,
                "low key bits to sort by; higher bits are ignored (and kept)",
            ),
            Variant::param(),
        ]
    }

    fn build(&self, params: &Params) -> Result<Box<dyn Node>, String> {
        Ok(Box::new(SortNode {
            bits: params.number("bits") as u32,
            variant: Variant::from_params(params)?,
        }))
    }
}

struct SortNode {
    bits: u32,
    variant: Variant,
}

impl SortNode {
    fn mask(&self) -> u32 {
        u32::MAX >> (32 - self.bits)
    }
}

impl Node for SortNode {
    fn infer(&self, inputs: &[Option<ValueType>]) -> Result<Signature, PortError> {
        let Some(Some(t)) = inputs.first() else {
            return Err(PortError::new("keys", "is required"));
        };
        Ok(Signature {
            outputs: vec![*t, *t],
            scratch: scratch_bytes(t.words(), self.bits),
        })
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _cx: RefCtx) {
        let Some(Some(keys)) = inputs.first() else {
            return;
        };
        let keys: Vec<u32> = keys.data.iter().map(|&k| k as u32).collect();
        let mut perm: Vec<usize> = (0..keys.len()).collect();
        // `sort_by_key` is stable: equal low bits keep their input order.
        perm.sort_by_key(|&i| keys[i] & self.mask());
        for (i, &p) in perm.iter().enumerate() {
            outputs[0].data[i] = keys[p] as f64;
            outputs[1].data[i] = p as f64;
        }
    }
}

/// One pass's uniforms, as `Pass` in shaders/sort/common.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct PassParams {
    n: u32,
    ntiles: u32,
    shift: u32,
    mask: u32,
    radix: u32,
    first: u32,
}

impl GpuKernels for SortNode {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let missing = || CompileError::Unsupported("sort: a port has no buffer".into());
        let keys = io.inputs.first().copied().flatten().ok_or_else(missing)?;
        let [out_keys, out_perm] = io.outputs.as_slice() else {
            return Err(missing());
        };
        let n = keys.ty.words();
        if n == 0 {
            return Ok(Vec::new());
        }
        let n32 = u32::try_from(n).map_err(|_| {
            CompileError::Unsupported(format!("sort of {n} keys: at most 2^32 - 1"))
        })?;

        let storage = cx.caps().max_workgroup_storage;
        let path = self.variant.choose(cx.caps(), "sort", |(min, max)| {
            scan::subgroup_scan_fits((min, max))?;
            let bytes = 4 * subgroup_scatter_words(min);
            if bytes > storage {
                return Err(format!(
                    "subgroups of {min} lanes need {bytes} bytes of workgroup memory, the device has {storage}"
                ));
            }
            Ok(())
        })?;
        let (tile, digit_bits, file) = match path {
            Path::Subgroup => (
                SUBGROUP_TILE,
                SUBGROUP_DIGIT_BITS,
                "sort/scatter_subgroup.wgsl",
            ),
            Path::Portable => (
                PORTABLE_TILE,
                PORTABLE_DIGIT_BITS,
                "sort/scatter_portable.wgsl",
            ),
        };
        let mut scatter_spec = KernelSpec::new(
            format!("sort scatter ({path:?})"),
            cx.shader(file)?,
            &[
                Binding::StorageRead,
                Binding::StorageRead,
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::StorageReadWrite,
                Binding::Uniform,
            ],
        );
        if let (Path::Subgroup, Some((min, max))) = (path, cx.caps().subgroups) {
            scatter_spec = scatter_spec
                .constant("COUNTER_WORDS", (128 * (256 / min)) as f64)
                .constant("WIDE", if max > 32 { 1.0 } else { 0.0 });
        }
        let scatter = cx.kernel(&scatter_spec)?;
        let histogram = cx.kernel(
            &KernelSpec::new(
                "sort histogram",
                cx.shader("sort/histogram.wgsl")?,
                &[
                    Binding::StorageRead,
                    Binding::StorageReadWrite,
                    Binding::Uniform,
                ],
            )
            .constant("TILE", tile as f64),
        )?;
        let scan = ScanKernels::new(cx, path, Elem::U32)?;

        let passes = self.bits.div_ceil(digit_bits);
        let scratch = io.scratch.as_slice();
        let (hist, hist_scanned, rest) = match scratch {
            [h, hs, rest @ ..] => (*h, *hs, rest),
            _ => return Err(missing()),
        };
        let has_pingpong = self.bits > PORTABLE_DIGIT_BITS.min(SUBGROUP_DIGIT_BITS);
        let (pingpong, scan_scratch) = match (has_pingpong, rest) {
            (true, [k, v, s @ ..]) => (Some((*k, *v)), s),
            (false, s) => (None, s),
            _ => return Err(missing()),
        };
        let ntiles = n.div_ceil(tile as u64);
        let grid = cx.grid_1d(ntiles, 1);

        let mut out = Vec::new();
        let mut src = (keys.buffer, keys.buffer);
        for p in 0..passes {
            let shift = p * digit_bits;
            let width = digit_bits.min(self.bits - shift);
            // The last pass writes the outputs, so passes alternate backwards from it.
            let dst = if (passes - 1 - p) % 2 == 0 {
                (out_keys.buffer, out_perm.buffer)
            } else {
                pingpong.ok_or_else(missing)?
            };
            let cfg = PassParams {
                n: n32,
                ntiles: ntiles as u32,
                shift,
                mask: (1 << width) - 1,
                radix: 1 << width,
                first: u32::from(p == 0),
            };
            let cfg = cx.uniform("sort pass", bytemuck::bytes_of(&cfg));
            out.push(cx.dispatch(&histogram, &[src.0, hist, &cfg], grid));
            scan.record(
                cx,
                hist,
                hist_scanned,
                (1u64 << width) * ntiles,
                scan_scratch,
                &mut out,
            )?;
            // In the first pass the payload binding is unused (identity); the keys stand in.
            out.push(cx.dispatch(
                &scatter,
                &[src.0, src.1, hist_scanned, dst.0, dst.1, &cfg],
                grid,
            ));
            src = dst;
        }
        Ok(out)
    }
}

pub fn register(r: &mut Registry) {
    r.add(SortKind);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_match_the_shaders() {
        for (file, tile) in [
            ("sort/scatter_subgroup.wgsl", SUBGROUP_TILE),
            ("sort/scatter_portable.wgsl", PORTABLE_TILE),
        ] {
            let src = crate::gpu::shaders::raw(file).unwrap_or_default();
            assert!(
                src.contains(&format!("const TILE: u32 = {tile}u;")),
                "{file}"
            );
        }
    }

    #[test]
    fn the_subgroup_kernel_fits_lavapipe_and_nvidia() {
        // lavapipe: subgroups of 8, 32 KiB of workgroup memory; NVIDIA: 32 lanes.
        assert!(4 * subgroup_scatter_words(8) <= 32 << 10);
        assert!(4 * subgroup_scatter_words(32) <= 20 << 10);
    }
}
