//! `bin_sort`: counting sort of small u32 keys (bin indices: the cell of each particle)
//! by atomics, with the sorting permutation, the count of keys per bin and the first slot
//! of each bin. It does what `sort` + `histogram` + `scan` do for a cell list, in four
//! dispatches instead of about ten: at 10^4-10^5 keys those cost little but per-dispatch
//! latency, so the dispatch count is the point.
//!
//! 1. Clear `bins + 1` counters (the engine's fill), one per bin and one overflow
//!    counter for keys at or past `bins`.
//! 2. `count` (shaders/bin_sort/count.wgsl): one thread per key,
//!    `rank[i] = atomicAdd(&counter[min(key, bins)], 1)`, the rank kept in scratch.
//! 3. The exclusive scan of the first `bins` counters into `start`, which also copies
//!    them to `count`: one workgroup of 1024 threads (256 where the device allows no
//!    more) with up to [`MAX_PER_THREAD`] counters each, in one dispatch
//!    (shaders/bin_sort/scan_subgroup.wgsl where the device has subgroups,
//!    scan_portable.wgsl otherwise: the `variant` param, as for `scan`). More bins than
//!    that one workgroup holds (32768, or 8192) take the general scan of nodes/scan.rs
//!    (3 dispatches up to 4096^2 bins, more past that), and the place kernel copies the
//!    counters to `count`.
//! 4. `place` (shaders/bin_sort/place.wgsl): key i goes to slot `start[bin] + rank[i]`;
//!    the overflow bin starts after every bin.
//!
//! Four dispatches up to 32768 bins (8192 on devices of 256 threads per workgroup), six
//! up to 4096^2; with N = 0 the count and place kernels drop out where they have nothing
//! to do.
//!
//! Order inside a bin is NOT stable: ranks come in whatever order the atomics run, and
//! change from run to run. Use `sort` where equal keys must keep their input order (or
//! where keys are not small: the counters take 4 bytes per bin). Deterministic runs
//! (`DeviceCaps::deterministic`) make it stable at the price of two more dispatches:
//! after step 4, `stable_rank` (shaders/bin_sort/stable_rank.wgsl) ranks each key by the
//! indices of its bin below its own, and `place` runs again with those ranks (each key
//! reads its whole bin: cheap for cell lists and tiles of a few hundred keys, quadratic
//! in a bin's size).
//!
//! Keys at or past `bins` are well defined: they sort after every bin (in any order among
//! themselves) and are counted in no bin, so `start[bins - 1] + count[bins - 1]` is the
//! first of them.
//!
//! Contention: keys of one bin meet at one counter. A cell list's bins hold a few
//! particles each; a single bin holding every key serialises its atomics (still correct).

use std::sync::Arc;

use crate::gpu::{
    Binding, Choice, CompileCtx, CompileError, DeviceCaps, Dispatch, Kernel, KernelSpec, NodeIo,
    WG_1D,
};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamSpec, PortError, PortSpec, RefCtx, Registry,
    Signature,
};
use crate::nodes::scan::{self, Path, ScanKernels, Variant};
use crate::value::{Elem, PortType, RefArray, ValueType};

/// Counters per thread of the one-workgroup scan at most (`quads` <= 8 in
/// shaders/bin_sort/scan_common.wgsl).
pub const MAX_PER_THREAD: u64 = 32;
/// Threads of the one-workgroup scan: the larger where the device allows it.
const WIDE_WG: u32 = 1024;
const NARROW_WG: u32 = 256;
/// Largest `bins`: the overflow counter `bins` must be a u32 too.
const MAX_BINS: f64 = (u32::MAX - 1) as f64;

/// Threads of the one-workgroup scan on a device.
fn scan_threads(caps: &DeviceCaps) -> u32 {
    if caps.max_invocations >= WIDE_WG {
        WIDE_WG
    } else {
        NARROW_WG
    }
}

/// Bins the one-workgroup scan takes on a device; more take the general scan.
pub fn single_scan_capacity(caps: &DeviceCaps) -> u64 {
    scan_threads(caps) as u64 * MAX_PER_THREAD
}

/// How step 3 runs for `bins` bins on a device.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScanPath {
    /// One workgroup of `threads`, `quads` vec4 of counters each; writes count and start.
    Single { threads: u32, quads: u32 },
    /// The general scan of nodes/scan.rs; the place kernel copies the counters to `count`.
    General,
}

pub fn scan_path(bins: u64, caps: &DeviceCaps) -> ScanPath {
    let threads = scan_threads(caps);
    if bins <= threads as u64 * MAX_PER_THREAD {
        let quads = bins.div_ceil(4 * threads as u64).max(1) as u32;
        ScanPath::Single { threads, quads }
    } else {
        ScanPath::General
    }
}

