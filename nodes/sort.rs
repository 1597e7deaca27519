//! `sort`: stable LSD radix sort of u32 keys, returning the sorted keys and the
//! permutation that sorts them (`perm[i]` is the input index of the i-th sorted key), as
//! needed to order particles by cell hash. Gathering other arrays by `perm` is left to
//! other nodes.
//!
//! Each pass sorts by one digit: a histogram kernel counts each tile's digits, the counts
//! are scanned in digit-major order (every (digit, tile) learns where its keys go), and a
//! scatter kernel ranks every key stably inside its tile, reorders the tile in workgroup
//! memory and writes key and payload out, each digit's run contiguous. The first pass
//! reads the input keys and makes the identity payload on the fly; passes alternate
//! between the outputs and one scratch pair so that the last one lands in the outputs.
//!
//! Only the low `bits` bits are sorted (fewer passes: cell hashes use 20 to 30 bits).
//! Keys with higher bits set are ordered by their low bits alone and come out unchanged,
//! in input order among keys with equal low bits.
//!
//! # Variants (the `variant` param)
//!
//! Bytes are per key for 32-bit keys; every scatter moves 16 (key and payload in and
//! out; 12 in the first pass, which reads no payload) and every histogram reads 4, so 4
//! passes move 76 and 8 passes 156, plus the per-tile counts noted below.
//!
//! - `tile4096`, `tile2048` (shaders/sort/scatter_tile.wgsl): 8-bit digits, 4 passes,
//!   tiles of 4096 or 2048 keys (16 or 8 per thread). (Tiles of 3072 keys were offered
//!   too and passed every lavapipe test, but returned the payload in place of the keys
//!   on an H100 at 10^7 keys, cause not found: removed rather than kept wrong.) Ranking as in
//!   `subgroup`, but every loop over a thread's keys is written out, so keys, ranks and
//!   payload stay in registers and a thread has all its loads in flight at once; keys
//!   are read lane-striped and written through the sorted stage. Per pass three
//!   dispatches: `tile_counts` (vec4 loads; also each digit's total over all tiles,
//!   by one atomic per tile and digit), `offsets` (one workgroup per digit scans its row
//!   of tile counts, starting from the digit totals: one dispatch where a general scan
//!   takes three) and the scatter; 16 bytes per tile and digit of counts and offsets,
//!   1 to 2 bytes per key and pass. Needs subgroups of 4 to 128 lanes and
//!   4 * (tile + max(128 * 256 / smallest subgroup, tile / 4 + 256)) bytes of
//!   workgroup memory (21 KiB for `tile4096` on 32 lanes; 32 KiB on lavapipe's 8).
//! - `subgroup` (shaders/sort/scatter_subgroup.wgsl): the first subgroup kernel, 8-bit
//!   digits, tiles of 3840 keys, loops over register arrays (on an H100 its scatter moved
//!   430-510 GB/s, as if about one scalar load per thread were in flight: most likely the
//!   driver left the loops rolled and the arrays in local memory), counts scanned by the
//!   general scan (3 dispatches; 20 bytes per tile and digit, 1.3 per key and pass).
//! - `portable` (shaders/sort/scatter_portable.wgsl): no subgroup operations; 4-bit
//!   digits ranked by per-thread counters and a workgroup scan, tiles of 2048 keys,
//!   8 passes, the general scan.
//! - `auto`: `tile4096` where it fits, else `subgroup`, else `portable`.

use std::sync::Arc;

use crate::gpu::{
    Binding, Choice, CompileCtx, CompileError, DeviceCaps, Dispatch, Kernel, KernelSpec, NodeIo,
};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamSpec, PortError, PortSpec, RefCtx, Registry,
    Signature,
};
use crate::nodes::scan::{self, Path, ScanKernels};
use crate::value::{Elem, PortType, RefArray, ValueType};

