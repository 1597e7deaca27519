//! Lawson edge flips on the torus mesh (`mesh.rs` layout), one parallel round per
//! evaluation, with the inverted-triangle repair in the same rounds (S1 sections 4.1 and
//! 4.3; Navarro, Hitschfeld and Scheihing 2014 for the GPU flips).
//!
//! **Predicate** (`shaders/disks/predicate.wgsl`, twin [`flip_code`]): for the edge b -> c
//! of the counter-clockwise triangle (a, b, c) with d across it, FOLDED when a lies in the
//! closed triangle (b, c, d) or d in (c, b, a) (S1 eq. 8, both orientations: a vertex
//! crossed the edge), ILLEGAL when all four triangles before and after the flip are
//! positively oriented and d lies inside the circumcircle of (a, b, c) by more than
//! `tolerance` m^2 (the in-circle determinant relative to d; m the largest squared
//! distance from d to a, b, c; the f32 determinant's round-off is about 1e-6 m^2, so the
//! default 1e-5 keeps the GPU's and the f64 decisions equal outside a band that thin:
//! quads closer to cocircular keep their edge, the paper's quasi-Delaunay), KEEP
//! otherwise. Flipping b -> c to a -> d repairs either case.
//!
//! **A round** (`edge_flip_round`, `shaders/disks/flip.wgsl`): every edge that needs a
//! flip claims, by `atomicMin` of its slot, the four triangles whose words its flip
//! writes: its own two (all six words each) and the owners of its outer edges c -> a and
//! b -> d (one twin word each, pointing to the slot the edge moved to). An edge that holds
//! all four claims flips, reading only the input mesh and writing only the output. The
//! flip pass runs one thread per triangle, not per slot: a winner holds the claim of its
//! own triangle, so the slot a triangle's claim names, when it lies in that triangle, is
//! the only edge there that may have won, and it is a candidate (only candidates claim):
//! the pass checks its other three claims without evaluating the predicate again. The
//! claim pass runs one thread per triangle too, for its three edges: the triangle's words
//! and its vertices' positions are read once.
//!
//! **Rounds per evaluation** (`rounds`, default 4): the output is copied from the input
//! once and the rounds flip in place on it; the output is declared in place of the
//! input (`PortSpec::in_place_of`), so where the plan gives both one buffer (the flip
//! loops: the mesh the loop carries, read by nothing after the node) there is no copy.
//! In place is safe: a winner reads and writes only triangles whose claims it holds, and
//! the flip pass reads a triangle's words only after seeing its claim held by the edge
//! it checks, so no thread reads a word another writes in the same pass. Nothing is reset between rounds: a claim is its slot below
//! its round's tag (later rounds win over earlier claims, which the flip pass ignores), a
//! mark its round's number, in two arrays taken in turn. Only the first round looks at
//! every edge (one thread per triangle); every candidate (and every edge left out as degenerate) marks its two
//! triangles, and the next round evaluates just the edges of the marked triangles, each
//! by its smaller slot as before. That set holds every candidate of a full round: an
//! edge's candidacy depends on its two triangles' words and the positions; the words a
//! round changes are its winners' two triangles (marked) and one twin word in each of
//! two outer triangles, which changes an unmarked edge's outer owners only: an edge the
//! predicate kept still keeps (its quad is the same), and a degenerate one was marked.
//! So `rounds` rounds here give the mesh and the count of as many single rounds
//! ([`flip_rounds`], the f64 twin), while the later rounds cost a pass over a word per
//! triangle: the Lawson cascade after a move (most flips in round 1, then a few next to
//! them) takes one or two evaluations, so fewer iterations of the loop that repeats it. Two
//! winners therefore write disjoint triangles, and an outer edge that neither moves keeps
//! its slot, so the twins it points to stay right. The lowest candidate always wins: a
//! round with candidates flips at least one edge, and the winners follow a fixed rule (the
//! same mesh every run). The counts of flips made, in all rounds and in the last one (two
//! u32), tell a loop when to stop: none in the last round means none is needed, so a loop
//! that stops on that word (`repeat`'s `stop_word` 1) spends no evaluation confirming it.