/// How a counting sort runs on an adapter, decided once (in `infer`, or by the node that
/// sorts inside): the scan kernels' path and how the counters are scanned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BinSortPlan {
    pub path: Path,
    pub scan: ScanPath,
    /// Bins the one-workgroup scan takes on this adapter (for the notes).
    pub capacity: u64,
    /// Order inside a bin by input index (deterministic runs), not by the atomics.
    pub stable: bool,
}

/// The plan for `bins` bins with `variant` on this adapter, or why the variant cannot
/// run there.
pub fn plan(variant: Variant, bins: u32, caps: &DeviceCaps) -> Result<BinSortPlan, String> {
    Ok(BinSortPlan {
        path: variant.choose(caps, "bin_sort", scan::subgroup_scan_fits)?,
        scan: scan_path(bins as u64, caps),
        capacity: single_scan_capacity(caps),
        stable: caps.deterministic,
    })
}

impl std::fmt::Display for BinSortPlan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.scan {
            ScanPath::Single { threads, quads } => write!(
                f,
                "strategy: {} kernels; bins scanned by one workgroup of {threads} threads ({} counters each)",
                self.path,
                4 * quads
            ),
            ScanPath::General => write!(
                f,
                "strategy: {} kernels; more than {} bins: the general scan (the place kernel copies the counts)",
                self.path, self.capacity
            ),
        }?;
        if self.stable {
            write!(f, "; stable inside a bin (deterministic)")?;
        }
        Ok(())
    }
}

/// Scratch layout: the counters (bins + 1 words, padded to whole vec4), the ranks (one
/// word per key), then the general scan's own scratch where it may run (the scratch is
/// fixed before the device is known, so for every bin count past the smallest device's
/// one-workgroup capacity).
pub fn scratch_bytes(n: u64, bins: u64) -> Vec<u64> {
    let mut s = vec![16 * (bins + 1).div_ceil(4), 4 * n.max(1)];
    if bins > NARROW_WG as u64 * MAX_PER_THREAD {
        s.extend(scan::scratch_bytes(bins));
    }
    s
}

fn bin_sort_kind() -> NodeKind {
    NodeKind::declare(
        "bin_sort",
        "counting sort of keys into `bins` bins by atomics (order inside a bin NOT stable, except in deterministic runs (--deterministic), which keep input order at the cost of two more dispatches: use `sort` where it matters; keys >= bins sort last, uncounted), with permutation, count and first slot per bin",
    )
    .input(PortSpec::new(
        "keys",
        PortType::Indices,
        "bin of each element (keys >= bins go to an overflow bin after all the others)",
    ))
    .output(PortSpec::new(
        "perm",
        PortType::Indices,
        "input index of each sorted slot: keys_out[s] = keys[perm[s]] (any order inside a bin)",
    ))
    .output(PortSpec::new(
        "keys",
        PortType::Indices,
        "the keys in ascending order of bin (keys >= bins last)",
    ))
    .output(PortSpec::new(
        "count",
        PortType::Indices,
        "keys in each bin (`bins` values; keys >= bins not counted)",
    ))
    .output(PortSpec::new(
        "start",
        PortType::Indices,
        "first slot of each bin: the exclusive prefix sum of count",
    ))
    .param(ParamSpec::integer(
        "bins",
        None,
        1.0,
        MAX_BINS,
        "number of bins (keys in [0, bins)); the counters take 4 bytes per bin",
    ))
    .param(Variant::param())
    .build(|p| {
        Ok(Box::new(BinSort {
            bins: p.number("bins") as u32,
            variant: Variant::from_params(p)?,
        }))
    })
}

struct BinSort {
    bins: u32,
    variant: Variant,
}