/// Keys per tile and digit width of the subgroup path (`TILE` in
/// shaders/sort/scatter_subgroup.wgsl: 256 threads x 15 keys).
const SUBGROUP_TILE: u32 = 3840;
/// Digit width of the subgroup and tile paths.
const DIGIT_BITS: u32 = 8;
/// The same for the portable path (shaders/sort/scatter_portable.wgsl: 256 x 8 keys).
const PORTABLE_TILE: u32 = 2048;
const PORTABLE_DIGIT_BITS: u32 = 4;
/// Keys per vec4 row of a tile-path workgroup (256 threads x 4 keys): a tile holds
/// `QUADS` of them.
const TILE_ROW: u32 = 1024;
/// vec4 of keys per thread of `auto`'s tile path.
const AUTO_QUADS: u32 = 4;
/// Passes of 8-bit digits at most (32-bit keys): rows of the digit totals.
const MAX_PASSES: u64 = 4;

/// The `variant` param of `sort`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SortVariant {
    Auto,
    /// The tile path with `quads` vec4 of keys per thread (tiles of 1024 * quads keys).
    Tile {
        quads: u32,
    },
    Subgroup,
    Portable,
}

impl SortVariant {
    /// Every value of the param, `auto` first.
    pub const NAMES: &'static [&'static str] =
        &["auto", "tile4096", "tile2048", "subgroup", "portable"];

    pub fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "auto" => SortVariant::Auto,
            "tile4096" => SortVariant::Tile { quads: 4 },
            "tile2048" => SortVariant::Tile { quads: 2 },
            "subgroup" => SortVariant::Subgroup,
            "portable" => SortVariant::Portable,
            _ => return None,
        })
    }

    fn param() -> ParamSpec {
        ParamSpec::choice(
            "variant",
            "auto",
            Self::NAMES,
            "kernels: `tile4096`/`tile2048` (subgroup ranking, keys in registers, \
             tiles of that many keys), `subgroup` (the first subgroup kernel), `portable` \
             (workgroup memory only), or `auto` (`tile4096`, else `subgroup`, else \
             `portable`, by what the device supports)",
        )
    }

    fn name(self) -> &'static str {
        Self::NAMES
            .iter()
            .copied()
            .find(|n| Self::from_name(n) == Some(self))
            .unwrap_or("auto")
    }

    /// Every path this variant may take on some device (scratch is sized for all of
    /// them: it is fixed before the device is known).
    fn possible(self) -> Vec<Kernels> {
        match self {
            SortVariant::Auto => vec![
                Kernels::Tile { quads: AUTO_QUADS },
                Kernels::Subgroup,
                Kernels::Portable,
            ],
            SortVariant::Tile { quads } => vec![Kernels::Tile { quads }],
            SortVariant::Subgroup => vec![Kernels::Subgroup],
            SortVariant::Portable => vec![Kernels::Portable],
        }
    }
}

/// The kernels actually chosen for a device.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kernels {
    Tile { quads: u32 },
    Subgroup,
    Portable,
}

impl std::fmt::Display for Kernels {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Kernels::Tile { quads } => write!(f, "strategy: tile{} kernels", TILE_ROW * quads),
            Kernels::Subgroup => f.write_str("strategy: subgroup kernels"),
            Kernels::Portable => f.write_str("strategy: portable kernels (workgroup memory)"),
        }
    }
}

impl Kernels {
    fn tile(self) -> u32 {
        match self {
            Kernels::Tile { quads } => TILE_ROW * quads,
            Kernels::Subgroup => SUBGROUP_TILE,
            Kernels::Portable => PORTABLE_TILE,
        }
    }

    fn digit_bits(self) -> u32 {
        match self {
            Kernels::Portable => PORTABLE_DIGIT_BITS,
            Kernels::Tile { .. } | Kernels::Subgroup => DIGIT_BITS,
        }
    }

    /// Words from one digit's row of tile counts to the next: the tile paths read rows as
    /// vec4, so theirs are padded to a multiple of 4.
    fn row_stride(self, n: u64) -> u64 {
        let tiles = n.div_ceil(self.tile() as u64);
        match self {
            Kernels::Tile { .. } => tiles.next_multiple_of(4),
            Kernels::Subgroup | Kernels::Portable => tiles,
        }
    }

    /// Words of tile counts for `n` keys.
    fn count_words(self, n: u64) -> u64 {
        (1u64 << self.digit_bits()) * self.row_stride(n)
    }
}