use super::mesh::{MESH_WORDS, orient};
use super::minimum_image;
use crate::gpu::DeviceCaps;
use crate::gpu::{Binding, CompileCtx, CompileError, Dispatch, KernelSpec, NodeIo, WG_1D};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamKind, ParamSpec, PortError, PortSpec, RefCtx,
    Registry, RowError, Signature,
};
use crate::value::{HostArray, HostData, PortType, RefArray, ValueType};

/// The flip decision for an edge.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlipCode {
    Keep = 0,
    Illegal = 1,
    Folded = 2,
}

/// S1 eq. 8: v3 in the closed triangle (v1, v2, v4), by the signs of its barycentric
/// coordinates.
fn in_closed_triangle(v1: [f64; 2], v2: [f64; 2], v3: [f64; 2], v4: [f64; 2]) -> bool {
    let cross = |p: [f64; 2], q: [f64; 2]| p[0] * q[1] - p[1] * q[0];
    let e0 = [v2[0] - v1[0], v2[1] - v1[1]];
    let e1 = [v3[0] - v1[0], v3[1] - v1[1]];
    let e2 = [v4[0] - v1[0], v4[1] - v1[1]];
    let (d2, s2, t2) = (cross(e2, e0), cross(e1, e0), cross(e2, e1));
    if d2 < 0.0 {
        s2 <= 0.0 && t2 <= 0.0 && s2 + t2 >= d2
    } else {
        s2 >= 0.0 && t2 >= 0.0 && s2 + t2 <= d2
    }
}

/// The f64 twin of `flip_code` in `shaders/disks/predicate.wgsl`: a, b, c relative to d.
pub fn flip_code(a: [f64; 2], b: [f64; 2], c: [f64; 2], tolerance: f64) -> FlipCode {
    let d = [0.0, 0.0];
    if in_closed_triangle(b, c, a, d) || in_closed_triangle(c, b, d, a) {
        return FlipCode::Folded;
    }
    let positive = orient(a, b, c) > 0.0
        && orient(d, c, b) > 0.0
        && orient(a, b, d) > 0.0
        && orient(d, c, a) > 0.0;
    let sq = |p: [f64; 2]| p[0] * p[0] + p[1] * p[1];
    let m = sq(a).max(sq(b)).max(sq(c));
    if positive && super::mesh::in_circle(a, b, c, d) > tolerance * m * m {
        FlipCode::Illegal
    } else {
        FlipCode::Keep
    }
}

fn tolerance_param() -> ParamSpec {
    ParamSpec::number(
        "tolerance",
        Some(1e-5),
        1e-6,
        0.1,
        "an edge is illegal when the in-circle determinant exceeds tolerance x m^2 (m the largest squared distance from the far vertex); the f32 determinant is good to about 1e-6 m^2",
    )
}

fn flip_predicate_kind() -> NodeKind {
    NodeKind::declare(
        "flip_predicate",
        "the edge-flip predicate of the disk mesh for quads given as rows (a, b, c, d) (N x 8; the edge b -> c of the counter-clockwise triangle (a, b, c), d across it): 0 keep, 1 illegal (d inside the circumcircle), 2 folded (S1 eq. 8)",
    )
    .input(PortSpec::new(
        "quads",
        PortType::Particles(Some(8)),
        "ax, ay, bx, by, cx, cy, dx, dy per quad",
    ))
    .output(PortSpec::new("codes", PortType::Indices, "the code of each quad"))
    .param(tolerance_param())
    .build(|p| {
        Ok(Box::new(FlipPredicate {
            tolerance: p.number("tolerance"),
        }))
    })
}

struct FlipPredicate {
    tolerance: f64,
}

impl Node for FlipPredicate {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let Some(ValueType::Particles { n, .. }) = inputs[0] else {
            unreachable!("port type checked")
        };
        Ok(Signature::outputs(vec![ValueType::Indices { n }]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let q = &inputs[0].as_ref().expect("required").data;
        for (i, r) in q.chunks(8).enumerate() {
            let rel = |j: usize| [r[2 * j] - r[6], r[2 * j + 1] - r[7]];
            outputs[0].data[i] = flip_code(rel(0), rel(1), rel(2), self.tolerance) as u32 as f64;
        }
    }
}

impl GpuKernels for FlipPredicate {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let q = io.inputs[0].expect("required");
        let ValueType::Particles { n, .. } = q.ty else {
            unreachable!()
        };
        let kernel = cx.kernel(&KernelSpec::new(
            "flip_predicate",
            cx.shader("disks/flip_predicate.wgsl")?,
            &[
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::Uniform,
            ],
        ))?;
        let words = [n, (self.tolerance as f32).to_bits()];
        let params = cx.uniform("flip predicate", bytemuck::cast_slice(&words));
        Ok(vec![cx.dispatch(
            &kernel,
            &[q.buffer, io.outputs[0].buffer, &params],
            cx.grid_1d(n as u64, WG_1D),
        )])
    }
}

