//! `overlap_correction_round`: one round of S1's overlap correction (section 2.3, eq. 4;
//! Algorithm 2) along the edges of the torus mesh (`mesh.rs` layout): every pair of
//! neighbours closer than sigma is pushed apart along its line of centres, each particle
//! by delta (sigma - r) (the paper's delta* = sigma - r: the whole overlap, "a bounce"),
//! the sum over a particle's edges clamped to length sigma / 4 (S1 section 4.4, the norm:
//! summed corrections that point the same way would overshoot and diverge), then the
//! particle moves and wraps into the box.
//!
//! No float atomics: each particle gathers over its own edges, in the order of the fan of
//! triangles around it walked by twins from its lowest corner, so the sums run in a fixed
//! order. The count output is the number of overlapping pairs (along edges) in the
//! positions read (a round that counts 0 moved nothing, which is when a loop stops), then
//! the number of disks in at least one such pair (S1's overlapping fraction, times N).
//!
//! **Fans once per mesh.** The mesh stays fixed while the rounds repeat (S1 section 4.4),
//! so what depends on it alone is the node `vertex_fans` (`shaders/disks/fans.wgsl`),
//! placed before the loop: per vertex its edge count, its lowest corner and the far ends
//! of its first `width` edges in walk order, column-major (rows of N words). A round
//! (`shaders/disks/overlap.wgsl`) is then one kernel over the particles reading their
//! neighbours contiguously (a fill zeroes the count before it); a fan wider than the
//! table is finished by walking the mesh from the first corner. The f64 round
//! [`overlap_round`] walks the mesh itself: the table is only a cache of the walk.
//!
//! **Tolerance.** A pair counts as overlapping below sigma - `overlap_tolerance` (8 f32
//! ulps of the largest coordinate, at least 1e-6 sigma): an overlap smaller than the
//! coordinates' resolution cannot be removed by moving them (the move rounds away), and
//! counting it kept loops going to their cap in dense, forced runs.

use super::flip::{check_mesh_twins, reference_mesh};
use super::mesh::MESH_WORDS;
use super::{minimum_image, wrap};
use crate::gpu::DeviceCaps;
use crate::gpu::{Binding, CompileCtx, CompileError, Dispatch, KernelSpec, NodeIo, WG_1D};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamKind, ParamSpec, PortError, PortSpec, RefCtx,
    Registry, RowError, Signature,
};
use crate::value::{HostArray, HostData, PortType, RefArray, ValueType};

/// The longest fan the kernels walk (`MAX_FAN` in the shaders).
const MAX_FAN: usize = 128;

/// The neighbour rows of `vertex_fans`' table by default: 6 edges per vertex on average,
/// more than 10 at about 1 vertex in 600 even for random points (the Poisson-Delaunay
/// degrees of Hinde and Miles 1980), fewer for packed disks; wider fans are finished from
/// the mesh. With 10 the table (12N words) is
/// the mesh's size, so it meets no binding limit the mesh does not.
const FAN_WIDTH: f64 = 10.0;

/// Each vertex's lowest corner (`usize::MAX` for a vertex in no triangle).
fn first_corners(mesh: &[u32], n: usize) -> Vec<usize> {
    let slots = mesh.len() / MESH_WORDS * 3;
    let mut first = vec![usize::MAX; n];
    for c in (0..slots).rev() {
        let v = mesh[MESH_WORDS * (c / 3) + c % 3] as usize;
        if v < n {
            first[v] = c;
        }
    }
    first
}

/// The far ends of `v`'s edges in walk order (by twins from its first corner, at most
/// `MAX_FAN`).
fn fan(mesh: &[u32], first: usize) -> Vec<usize> {
    let slots = mesh.len() / MESH_WORDS * 3;
    let mut ends = Vec::new();
    let mut c = first;
    while ends.len() < MAX_FAN && c < slots {
        let (t, k) = (c / 3, c % 3);
        ends.push(mesh[MESH_WORDS * t + (k + 1) % 3] as usize);
        let u = mesh[MESH_WORDS * t + 3 + (k + 2) % 3] as usize;
        c = 3 * (u / 3) + (u % 3 + 2) % 3;
        if c == first {
            break;
        }
    }
    ends
}