/// Workgroup memory of the subgroup scatter kernel in u32 words, for subgroups of at
/// least `min` lanes: 128 counter words per subgroup, the tile, 64 subgroup totals.
fn subgroup_scatter_words(min: u32) -> u32 {
    128 * (256 / min) + SUBGROUP_TILE + 64
}

/// Words of the tile scatter kernel's `region` (REGION_WORDS in scatter_tile.wgsl): 128
/// counter words per subgroup while ranking, then the sorted keys' digits (a quarter
/// word each) and 256 digit moves.
fn tile_region_words(quads: u32, min: u32) -> u32 {
    (128 * (256 / min)).max(TILE_ROW * quads / 4 + 256)
}

/// Workgroup memory of the tile scatter kernel in u32 words: the stage and the region.
fn tile_scatter_words(quads: u32, min: u32) -> u32 {
    TILE_ROW * quads + tile_region_words(quads, min)
}

/// Whether the kernels can run with the device's subgroup sizes and workgroup memory.
fn fits(kernels: Kernels, caps: &DeviceCaps) -> Result<(), String> {
    let words = match (kernels, caps.subgroups) {
        (Kernels::Portable, _) => return Ok(()),
        (_, None) => return Err("the device has no subgroup operations".into()),
        (Kernels::Subgroup, Some((min, max))) => {
            scan::subgroup_scan_fits((min, max))?;
            subgroup_scatter_words(min)
        }
        (Kernels::Tile { quads }, Some((min, max))) => {
            scan::subgroup_scan_fits((min, max))?;
            tile_scatter_words(quads, min)
        }
    };
    let bytes = 4 * words;
    if bytes > caps.max_workgroup_storage {
        let (min, _) = caps.subgroups.unwrap_or_default();
        return Err(format!(
            "subgroups of {min} lanes need {bytes} bytes of workgroup memory, the device has {}",
            caps.max_workgroup_storage
        ));
    }
    Ok(())
}

/// The kernels for a device: the variant's own, or for `auto` the first that fits.
fn choose(variant: SortVariant, caps: &DeviceCaps) -> Result<Kernels, String> {
    let wanted = match variant {
        SortVariant::Auto => {
            let first = [Kernels::Tile { quads: AUTO_QUADS }, Kernels::Subgroup]
                .into_iter()
                .find(|&k| fits(k, caps).is_ok());
            return Ok(first.unwrap_or(Kernels::Portable));
        }
        SortVariant::Tile { quads } => Kernels::Tile { quads },
        SortVariant::Subgroup => Kernels::Subgroup,
        SortVariant::Portable => Kernels::Portable,
    };
    fits(wanted, caps).map_err(|why| {
        format!(
            "sort variant `{}` cannot run on {}: {why}; use `auto` or `portable`",
            variant.name(),
            caps.adapter
        )
    })?;
    Ok(wanted)
}

/// Bytes moved per key by the sort of `n` keys by their low `bits` bits with `variant` on
/// a device: per pass 4 read by the histogram and 16 by the scatter (12 in the first),
/// and per count of a tile's digit 20 more with the general scan (written; read twice
/// and written by the scan; read by the scatter; its upper levels left out) or 16 on the
/// tile paths (written; read and written by `offsets`; read by the scatter).
pub fn traffic_per_key(
    variant: SortVariant,
    caps: &DeviceCaps,
    bits: u32,
    n: u64,
) -> Result<f64, CompileError> {
    let kernels = choose(variant, caps).map_err(CompileError::Unsupported)?;
    let passes = bits.div_ceil(kernels.digit_bits()) as f64;
    let per_count = match kernels {
        Kernels::Tile { .. } => 16.0,
        Kernels::Subgroup | Kernels::Portable => 20.0,
    };
    let counts = per_count * kernels.count_words(n) as f64 / n.max(1) as f64;
    Ok(passes * (20.0 + counts) - 4.0)
}