fn edge_flip_round_kind() -> NodeKind {
    NodeKind::declare(
        "edge_flip_round",
        "`rounds` parallel rounds of Lawson flips on the disk mesh (6 u32 per triangle: vertices, twin slots): in each, every folded or illegal edge claims the triangles its flip writes and the edges holding their claims flip; the first round looks at every edge, the later ones at the edges near the round before's candidates only; `flips` counts the flips of all rounds and of the last one (0 in either: the mesh is a valid, quasi-Delaunay triangulation)",
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
    .output(
        PortSpec::new(
            "mesh",
            PortType::Indices,
            "the mesh after the rounds",
        )
        .in_place_of("mesh"),
    )
    .output(PortSpec::new(
        "flips",
        PortType::Indices,
        "the edges flipped in all rounds, then in the last round (2 words): the last round flipping nothing means no edge needs a flip, so a loop may stop on word 1 without another evaluation",
    ))
    .param(tolerance_param())
    .param(ParamSpec::integer(
        "rounds",
        Some(4.0),
        1.0,
        16.0,
        "Lawson rounds per evaluation, in place: the first looks at every edge, each later one only at the edges of the triangles the round before marked (its candidates' and degenerate edges'), which holds every edge that may have turned a candidate: the same mesh as that many single rounds",
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
        Ok(Box::new(EdgeFlipRound {
            tolerance: p.number("tolerance"),
            rounds: p.number("rounds") as u32,
            box_lengths: [b[0], b[1]],
        }))
    })
}

pub struct EdgeFlipRound {
    tolerance: f64,
    rounds: u32,
    box_lengths: [f64; 2],
}

/// The winners' flips of one round, in f64: the twin of `shaders/disks/flip.wgsl`. Returns
/// the new mesh and the number of flips.
pub fn flip_round(mesh: &[u32], x: &[f64], l: [f64; 2], tolerance: f64) -> (Vec<u32>, u32) {
    let tris = mesh.len() / MESH_WORDS;
    let vert = |t: usize, k: usize| mesh[MESH_WORDS * t + k % 3] as usize;
    let twin = |t: usize, k: usize| mesh[MESH_WORDS * t + 3 + k % 3] as usize;
    let candidate = |s: usize| -> Option<[usize; 4]> {
        let (t, k) = (s / 3, s % 3);
        let us = twin(t, k);
        if us <= s || us >= 3 * tris {
            return None;
        }
        let (u, m) = (us / 3, us % 3);
        let (a, d) = (vert(t, k), vert(u, m));
        let (xb, xc) = (twin(t, k + 1) / 3, twin(t, k + 2) / 3);
        let (yc, yb) = (twin(u, m + 1) / 3, twin(u, m + 2) / 3);
        if a == d || xb == u || xc == u || yc == t || yb == t || t == u {
            return None;
        }
        let rel = |w: usize| [0, 1].map(|i| minimum_image(x[2 * w + i] - x[2 * d + i], l[i]));
        let code = flip_code(rel(a), rel(vert(t, k + 1)), rel(vert(t, k + 2)), tolerance);
        (code != FlipCode::Keep).then_some([t, u, xb, yc])
    };
    let candidates: Vec<(usize, [usize; 4])> = (0..3 * tris)
        .filter_map(|s| candidate(s).map(|c| (s, c)))
        .collect();
    let mut claims = vec![usize::MAX; tris];
    for (s, c) in &candidates {
        for &t in c {
            claims[t] = claims[t].min(*s);
        }
    }
    let mut out = mesh.to_vec();
    let mut flips = 0;
    for (s, four) in candidates {
        if four.iter().any(|&w| claims[w] != s) {
            continue;
        }
        let [t, u, _, _] = four;
        let k = s % 3;
        let m = twin(t, k) % 3;
        let (a, d) = (vert(t, k), vert(u, m));
        let (x_b, x_c) = (twin(t, k + 1), twin(t, k + 2));
        let (y_c, y_b) = (twin(u, m + 1), twin(u, m + 2));
        let (k1, k2, m1, m2) = ((k + 1) % 3, (k + 2) % 3, (m + 1) % 3, (m + 2) % 3);
        let w = |t: usize, j: usize| MESH_WORDS * t + j;
        out[w(t, k2)] = d as u32;
        out[w(t, 3 + k)] = y_c as u32;
        out[w(t, 3 + k1)] = (3 * u + m1) as u32;
        out[w(t, 3 + k2)] = x_c as u32;
        out[w(u, m2)] = a as u32;
        out[w(u, 3 + m)] = x_b as u32;
        out[w(u, 3 + m1)] = (3 * t + k1) as u32;
        out[w(u, 3 + m2)] = y_b as u32;
        out[w(y_c / 3, 3 + y_c % 3)] = (3 * t + k) as u32;
        out[w(x_b / 3, 3 + x_b % 3)] = (3 * u + m) as u32;
        flips += 1;
    }
    (out, flips)
}

/// `rounds` rounds of [`flip_round`] (fewer once one flips nothing: the rest would not
/// change the mesh): the twin of an `edge_flip_round` evaluation. Returns the mesh, the
/// flips of all rounds and those of the last round (0 where one flipped nothing).
pub fn flip_rounds(
    mesh: &[u32],
    x: &[f64],
    l: [f64; 2],
    tolerance: f64,
    rounds: u32,
) -> (Vec<u32>, u32, u32) {
    let (mut out, mut total, mut last) = (mesh.to_vec(), 0, 0);
    for _ in 0..rounds {
        let (next, flips) = flip_round(&out, x, l, tolerance);
        out = next;
        total += flips;
        last = flips;
        if flips == 0 {
            break;
        }
    }
    (out, total, last)
}

/// A mesh input of a CPU reference (f64 words) as the u32 words the kernels read.
pub(crate) fn reference_mesh(input: &Option<RefArray>) -> Vec<u32> {
    input
        .as_ref()
        .expect("required")
        .data
        .iter()
        .map(|&v| v as u32)
        .collect()
}

/// The twins of a mesh given from the host: in range, pointing back, the same edge
/// reversed. The first triangle that breaks a rule is refused.
pub fn check_mesh_twins(mesh: &[u32]) -> Result<(), RowError> {
    let slots = mesh.len() / MESH_WORDS * 3;
    let vert = |s: usize| mesh[MESH_WORDS * (s / 3) + s % 3];
    let twin = |s: usize| mesh[MESH_WORDS * (s / 3) + 3 + s % 3] as usize;
    let ends = |s: usize| {
        (
            vert(3 * (s / 3) + (s + 1) % 3),
            vert(3 * (s / 3) + (s + 2) % 3),
        )
    };
    for s in 0..slots {
        let u = twin(s);
        if u >= slots {
            return Err(RowError::new(
                s / 3,
                format!("twin slot {u} is past the last slot {}", slots - 1),
            ));
        }
        let (p, q) = ends(s);
        if twin(u) != s || ends(u) != (q, p) {
            return Err(RowError::new(
                s / 3,
                format!(
                    "slot {s} (edge {p} -> {q}) has twin {u} (edge {} -> {}, twin {}): not the same edge reversed, pointing back",
                    ends(u).0,
                    ends(u).1,
                    twin(u)
                ),
            ));
        }
    }
    Ok(())
}

impl Node for EdgeFlipRound {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let Some(ValueType::Particles { n, .. }) = inputs[0] else {
            unreachable!("port type checked")
        };
        let Some(mesh @ ValueType::Indices { n: words }) = inputs[1] else {
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
        let tris = words as u64 / MESH_WORDS as u64;
        // A claim holds its slot in 27 bits below its round's tag.
        if 3 * tris >= 1 << 27 {
            return Err(PortError::new(
                "mesh",
                format!(
                    "has {} slots; edge_flip_round's claims hold slots below 2^27 (N below 22369621)",
                    3 * tris
                ),
            ));
        }
        // The claims and the marks of two rounds, a word per triangle each.
        Ok(Signature::outputs(vec![mesh, ValueType::Indices { n: 2 }])
            .with_scratch(vec![4 * tris; 3]))
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

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let x = &inputs[0].as_ref().expect("required").data;
        let mesh = reference_mesh(&inputs[1]);
        let (out, flips, last) =
            flip_rounds(&mesh, x, self.box_lengths, self.tolerance, self.rounds);
        outputs[0].data = out.iter().map(|&v| v as f64).collect();
        outputs[1].data = vec![flips as f64, last as f64];
    }
}

impl GpuKernels for EdgeFlipRound {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let x = io.inputs[0].expect("required");
        let mesh = io.inputs[1].expect("required");
        let slots = (mesh.ty.words() / 2) as u32;
        let source = cx.shader("disks/flip.wgsl")?;
        let triangles = slots / 3;
        let prepare = cx.kernel(&KernelSpec::new(
            "edge_flip_prepare",
            cx.shader("disks/flip_prepare.wgsl")?,
            &[
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::StorageReadWrite,
                Binding::StorageReadWrite,
                Binding::Uniform,
                Binding::StorageReadWrite,
                Binding::StorageReadWrite,
            ],
        ))?;
        // The mesh's 12N words as 3N 16-byte quads.
        let quads = mesh.ty.words() as u32 / 4;
        let [claims, marks_a, marks_b] = [io.scratch[0], io.scratch[1], io.scratch[2]];
        // In place (the plan gave the output the input's buffer): the mesh is there
        // already, so `prepare` copies nothing, and since wgpu refuses one buffer bound
        // read-only and read-write in a dispatch, the positions stand in for its unread
        // input binding.
        let in_place = io.in_place(0, 1);
        let (quads, copied) = if in_place {
            (0, x.buffer)
        } else {
            (quads, mesh.buffer)
        };
        let prepare_params = cx.uniform(
            "edge flip prepare",
            bytemuck::cast_slice(&[quads, triangles, 0, 0]),
        );
        let mut out = vec![cx.dispatch(
            &prepare,
            &[
                copied,
                io.outputs[0].buffer,
                claims,
                io.outputs[1].buffer,
                &prepare_params,
                marks_a,
                marks_b,
            ],
            cx.grid_1d(quads.max(triangles) as u64, WG_1D),
        )];
        let bindings = [
            Binding::StorageRead,
            Binding::StorageReadWrite,
            Binding::StorageReadWrite,
            Binding::StorageReadWrite,
            Binding::Uniform,
            Binding::StorageRead,
            Binding::StorageReadWrite,
        ];
        let kernel = |cx: &mut CompileCtx<'_>, entry: &str| {
            cx.kernel(
                &KernelSpec::new(format!("edge_flip_{entry}"), source.clone(), &bindings)
                    .entry(entry),
            )
        };
        let (claim, claim_marked, flip) = (
            kernel(cx, "claim")?,
            kernel(cx, "claim_marked")?,
            kernel(cx, "flip")?,
        );
        let grid = cx.grid_1d(triangles as u64, WG_1D);
        for round in 0..self.rounds {
            // Round j marks into one buffer and reads the other's marks (round j - 1's).
            let (marks, marked) = if round % 2 == 0 {
                (marks_a, marks_b)
            } else {
                (marks_b, marks_a)
            };
            let words: [u32; 8] = [
                slots,
                (self.tolerance as f32).to_bits(),
                (self.box_lengths[0] as f32).to_bits(),
                (self.box_lengths[1] as f32).to_bits(),
                round,
                self.rounds - 1 - round,
                0,
                0,
            ];
            let params = cx.uniform("edge flip round", bytemuck::cast_slice(&words));
            let buffers = [
                x.buffer,
                io.outputs[0].buffer,
                claims,
                io.outputs[1].buffer,
                &params,
                marked,
                marks,
            ];
            let first = if round == 0 { &claim } else { &claim_marked };
            out.push(cx.dispatch(first, &buffers, grid));
            out.push(cx.dispatch(&flip, &buffers, grid));
        }
        Ok(out)
    }
}

pub fn register(r: &mut Registry) {
    r.add(flip_predicate_kind());
    r.add(edge_flip_round_kind());
}