/// The table of `vertex_fans` (the twin of `shaders/disks/fans.wgsl`) for a mesh over `n`
/// vertices: rows of n words, column-major: the edge counts, the first corners
/// (0xFFFFFFFF for none), then `width` rows of far ends (0 past a vertex's edges).
pub fn vertex_fans(mesh: &[u32], n: usize, width: usize) -> Vec<u32> {
    let mut table = vec![0u32; (2 + width) * n];
    for (v, &first) in first_corners(mesh, n).iter().enumerate() {
        let ends = fan(mesh, first);
        table[v] = ends.len() as u32;
        table[n + v] = first.min(u32::MAX as usize) as u32;
        for (j, &w) in ends.iter().take(width).enumerate() {
            table[(2 + j) * n + v] = w as u32;
        }
    }
    table
}

/// The vertices of a mesh input of `words` words (2N triangles), or the port's problem.
fn mesh_vertices(words: u32, port: &str) -> Result<u32, PortError> {
    if words == 0 || !(words as usize).is_multiple_of(2 * MESH_WORDS) {
        return Err(PortError::new(
            port,
            format!(
                "has {words} words; a triangulation of the torus over N points has 2N triangles of {MESH_WORDS} words"
            ),
        ));
    }
    Ok(words / (2 * MESH_WORDS as u32))
}

fn vertex_fans_kind() -> NodeKind {
    NodeKind::declare(
        "vertex_fans",
        "each vertex's edges in the disk mesh, walked once for the overlap-correction rounds that read them: (2 + width) x N u32, column-major rows of N: the edge count, the lowest corner (3 t + k; the walk's start, so the rounds sum in a fixed order), then the far ends of the first `width` edges in walk order (around the vertex by twins)",
    )
    .input(PortSpec::new(
        "mesh",
        PortType::Indices,
        "the triangulation of the torus (2N triangles x 6 words, nodes/disks/mesh.rs)",
    ))
    .output(PortSpec::new(
        "fans",
        PortType::Indices,
        "the fan table ((2 + width) x N words, column-major)",
    ))
    .param(ParamSpec::integer(
        "width",
        Some(FAN_WIDTH),
        1.0,
        MAX_FAN as f64,
        "edges per vertex kept in the table (wider fans are finished from the mesh by the round)",
    ))
    .build(|p| {
        Ok(Box::new(VertexFans {
            width: p.number("width") as u32,
        }))
    })
}

pub struct VertexFans {
    width: u32,
}