/// Scratch layout, the same for every variant: tile counts and their scan (sized for
/// every path the variant may take, as scratch sizes come from `infer`, before the
/// device is known), the digit totals of the tile paths, a ping-pong pair for keys and
/// payload when there can be more than one pass, then the general scan's own scratch
/// where it may run.
fn scratch_bytes(n: u64, bits: u32, variant: SortVariant) -> Vec<u64> {
    let paths = variant.possible();
    let words = paths.iter().map(|k| k.count_words(n)).max().unwrap_or(0);
    let general_scan = paths.iter().any(|k| !matches!(k, Kernels::Tile { .. }));
    let mut s = vec![4 * words, 4 * words, 4 * 256 * MAX_PASSES];
    if bits > PORTABLE_DIGIT_BITS.min(DIGIT_BITS) {
        s.extend([4 * n, 4 * n]);
    }
    if general_scan {
        s.extend(scan::scratch_bytes(words));
    }
    s
}

fn sort_kind() -> NodeKind {
    NodeKind::declare(
        "sort",
        "stable radix sort of u32 keys by their low `bits` bits, with the sorting permutation",
    )
    .input(PortSpec::new("keys", PortType::Indices, "keys to sort"))
    .output(PortSpec::new(
        "keys",
        PortType::Indices,
        "the keys in ascending order of their low `bits` bits (equal ones in input order)",
    ))
    .output(PortSpec::new(
        "perm",
        PortType::Indices,
        "input index of each sorted key: keys_out[i] = keys[perm[i]]",
    ))
    .param(ParamSpec::integer(
        "bits",
        Some(32.0),
        1.0,
        32.0,
        "low key bits to sort by; higher bits are ignored (and kept)",
    ))
    .param(SortVariant::param())
    .build(|params| {
        let name = params.text("variant");
        let variant =
            SortVariant::from_name(name).ok_or_else(|| format!("unknown variant `{name}`"))?;
        Ok(Box::new(SortNode {
            bits: params.number("bits") as u32,
            variant,
        }))
    })
}

pub(crate) struct SortNode {
    bits: u32,
    variant: SortVariant,
}

impl SortNode {
    /// The stable radix sort of `bits`-bit keys the device's kernels do best, for a node
    /// that sorts within its own dispatches: `infer` gives its scratch, `compile` its
    /// dispatches (inputs: the keys; outputs: sorted keys, permutation).
    pub(crate) fn radix(bits: u32) -> SortNode {
        SortNode {
            bits: bits.clamp(1, 32),
            variant: SortVariant::Auto,
        }
    }

    fn mask(&self) -> u32 {
        u32::MAX >> (32 - self.bits)
    }
}

impl Node for SortNode {
    fn infer(
        &self,
        inputs: &[Option<ValueType>],
        caps: &DeviceCaps,
    ) -> Result<Signature, PortError> {
        let Some(Some(t)) = inputs.first() else {
            return Err(PortError::new("keys", "is required"));
        };
        Ok(Signature::outputs(vec![*t, *t])
            .with_scratch(scratch_bytes(t.words(), self.bits, self.variant))
            .with_plan(Choice(choose(self.variant, caps))))
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
    stride: u32,
    index: u32,
}

/// The scratch buffers, by role (see [`scratch_bytes`]).
struct Scratch<'a> {
    counts: &'a wgpu::Buffer,
    offsets: &'a wgpu::Buffer,
    totals: &'a wgpu::Buffer,
    pingpong: Option<(&'a wgpu::Buffer, &'a wgpu::Buffer)>,
    scan: &'a [&'a wgpu::Buffer],
}

/// The kernels of one pass, recorded by [`SortNode::compile`] for each digit.
enum PassKernels {
    /// Histogram, general scan, scatter.
    Scanned {
        histogram: Arc<Kernel>,
        scan: ScanKernels,
        scatter: Arc<Kernel>,
    },
    /// Tile counts with digit totals, row scan, scatter.
    Tiles {
        counts: Arc<Kernel>,
        offsets: Arc<Kernel>,
        scatter: Arc<Kernel>,
    },
}

fn scatter_bindings() -> [Binding; 6] {
    [
        Binding::StorageRead,
        Binding::StorageRead,
        Binding::StorageRead,
        Binding::StorageReadWrite,
        Binding::StorageReadWrite,
        Binding::Uniform,
    ]
}