impl Node for BinSort {
    fn infer(
        &self,
        inputs: &[Option<ValueType>],
        caps: &DeviceCaps,
    ) -> Result<Signature, PortError> {
        let Some(Some(t @ ValueType::Indices { n })) = inputs.first().copied() else {
            return Err(PortError::new("keys", "is required"));
        };
        let bins = ValueType::Indices { n: self.bins };
        Ok(Signature::outputs(vec![t, t, bins, bins])
            .with_scratch(scratch_bytes(n as u64, self.bins as u64))
            .with_plan(Choice(plan(self.variant, self.bins, caps))))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn notes(&self, _inputs: &[Option<ValueType>]) -> Vec<String> {
        vec![format!(
            "{} bins, {} B of counters",
            self.bins,
            16 * (self.bins as u64 + 1).div_ceil(4)
        )]
    }

    /// A stable counting sort (the GPU's order inside a bin is any order: compare the
    /// outputs after canonicalising it, as tests/it/bin_sort.rs does).
    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _cx: RefCtx) {
        let Some(Some(keys)) = inputs.first() else {
            return;
        };
        let bins = self.bins as usize;
        let bin = |k: f64| (k as usize).min(bins);
        let mut count = vec![0usize; bins + 1];
        for &k in &keys.data {
            count[bin(k)] += 1;
        }
        let mut next = vec![0usize; bins + 1];
        let mut acc = 0;
        for (b, c) in count.iter().enumerate() {
            next[b] = acc;
            acc += c;
        }
        for b in 0..bins {
            outputs[2].data[b] = count[b] as f64;
            outputs[3].data[b] = next[b] as f64;
        }
        for (i, &k) in keys.data.iter().enumerate() {
            let slot = &mut next[bin(k)];
            outputs[0].data[*slot] = i as f64;
            outputs[1].data[*slot] = k;
            *slot += 1;
        }
    }
}

fn shader_kernel(
    cx: &mut CompileCtx<'_>,
    label: &str,
    file: &str,
    bindings: &[Binding],
) -> Result<Arc<Kernel>, CompileError> {
    let source = cx.shader(file)?;
    cx.kernel(&KernelSpec::new(label, source, bindings))
}

impl GpuKernels for BinSort {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let missing = || CompileError::Unsupported("bin_sort: a port has no buffer".into());
        let keys = io.inputs.first().copied().flatten().ok_or_else(missing)?;
        let [perm, keys_out, count, start] = io.outputs.as_slice() else {
            return Err(missing());
        };
        let [counter, rank, scan_scratch @ ..] = io.scratch.as_slice() else {
            return Err(missing());
        };
        record(
            cx,
            io.plan::<Choice<BinSortPlan>>().get()?,
            self.bins,
            keys.ty.words(),
            &BinSortBuffers {
                keys: keys.buffer,
                perm: perm.buffer,
                keys_out: keys_out.buffer,
                count: count.buffer,
                start: start.buffer,
                counter,
                rank,
                scan_scratch,
            },
        )
    }
}

/// The buffers of one counting sort: the keys, the node's four outputs and its scratch
/// (`scratch_bytes`: the counters, the ranks, the general scan's own).
pub struct BinSortBuffers<'a> {
    pub keys: &'a wgpu::Buffer,
    pub perm: &'a wgpu::Buffer,
    pub keys_out: &'a wgpu::Buffer,
    pub count: &'a wgpu::Buffer,
    pub start: &'a wgpu::Buffer,
    pub counter: &'a wgpu::Buffer,
    pub rank: &'a wgpu::Buffer,
    pub scan_scratch: &'a [&'a wgpu::Buffer],
}