impl Node for VertexFans {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let Some(ValueType::Indices { n: words }) = inputs[0] else {
            unreachable!("port type checked")
        };
        let n = mesh_vertices(words, "mesh")?;
        let table = (2 + self.width as u64) * n as u64;
        let Ok(table) = u32::try_from(table) else {
            return Err(PortError::new(
                "mesh",
                format!("over {n} vertices makes a fan table of {table} words, past 2^32"),
            ));
        };
        Ok(Signature::outputs(vec![ValueType::Indices { n: table }]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn check_input(&self, _: usize, data: &HostArray) -> Result<(), RowError> {
        match &data.data {
            HostData::U32(mesh) => check_mesh_twins(mesh),
            _ => Ok(()),
        }
    }

    fn checks_input(&self) -> bool {
        true
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let mesh = reference_mesh(&inputs[0]);
        let n = mesh.len() / (2 * MESH_WORDS);
        let table = vertex_fans(&mesh, n, self.width as usize);
        outputs[0].data = table.iter().map(|&v| v as f64).collect();
    }
}

impl GpuKernels for VertexFans {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let mesh = io.inputs[0].expect("required");
        let slots = (mesh.ty.words() / 2) as u32;
        let n = slots / 6;
        let bindings = [
            Binding::StorageRead,
            Binding::StorageReadWrite,
            Binding::Uniform,
        ];
        let source = cx.shader("disks/fans.wgsl")?;
        let words: [u32; 4] = [n, slots, self.width, 0];
        let params = cx.uniform("vertex fans", bytemuck::cast_slice(&words));
        let buffers = [mesh.buffer, io.outputs[0].buffer, &params];
        let mut out = Vec::new();
        for (entry, items) in [
            ("clear", n as u64),
            ("corners", slots as u64),
            ("walk", n as u64),
        ] {
            let kernel = cx.kernel(
                &KernelSpec::new(format!("vertex_fans_{entry}"), source.clone(), &bindings)
                    .entry(entry),
            )?;
            out.push(cx.dispatch(&kernel, &buffers, cx.grid_1d(items, WG_1D)));
        }
        Ok(out)
    }
}

fn overlap_correction_round_kind() -> NodeKind {
    NodeKind::declare(
        "overlap_correction_round",
        "one round of S1's overlap correction along the mesh edges: each particle moves by delta (sigma - r) along the line of centres away from every neighbour closer than sigma, the sum clamped to sigma/4, wrapped into the box; `overlaps` counts the overlapping pairs read (0: nothing moved). The edges come from `fans` (`vertex_fans` of the mesh, made once outside the loop of rounds), the mesh finishes fans wider than that table",
    )
    .input(PortSpec::new(
        "positions",
        PortType::Particles(Some(2)),
        "positions (N x 2)",
    ))
    .input(PortSpec::new(
        "mesh",
        PortType::Indices,
        "the triangulation of the torus (2N triangles x 6 words, nodes/disks/mesh.rs)",
    ))
    .input(PortSpec::new(
        "fans",
        PortType::Indices,
        "the mesh's fan table (`vertex_fans` of the same mesh, made once before the rounds)",
    ))
    .output(PortSpec::new(
        "positions",
        PortType::Particles(Some(2)),
        "the corrected positions (N x 2)",
    ))
    .output(PortSpec::new(
        "overlaps",
        PortType::Indices,
        "before the round: the number of overlapping pairs along edges, then the number of disks in at least one (2 words; the overlapping fraction is the second over N)",
    ))
    .param(ParamSpec::f32_positive("sigma", Some(1.0), "disk diameter sigma"))
    .param(ParamSpec::number(
        "delta",
        Some(1.0),
        0.0,
        10.0,
        "each particle of an overlapping pair moves by delta (sigma - r): S1 uses 1 (the whole overlap)",
    ))
    .param(ParamSpec {
        name: "box",
        kind: ParamKind::Numbers {
            len: Some(2),
            min: 1e-18,
            max: 1e18,
        },
        default: None,
        doc: "box lengths (Lx, Ly) of the torus",
    })
    .build(|p| {
        let b = p.numbers("box");
        Ok(Box::new(OverlapCorrectionRound {
            sigma: p.number("sigma"),
            delta: p.number("delta"),
            box_lengths: [b[0], b[1]],
        }))
    })
}

pub struct OverlapCorrectionRound {
    sigma: f64,
    delta: f64,
    box_lengths: [f64; 2],
}

/// The overlap the correction leaves alone: 8 f32 ulps of the largest coordinate (half
/// the box), at least 1e-6 sigma.
pub fn overlap_tolerance(sigma: f64, l: [f64; 2]) -> f64 {
    (8.0 * f32::EPSILON as f64 * 0.5 * l[0].max(l[1])).max(1e-6 * sigma)
}

/// One round in f64, the twin of `shaders/disks/overlap.wgsl`: the corrected positions,
/// the number of overlapping pairs along edges and the number of disks in at least one.
pub fn overlap_round(
    mesh: &[u32],
    x: &[f64],
    l: [f64; 2],
    sigma: f64,
    delta: f64,
) -> (Vec<f64>, u32, u32) {
    let n = x.len() / 2;
    let mut out = vec![0.0; 2 * n];
    let mut count = 0;
    let mut disks = 0;
    let limit = (sigma - overlap_tolerance(sigma, l)) as f32 as f64;
    for (v, first) in first_corners(mesh, n).into_iter().enumerate() {
        let mut shift = [0.0f64; 2];
        let mut overlapping = false;
        for w in fan(mesh, first) {
            let r = [0, 1].map(|a| minimum_image(x[2 * w + a] - x[2 * v + a], l[a]));
            let len = r[0].hypot(r[1]);
            if len < limit && len > 0.0 {
                for a in 0..2 {
                    shift[a] -= delta * (sigma - len) / len * r[a];
                }
                count += (w > v) as u32;
                overlapping = true;
            }
        }
        disks += overlapping as u32;
        let s = shift[0].hypot(shift[1]);
        let max_step = 0.25 * sigma;
        if s > max_step {
            shift = shift.map(|d| d * max_step / s);
        }
        for a in 0..2 {
            out[2 * v + a] = wrap(x[2 * v + a] + shift[a], l[a]);
        }
    }
    (out, count, disks)
}

impl Node for OverlapCorrectionRound {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let Some(x @ ValueType::Particles { n, .. }) = inputs[0] else {
            unreachable!("port type checked")
        };
        let Some(ValueType::Indices { n: words }) = inputs[1] else {
            unreachable!("port type checked")
        };
        if words as u64 != 2 * MESH_WORDS as u64 * n as u64 {
            return Err(PortError::new(
                "mesh",
                format!(
                    "has {words} words; a triangulation of the torus over {n} points has 2N = {} triangles of {MESH_WORDS} words",
                    2 * n as u64
                ),
            ));
        }
        let Some(ValueType::Indices { n: table }) = inputs[2] else {
            unreachable!("port type checked")
        };
        if n == 0 || table % n != 0 || table / n < 3 {
            return Err(PortError::new(
                "fans",
                format!(
                    "has {table} words; a fan table over {n} points (vertex_fans) has (2 + width) x {n}, width at least 1"
                ),
            ));
        }
        Ok(Signature::outputs(vec![x, ValueType::Indices { n: 2 }]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn check_input(&self, port: usize, data: &HostArray) -> Result<(), RowError> {
        match (port, &data.data) {
            (1, HostData::U32(mesh)) => check_mesh_twins(mesh),
            _ => Ok(()),
        }
    }

    fn checks_input(&self) -> bool {
        true
    }

    // The fans are a cache of the mesh's walk: the reference walks the mesh.
    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let x = &inputs[0].as_ref().expect("required").data;
        let mesh = reference_mesh(&inputs[1]);
        let (out, count, disks) = overlap_round(&mesh, x, self.box_lengths, self.sigma, self.delta);
        outputs[0].data = out;
        outputs[1].data = vec![count as f64, disks as f64];
    }
}

impl GpuKernels for OverlapCorrectionRound {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let x = io.inputs[0].expect("required");
        let mesh = io.inputs[1].expect("required");
        let ValueType::Particles { n, .. } = x.ty else {
            unreachable!()
        };
        let fans = io.inputs[2].expect("required");
        let slots = (mesh.ty.words() / 2) as u32;
        let width = fans.ty.words() as u32 / n - 2;
        let kernel = cx.kernel(
            &KernelSpec::new(
                "overlap_correct",
                cx.shader("disks/overlap.wgsl")?,
                &[
                    Binding::StorageRead,
                    Binding::StorageRead,
                    Binding::StorageRead,
                    Binding::StorageReadWrite,
                    Binding::StorageReadWrite,
                    Binding::Uniform,
                ],
            )
            .entry("correct"),
        )?;
        let words: [u32; 12] = [
            n,
            slots,
            (self.sigma as f32).to_bits(),
            (self.delta as f32).to_bits(),
            (self.box_lengths[0] as f32).to_bits(),
            (self.box_lengths[1] as f32).to_bits(),
            ((0.25 * self.sigma) as f32).to_bits(),
            ((self.sigma - overlap_tolerance(self.sigma, self.box_lengths)) as f32).to_bits(),
            width,
            0,
            0,
            0,
        ];
        let params = cx.uniform("overlap correction round", bytemuck::cast_slice(&words));
        let count = io.outputs[1].buffer;
        Ok(vec![
            cx.fill(count, 2, 0)?,
            cx.dispatch(
                &kernel,
                &[
                    x.buffer,
                    mesh.buffer,
                    fans.buffer,
                    io.outputs[0].buffer,
                    count,
                    &params,
                ],
                cx.grid_1d(n as u64, WG_1D),
            ),
        ])
    }
}

pub fn register(r: &mut Registry) {
    r.add(vertex_fans_kind());
    r.add(overlap_correction_round_kind());
}