impl PassKernels {
    fn new(cx: &mut CompileCtx<'_>, kernels: Kernels) -> Result<Self, CompileError> {
        // Only the portable kernels, which take no subgroup sizes, run without subgroups.
        let (min, max) = cx.caps().subgroups.unwrap_or((4, 128));
        let wide = if max > 32 { 1.0 } else { 0.0 };
        match kernels {
            Kernels::Tile { quads } => {
                let tile = TILE_ROW * quads;
                let scatter = cx.kernel(
                    &KernelSpec::new(
                        format!("sort scatter (tile {tile})"),
                        cx.shader("sort/scatter_tile.wgsl")?,
                        &scatter_bindings(),
                    )
                    .constant("QUADS", quads as f64)
                    .constant("TILE", tile as f64)
                    .constant("REGION_WORDS", tile_region_words(quads, min) as f64)
                    .constant("WIDE", wide),
                )?;
                let counts = cx.kernel(
                    &KernelSpec::new(
                        format!("sort tile counts ({tile})"),
                        cx.shader("sort/tile_counts.wgsl")?,
                        &[
                            Binding::StorageRead,
                            Binding::StorageReadWrite,
                            Binding::StorageReadWrite,
                            Binding::Uniform,
                        ],
                    )
                    .constant("QUADS", quads as f64),
                )?;
                let offsets = cx.kernel(&KernelSpec::new(
                    "sort offsets",
                    cx.shader("sort/offsets.wgsl")?,
                    &[
                        Binding::StorageRead,
                        Binding::StorageRead,
                        Binding::StorageReadWrite,
                        Binding::Uniform,
                    ],
                ))?;
                Ok(PassKernels::Tiles {
                    counts,
                    offsets,
                    scatter,
                })
            }
            Kernels::Subgroup | Kernels::Portable => {
                let (path, file) = if kernels == Kernels::Subgroup {
                    (Path::Subgroup, "sort/scatter_subgroup.wgsl")
                } else {
                    (Path::Portable, "sort/scatter_portable.wgsl")
                };
                let mut spec = KernelSpec::new(
                    format!("sort scatter ({path:?})"),
                    cx.shader(file)?,
                    &scatter_bindings(),
                );
                if path == Path::Subgroup {
                    spec = spec
                        .constant("COUNTER_WORDS", (128 * (256 / min)) as f64)
                        .constant("WIDE", wide);
                }
                let scatter = cx.kernel(&spec)?;
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
                    .constant("TILE", kernels.tile() as f64),
                )?;
                let scan = ScanKernels::new(cx, path, Elem::U32)?;
                Ok(PassKernels::Scanned {
                    histogram,
                    scan,
                    scatter,
                })
            }
        }
    }

    /// Records one pass: `src` keys and payload (the keys stand in for the payload in
    /// the first pass, whose payload is the identity) to `dst`.
    fn record(
        &self,
        cx: &CompileCtx<'_>,
        cfg: &PassParams,
        src: (&wgpu::Buffer, &wgpu::Buffer),
        dst: (&wgpu::Buffer, &wgpu::Buffer),
        s: &Scratch<'_>,
        out: &mut Vec<Dispatch>,
    ) -> Result<(), CompileError> {
        let grid = cx.grid_1d(cfg.ntiles as u64, 1);
        let uniform = cx.uniform("sort pass", bytemuck::bytes_of(cfg));
        let scatter = match self {
            PassKernels::Scanned {
                histogram,
                scan,
                scatter,
            } => {
                out.push(cx.dispatch(histogram, &[src.0, s.counts, &uniform], grid));
                let len = cfg.radix as u64 * cfg.ntiles as u64;
                scan.record(cx, s.counts, s.offsets, len, s.scan, out)?;
                scatter
            }
            PassKernels::Tiles {
                counts,
                offsets,
                scatter,
            } => {
                out.push(cx.dispatch(counts, &[src.0, s.counts, s.totals, &uniform], grid));
                out.push(cx.dispatch(
                    offsets,
                    &[s.counts, s.totals, s.offsets, &uniform],
                    cx.grid_1d(cfg.radix as u64, 1),
                ));
                scatter
            }
        };
        out.push(cx.dispatch(
            scatter,
            &[src.0, src.1, s.offsets, dst.0, dst.1, &uniform],
            grid,
        ));
        Ok(())
    }
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
        let kernels = *io.plan::<Choice<Kernels>>().get()?;
        let pass_kernels = PassKernels::new(cx, kernels)?;

        let has_pingpong = self.bits > PORTABLE_DIGIT_BITS.min(DIGIT_BITS);
        let scratch = match (io.scratch.as_slice(), has_pingpong) {
            ([counts, offsets, totals, k, v, scan @ ..], true) => Scratch {
                counts,
                offsets,
                totals,
                pingpong: Some((k, v)),
                scan,
            },
            ([counts, offsets, totals, scan @ ..], false) => Scratch {
                counts,
                offsets,
                totals,
                pingpong: None,
                scan,
            },
            _ => return Err(missing()),
        };
        let digit_bits = kernels.digit_bits();
        let passes = self.bits.div_ceil(digit_bits);
        let ntiles = n.div_ceil(kernels.tile() as u64);

        let mut out = Vec::new();
        if matches!(kernels, Kernels::Tile { .. }) {
            // The counts kernel adds each pass's digit totals into its own row.
            out.push(cx.fill(scratch.totals, 256 * passes as u64, 0)?);
        }
        let mut src = (keys.buffer, keys.buffer);
        for p in 0..passes {
            let shift = p * digit_bits;
            let width = digit_bits.min(self.bits - shift);
            // The last pass writes the outputs, so passes alternate backwards from it.
            let dst = if (passes - 1 - p) % 2 == 0 {
                (out_keys.buffer, out_perm.buffer)
            } else {
                scratch.pingpong.ok_or_else(missing)?
            };
            let cfg = PassParams {
                n: n32,
                ntiles: ntiles as u32,
                shift,
                mask: (1 << width) - 1,
                radix: 1 << width,
                first: u32::from(p == 0),
                stride: kernels.row_stride(n) as u32,
                index: p,
            };
            pass_kernels.record(cx, &cfg, src, dst, &scratch, &mut out)?;
            src = dst;
        }
        Ok(out)
    }
}

