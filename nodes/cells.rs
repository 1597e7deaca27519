//! Cells of a box: particle positions to cell indices (linear or Morton order), and
//! histograms of indices. With `bin_sort` (nodes/bin_sort.rs: perm, sorted keys, count
//! and first particle of every cell in one node) these make cell lists:
//! graphs/lib/cell_list.json; `sort` -> histogram -> exclusive scan does the same with
//! a stable order inside each cell.

use crate::expr::ParamValue;
use crate::gpu::DeviceCaps;
use crate::gpu::{Binding, CompileCtx, CompileError, Dispatch, KernelSpec, NodeIo, WG_1D};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamKind, ParamSpec, PortError, PortSpec, RefCtx,
    Registry, Signature,
};
use crate::value::{PortType, RefArray, ValueType};

fn cell_hash_kind() -> NodeKind {
    NodeKind::declare(
        "cell_hash",
        "cell index of each particle in a box centred at the origin (linear or Morton order; periodic wrap)",
    )
    .input(PortSpec::new(
        "positions",
        PortType::Particles(None),
        "positions (N x 2 or N x 3)",
    ))
    .output(PortSpec::new(
        "out",
        PortType::Indices,
        "cell index per particle",
    ))
    .param(ParamSpec {
        name: "box",
        kind: ParamKind::Numbers {
            len: None,
            min: f64::MIN_POSITIVE,
            max: f64::MAX,
        },
        default: None,
        doc: "box lengths per axis (2 or 3 values)",
    })
    .param(ParamSpec {
        name: "cells",
        kind: ParamKind::Numbers {
            len: None,
            min: 1.0,
            max: u32::MAX as f64,
        },
        default: None,
        doc: "cells per axis (cells may be non-cubic: size box/cells per axis)",
    })
    .param(ParamSpec::choice(
        "order",
        "linear",
        &["linear", "morton"],
        "cell numbering",
    ))
    .param(ParamSpec {
        name: "periodic",
        kind: ParamKind::Numbers {
            len: None,
            min: 0.0,
            max: 1.0,
        },
        default: Some(ParamValue::Numbers(vec![1.0, 1.0, 1.0])),
        doc: "1 for a periodic axis (wrapped), 0 for a walled one (clamped to the edge cells)",
    })
    .build(|p| {
        let lengths = p.numbers("box").to_vec();
        let cells = p.numbers("cells").to_vec();
        let dims = lengths.len();
        if !(2..=3).contains(&dims) || cells.len() != dims {
            return Err(format!(
                "`box` and `cells` need 2 or 3 values each, got {} and {}",
                dims,
                cells.len()
            ));
        }
        if cells.iter().any(|c| c.fract() != 0.0) {
            return Err(format!("`cells` must be whole numbers, got {cells:?}"));
        }
        let morton = p.text("order") == "morton";
        let limit = if dims == 3 { 1024.0 } else { 65536.0 };
        if morton && cells.iter().any(|&c| c > limit) {
            return Err(format!(
                "Morton order supports at most {limit} cells per axis in {dims}D, got {cells:?}"
            ));
        }
        if !morton && cells.iter().product::<f64>() > u32::MAX as f64 {
            return Err(format!(
                "{} cells do not fit u32 indices",
                cells.iter().product::<f64>()
            ));
        }
        let mut periodic: Vec<bool> = p.numbers("periodic").iter().map(|&x| x == 1.0).collect();
        periodic.resize(dims, true);
        Ok(Box::new(CellHash {
            lengths,
            cells: cells.iter().map(|&c| c as u32).collect(),
            morton,
            periodic,
        }))
    })
}

struct CellHash {
    lengths: Vec<f64>,
    cells: Vec<u32>,
    morton: bool,
    periodic: Vec<bool>,
}

fn spread(v: u32, dims: usize) -> u64 {
    let bits = if dims == 3 { 10 } else { 16 };
    (0..bits)
        .map(|b| (((v >> b) & 1) as u64) << (b * dims))
        .sum()
}

/// The Morton key `cell_hash` gives the cell of integer coordinates `i` (2 or 3 axes):
/// their bits interleaved, x lowest. Increasing in each coordinate, so the last cell of a
/// grid has the largest key: `morton(&[cx - 1, cy - 1, cz - 1]) + 1` bins hold them all.
pub fn morton(i: &[u32]) -> u64 {
    let dims = i.len();
    (0..dims).map(|a| spread(i[a], dims) << a).sum()
}

impl CellHash {
    /// Reference cell along one axis, in f64.
    fn axis_cell(&self, x: f64, a: usize) -> u32 {
        let n = self.cells[a] as i64;
        let i = (x * n as f64 / self.lengths[a] + n as f64 / 2.0).floor() as i64;
        if self.periodic[a] {
            i.rem_euclid(n) as u32
        } else {
            i.clamp(0, n - 1) as u32
        }
    }