/// The dispatches of a counting sort of `n` keys into `bins` bins (clear the counters,
/// rank, scan, place), for the node and for nodes that sort inside (tiled spreading).
pub fn record(
    cx: &mut CompileCtx<'_>,
    plan: &BinSortPlan,
    bins: u32,
    n: u64,
    b: &BinSortBuffers<'_>,
) -> Result<Vec<Dispatch>, CompileError> {
    let n32 = u32::try_from(n).map_err(|_| {
        CompileError::Unsupported(format!("bin_sort of {n} keys: at most 2^32 - 1"))
    })?;
    let path = plan.path;
    let mut out = vec![cx.fill(b.counter, bins as u64 + 1, 0)?];
    if n > 0 {
        let shape = cx.uniform("bin_sort count", bytemuck::cast_slice(&[n32, bins]));
        let kernel = shader_kernel(
            cx,
            "bin_sort count",
            "bin_sort/count.wgsl",
            &[
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::StorageReadWrite,
                Binding::Uniform,
            ],
        )?;
        out.push(cx.dispatch(
            &kernel,
            &[b.keys, b.counter, b.rank, &shape],
            cx.grid_1d(n, WG_1D),
        ));
    }
    // Counters the place kernel copies to `count` (the one-workgroup scan writes them).
    let copy = match plan.scan {
        ScanPath::Single { threads, quads } => {
            let file = match path {
                Path::Subgroup => "bin_sort/scan_subgroup.wgsl",
                Path::Portable => "bin_sort/scan_portable.wgsl",
            };
            let mut spec = KernelSpec::new(
                format!("bin_sort scan ({threads} threads, {path:?})"),
                cx.shader(file)?,
                &[
                    Binding::StorageRead,
                    Binding::StorageReadWrite,
                    Binding::StorageReadWrite,
                    Binding::Uniform,
                ],
            )
            .constant("WG", threads as f64);
            if path == Path::Subgroup {
                // Its loops over a thread's quads have a constant trip count.
                spec = spec.constant("QUADS", quads as f64);
            }
            let kernel = cx.kernel(&spec)?;
            let params = cx.uniform("bin_sort scan", bytemuck::cast_slice(&[bins, quads]));
            out.push(cx.dispatch(&kernel, &[b.counter, b.count, b.start, &params], [1, 1, 1]));
            0
        }
        ScanPath::General => {
            let kernels = ScanKernels::new(cx, path, Elem::U32)?;
            kernels.record(
                cx,
                b.counter,
                b.start,
                bins as u64,
                b.scan_scratch,
                &mut out,
            )?;
            bins
        }
    };
    let threads = n.max(copy as u64);
    if threads > 0 {
        let kernel = shader_kernel(
            cx,
            "bin_sort place",
            "bin_sort/place.wgsl",
            &[
                Binding::StorageRead,
                Binding::StorageRead,
                Binding::StorageRead,
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::StorageReadWrite,
                Binding::StorageReadWrite,
                Binding::Uniform,
            ],
        )?;
        let shape = cx.uniform("bin_sort place", bytemuck::cast_slice(&[n32, bins, copy]));
        let place = cx.dispatch(
            &kernel,
            &[
                b.keys, b.rank, b.counter, b.start, b.perm, b.keys_out, b.count, &shape,
            ],
            cx.grid_1d(threads, WG_1D),
        );
        if plan.stable && n > 0 {
            // Rank again by input index inside each bin, then place again: the same
            // kernel and buffers, now with order-independent ranks.
            let rank_kernel = shader_kernel(
                cx,
                "bin_sort stable rank",
                "bin_sort/stable_rank.wgsl",
                &[
                    Binding::StorageRead,
                    Binding::StorageRead,
                    Binding::StorageRead,
                    Binding::StorageRead,
                    Binding::StorageReadWrite,
                    Binding::Uniform,
                ],
            )?;
            let rank_shape = cx.uniform("bin_sort stable rank", bytemuck::cast_slice(&[n32, bins]));
            let again = place.clone();
            out.push(place);
            out.push(cx.dispatch(
                &rank_kernel,
                &[b.keys, b.perm, b.counter, b.start, b.rank, &rank_shape],
                cx.grid_1d(n, WG_1D),
            ));
            out.push(again);
        } else {
            out.push(place);
        }
    }
    Ok(out)
}

pub fn register(r: &mut Registry) {
    r.add(bin_sort_kind());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scan_path_follows_bins_and_device_limits() {
        let mut caps = DeviceCaps::baseline();
        caps.max_invocations = 1024;
        assert_eq!(
            scan_path(1, &caps),
            ScanPath::Single {
                threads: 1024,
                quads: 1
            }
        );
        assert_eq!(
            scan_path(4097, &caps),
            ScanPath::Single {
                threads: 1024,
                quads: 2
            }
        );
        assert_eq!(
            scan_path(32768, &caps),
            ScanPath::Single {
                threads: 1024,
                quads: 8
            }
        );
        assert_eq!(scan_path(32769, &caps), ScanPath::General);
        caps.max_invocations = 256;
        assert_eq!(
            scan_path(8192, &caps),
            ScanPath::Single {
                threads: 256,
                quads: 8
            }
        );
        assert_eq!(scan_path(8193, &caps), ScanPath::General);
    }

    #[test]
    fn the_quads_bound_matches_the_shader() {
        let src = crate::gpu::shaders::raw("bin_sort/scan_common.wgsl").unwrap_or_default();
        assert!(src.contains(&format!(
            "at most {}: {MAX_PER_THREAD} counters",
            MAX_PER_THREAD / 4
        )));
        // Workgroup memory of the portable scan: two halves of the widest workgroup.
        let portable = crate::gpu::shaders::raw("bin_sort/scan_portable.wgsl").unwrap_or_default();
        assert!(portable.contains(&format!("array<u32, {}>", 2 * WIDE_WG)));
    }

    #[test]
    fn scratch_holds_the_general_scan_only_where_it_may_run() {
        assert_eq!(scratch_bytes(0, 1), vec![16, 4]);
        assert_eq!(scratch_bytes(10, 8192), vec![16 * 2049, 40]);
        let s = scratch_bytes(10, 8193);
        assert_eq!(s.len(), 4);
        assert_eq!(&s[2..], scan::scratch_bytes(8193).as_slice());
    }
}