pub fn register(r: &mut Registry) {
    r.add(sort_kind());
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
    fn every_variant_name_parses_back() {
        for name in SortVariant::NAMES {
            assert!(SortVariant::from_name(name).is_some(), "{name}");
        }
        assert_eq!(SortVariant::from_name("tile1"), None);
    }

    #[test]
    fn the_subgroup_kernels_fit_lavapipe_and_nvidia() {
        // lavapipe: subgroups of 8, 32 KiB of workgroup memory; NVIDIA: 32 lanes, 48 KiB.
        assert!(4 * subgroup_scatter_words(8) <= 32 << 10);
        assert!(4 * subgroup_scatter_words(32) <= 20 << 10);
        for quads in 2..=4 {
            assert!(4 * tile_scatter_words(quads, 8) <= 32 << 10, "{quads}");
            assert!(4 * tile_scatter_words(quads, 32) <= 22 << 10, "{quads}");
        }
    }

    #[test]
    fn auto_takes_the_largest_tile_then_falls_back() {
        let mut caps = DeviceCaps::baseline();
        caps.max_workgroup_storage = 48 << 10;
        assert_eq!(
            choose(SortVariant::Auto, &caps).ok(),
            Some(Kernels::Portable)
        );
        caps.subgroups = Some((32, 32));
        assert_eq!(
            choose(SortVariant::Auto, &caps).ok(),
            Some(Kernels::Tile { quads: AUTO_QUADS })
        );
        // Subgroups of 16 and 24000 bytes: the tile path needs 24576, the subgroup 23808.
        caps.subgroups = Some((16, 16));
        caps.max_workgroup_storage = 24000;
        assert_eq!(
            choose(SortVariant::Auto, &caps).ok(),
            Some(Kernels::Subgroup)
        );
        assert!(choose(SortVariant::Tile { quads: 4 }, &caps).is_err());
    }

    #[test]
    fn scratch_covers_every_path_a_variant_may_take() {
        let n = 1_000_003;
        for name in SortVariant::NAMES {
            let Some(variant) = SortVariant::from_name(name) else {
                continue;
            };
            let s = scratch_bytes(n, 32, variant);
            for k in variant.possible() {
                assert!(s[0] >= 4 * k.count_words(n), "{name}");
            }
        }
        // Rows of the tile paths are vec4-aligned.
        assert_eq!(Kernels::Tile { quads: 4 }.row_stride(4097), 4);
    }
}