    /// Reference key of one particle.
    pub fn key(&self, pos: &[f64]) -> u32 {
        let dims = self.cells.len();
        let i: Vec<u32> = (0..dims).map(|a| self.axis_cell(pos[a], a)).collect();
        if self.morton {
            morton(&i) as u32
        } else {
            let mut k = 0u64;
            for a in (0..dims).rev() {
                k = k * self.cells[a] as u64 + i[a] as u64;
            }
            k as u32
        }
    }
}

impl Node for CellHash {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let Some(ValueType::Particles { n, k }) = inputs[0] else {
            unreachable!("port type checked")
        };
        if k as usize != self.cells.len() {
            return Err(PortError::new(
                "positions",
                format!("has {k} columns but the box has {} axes", self.cells.len()),
            ));
        }
        Ok(Signature::outputs(vec![ValueType::Indices { n }]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn notes(&self, _: &[Option<ValueType>]) -> Vec<String> {
        let size: Vec<String> = (0..self.cells.len())
            .map(|a| format!("{:.6}", self.lengths[a] / self.cells[a] as f64))
            .collect();
        vec![format!(
            "{:?} cells of size ({}), {} order",
            self.cells,
            size.join(", "),
            if self.morton { "Morton" } else { "linear" }
        )]
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let pos = &inputs[0].as_ref().expect("required").data;
        let dims = self.cells.len();
        for (p, out) in outputs[0].data.iter_mut().enumerate() {
            *out = self.key(&pos[p * dims..(p + 1) * dims]) as f64;
        }
    }
}

/// Layout of the `Grid` uniform of shaders/cells/hash.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct GridUniform {
    scale: [f32; 4],
    half: [f32; 4],
    cells: [u32; 4],
    periodic: [u32; 4],
    n: u32,
    pad: [u32; 3],
}

impl GpuKernels for CellHash {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let pos = io.inputs[0].expect("required");
        let ValueType::Particles { n, .. } = pos.ty else {
            unreachable!()
        };
        let dims = self.cells.len();
        let mut u = GridUniform {
            scale: [0.0; 4],
            half: [0.0; 4],
            cells: [1; 4],
            periodic: [1; 4],
            n,
            pad: [0; 3],
        };
        for a in 0..dims {
            // n / L in f64, rounded once to f32.
            u.scale[a] = (self.cells[a] as f64 / self.lengths[a]) as f32;
            u.half[a] = (self.cells[a] as f64 / 2.0) as f32;
            u.cells[a] = self.cells[a];
            u.periodic[a] = u32::from(self.periodic[a]);
        }
        let kernel = cx.kernel(
            &KernelSpec::new(
                "cell_hash",
                cx.shader("cells/hash.wgsl")?,
                &[
                    Binding::StorageRead,
                    Binding::StorageReadWrite,
                    Binding::Uniform,
                ],
            )
            .constant("DIMS", dims as f64)
            .constant("MORTON", f64::from(u8::from(self.morton))),
        )?;
        let grid = cx.uniform("cell grid", bytemuck::bytes_of(&u));
        Ok(vec![cx.dispatch(
            &kernel,
            &[pos.buffer, io.outputs[0].buffer, &grid],
            cx.grid_1d(n as u64, WG_1D),
        )])
    }
}

fn histogram_kind() -> NodeKind {
    NodeKind::declare(
        "histogram",
        "count of each key in [0, bins) (keys past the last bin are not counted)",
    )
    .input(PortSpec::new("keys", PortType::Indices, "keys to count"))
    .output(PortSpec::new("out", PortType::Indices, "count per bin"))
    .param(ParamSpec::integer(
        "bins",
        None,
        1.0,
        u32::MAX as f64,
        "number of bins",
    ))
    .build(|p| {
        Ok(Box::new(Histogram {
            bins: p.number("bins") as u32,
        }))
    })
}

struct Histogram {
    bins: u32,
}

impl Node for Histogram {
    fn infer(&self, _: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        Ok(Signature::outputs(vec![ValueType::Indices {
            n: self.bins,
        }]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        outputs[0].data.fill(0.0);
        for &k in &inputs[0].as_ref().expect("required").data {
            if k < self.bins as f64 {
                outputs[0].data[k as usize] += 1.0;
            }
        }
    }
}

impl GpuKernels for Histogram {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let keys = io.inputs[0].expect("required");
        let ValueType::Indices { n } = keys.ty else {
            unreachable!()
        };
        let kernel = cx.kernel(&KernelSpec::new(
            "histogram",
            cx.shader("cells/histogram.wgsl")?,
            &[
                Binding::StorageRead,
                Binding::StorageReadWrite,
                Binding::Uniform,
            ],
        ))?;
        let shape = cx.uniform("histogram shape", bytemuck::cast_slice(&[n, self.bins]));
        let out = io.outputs[0].buffer;
        Ok(vec![
            cx.fill(out, self.bins as u64, 0)?,
            cx.dispatch(
                &kernel,
                &[keys.buffer, out, &shape],
                cx.grid_1d(n as u64, WG_1D),
            ),
        ])
    }
}

pub fn register(r: &mut Registry) {
    r.add(cell_hash_kind());
    r.add(histogram_kind());
}
