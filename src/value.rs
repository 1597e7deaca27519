//! Typed values that flow along graph edges, and their host-side forms.
//!
//! Every edge carries exactly one [`ValueType`], resolved at plan time. On the GPU a
//! value is one storage buffer of 4-byte words:
//! - particles: N rows of k f32, row-major (an (N,3) NPY array as-is);
//! - real grids: f32, component-major, x fastest: `((c*nz + z)*ny + y)*nx + x`;
//! - complex grids: the same order with interleaved (re, im) f32 pairs;
//! - half-complex grids (the Hermitian half spectrum of a real grid of dims (nx, ny, nz)):
//!   (nx/2 + 1) x ny x nz complex values per component, same order;
//! - frames (a trajectory): F frames of N rows of k f32, frame-major (an (F,N,k) NPY
//!   array as-is);
//! - index arrays: u32;
//! - scalars: one f32.

use std::fmt;

/// The type and shape of a value on an edge.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ValueType {
    /// N particles with k f32 each.
    Particles { n: u32, k: u32 },
    /// A real grid of `comps` components on `dims` = (nx, ny, nz) cells.
    RealGrid { dims: [u32; 3], comps: u32 },
    /// A complex grid of `comps` components on `dims` = (nx, ny, nz) cells.
    ComplexGrid { dims: [u32; 3], comps: u32 },
    /// The spectrum of a real grid of `dims` = (nx, ny, nz) cells, stored as its Hermitian
    /// half: x wave numbers 0..=nx/2 only (the rest are complex conjugates).
    HalfComplexGrid { dims: [u32; 3], comps: u32 },
    /// `frames` snapshots of N particles with k f32 each (a trajectory).
    Frames { frames: u32, n: u32, k: u32 },
    /// N u32 indices.
    Indices { n: u32 },
    /// One f32.
    Scalar,
}

/// The machine type of one stored word.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Elem {
    F32,
    U32,
}

impl ValueType {
    /// Number of 4-byte words the value occupies.
    pub fn words(&self) -> u64 {
        match *self {
            ValueType::Particles { n, k } => n as u64 * k as u64,
            ValueType::RealGrid { dims, comps } => cells(dims) * comps as u64,
            ValueType::ComplexGrid { dims, comps } => 2 * cells(dims) * comps as u64,
            ValueType::HalfComplexGrid { dims, comps } => 2 * cells(half_dims(dims)) * comps as u64,
            ValueType::Frames { frames, n, k } => frames as u64 * n as u64 * k as u64,
            ValueType::Indices { n } => n as u64,
            ValueType::Scalar => 1,
        }
    }

    pub fn bytes(&self) -> u64 {
        4 * self.words()
    }

    pub fn elem(&self) -> Elem {
        match self {
            ValueType::Indices { .. } => Elem::U32,
            _ => Elem::F32,
        }
    }

    /// The family name used in graph files (`"particles"`, `"real_grid"`, ...).
    pub fn family(&self) -> &'static str {
        match self {
            ValueType::Particles { .. } => "particles",
            ValueType::RealGrid { .. } => "real_grid",
            ValueType::ComplexGrid { .. } => "complex_grid",
            ValueType::HalfComplexGrid { .. } => "half_complex_grid",
            ValueType::Frames { .. } => "frames",
            ValueType::Indices { .. } => "indices",
            ValueType::Scalar => "scalar",
        }
    }

    /// The component an element (4-byte word index) belongs to: the column of a particle
    /// array, the component of a real grid, 0 otherwise. Element-wise kernels use the same
    /// rule.
    pub fn component_of(&self, idx: u64) -> u32 {
        match *self {
            ValueType::Particles { k, .. } | ValueType::Frames { k, .. } => {
                (idx % k.max(1) as u64) as u32
            }
            ValueType::RealGrid { dims, .. } => (idx / cells(dims).max(1)) as u32,
            _ => 0,
        }
    }

    /// The NPY shape this value is read from and written to.
    pub fn npy_shape(&self) -> Vec<u64> {
        match *self {
            ValueType::Particles { n, k } => vec![n as u64, k as u64],
            ValueType::RealGrid { dims, comps } => {
                vec![comps as u64, dims[2] as u64, dims[1] as u64, dims[0] as u64]
            }
            ValueType::ComplexGrid { dims, comps } => vec![
                comps as u64,
                dims[2] as u64,
                dims[1] as u64,
                dims[0] as u64,
                2,
            ],
            ValueType::HalfComplexGrid { dims, comps } => vec![
                comps as u64,
                dims[2] as u64,
                dims[1] as u64,
                half_dims(dims)[0] as u64,
                2,
            ],
            ValueType::Frames { frames, n, k } => vec![frames as u64, n as u64, k as u64],
            ValueType::Indices { n } => vec![n as u64],
            ValueType::Scalar => vec![],
        }
    }
}

fn cells(d: [u32; 3]) -> u64 {
    d[0] as u64 * d[1] as u64 * d[2] as u64
}

/// Stored dims of the half spectrum of a real grid: (nx/2 + 1, ny, nz).
pub fn half_dims(d: [u32; 3]) -> [u32; 3] {
    [d[0] / 2 + 1, d[1], d[2]]
}

impl fmt::Display for ValueType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            ValueType::Particles { n, k } => write!(f, "particles({n}x{k})"),
            ValueType::RealGrid { dims, comps } => {
                write!(
                    f,
                    "real_grid({}x{}x{}, {comps} comp)",
                    dims[0], dims[1], dims[2]
                )
            }
            ValueType::ComplexGrid { dims, comps } => {
                write!(
                    f,
                    "complex_grid({}x{}x{}, {comps} comp)",
                    dims[0], dims[1], dims[2]
                )
            }
            ValueType::HalfComplexGrid { dims, comps } => write!(
                f,
                "half_complex_grid(of {}x{}x{}, {comps} comp)",
                dims[0], dims[1], dims[2]
            ),
            ValueType::Frames { frames, n, k } => write!(f, "frames({frames}x{n}x{k})"),
            ValueType::Indices { n } => write!(f, "indices({n})"),
            ValueType::Scalar => write!(f, "scalar"),
        }
    }
}

/// What a port accepts: a pattern over [`ValueType`]s, shown by `mesoflow nodes`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PortType {
    /// Particles with exactly `k` columns, or any column count when `None`.
    Particles(Option<u32>),
    RealGrid,
    ComplexGrid,
    HalfComplexGrid,
    Indices,
    Scalar,
    /// Any f32 value that is not a complex grid: particles, real grid or scalar.
    RealArray,
    /// Rows: particles (N x k) or indices (N).
    Rows,
    /// A [`PortType::RealArray`] value or an index array: any array of real words
    /// (f32 or u32), for nodes that treat values as flat sequences (scan).
    RealOrIndices,
    /// A spectrum: a complex grid or a half complex grid.
    Spectrum,
    /// Any f32 value, spectra included: for real-linear element-wise operations (sums,
    /// real factors), which act on the real and imaginary parts alike.
    Linear,
    /// A trajectory: frames of particles.
    Frames,
}

impl PortType {
    pub fn accepts(&self, t: &ValueType) -> bool {
        match (self, t) {
            (PortType::Particles(None), ValueType::Particles { .. }) => true,
            (PortType::Particles(Some(k)), ValueType::Particles { k: kk, .. }) => k == kk,
            (PortType::RealGrid, ValueType::RealGrid { .. }) => true,
            (PortType::ComplexGrid, ValueType::ComplexGrid { .. }) => true,
            (PortType::HalfComplexGrid, ValueType::HalfComplexGrid { .. }) => true,
            (PortType::Indices, ValueType::Indices { .. }) => true,
            (PortType::Frames, ValueType::Frames { .. }) => true,
            (PortType::Scalar, ValueType::Scalar) => true,
            (
                PortType::RealArray,
                ValueType::Particles { .. } | ValueType::RealGrid { .. } | ValueType::Scalar,
            ) => true,
            (PortType::Rows, ValueType::Particles { .. } | ValueType::Indices { .. }) => true,
            (
                PortType::RealOrIndices,
                ValueType::Particles { .. }
                | ValueType::RealGrid { .. }
                | ValueType::Scalar
                | ValueType::Indices { .. },
            ) => true,
            (
                PortType::Spectrum,
                ValueType::ComplexGrid { .. } | ValueType::HalfComplexGrid { .. },
            ) => true,
            (
                PortType::Linear,
                ValueType::Particles { .. }
                | ValueType::RealGrid { .. }
                | ValueType::Scalar
                | ValueType::ComplexGrid { .. }
                | ValueType::HalfComplexGrid { .. },
            ) => true,
            _ => false,
        }
    }
}

impl fmt::Display for PortType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PortType::Particles(None) => write!(f, "particles(N x k)"),
            PortType::Particles(Some(k)) => write!(f, "particles(N x {k})"),
            PortType::RealGrid => write!(f, "real_grid"),
            PortType::ComplexGrid => write!(f, "complex_grid"),
            PortType::HalfComplexGrid => write!(f, "half_complex_grid"),
            PortType::Indices => write!(f, "indices"),
            PortType::Scalar => write!(f, "scalar"),
            PortType::RealArray => write!(f, "particles | real_grid | scalar"),
            PortType::Rows => write!(f, "particles | indices"),
            PortType::RealOrIndices => write!(f, "indices | particles | real_grid | scalar"),
            PortType::Spectrum => write!(f, "complex_grid | half_complex_grid"),
            PortType::Linear => write!(
                f,
                "particles | real_grid | scalar | complex_grid | half_complex_grid"
            ),
            PortType::Frames => write!(f, "frames(F x N x k)"),
        }
    }
}

/// Host-side data of a value as it lives on the GPU (f32 or u32 words).
#[derive(Clone, Debug, PartialEq)]
pub enum HostData {
    F32(Vec<f32>),
    U32(Vec<u32>),
}

/// Host data borrowed (from a caller's array: Python's numpy), for uploads that need not
/// own it.
#[derive(Clone, Copy, Debug)]
pub enum HostWords<'a> {
    F32(&'a [f32]),
    U32(&'a [u32]),
}

impl HostWords<'_> {
    pub fn len(&self) -> usize {
        match self {
            HostWords::F32(v) => v.len(),
            HostWords::U32(v) => v.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn elem(&self) -> Elem {
        match self {
            HostWords::F32(_) => Elem::F32,
            HostWords::U32(_) => Elem::U32,
        }
    }

    pub fn as_bytes(&self) -> &[u8] {
        match self {
            HostWords::F32(v) => bytemuck::cast_slice(v),
            HostWords::U32(v) => bytemuck::cast_slice(v),
        }
    }

    /// An owned copy, typed `ty`.
    pub fn to_array(&self, ty: ValueType) -> HostArray {
        match self {
            HostWords::F32(v) => HostArray::f32(ty, v.to_vec()),
            HostWords::U32(v) => HostArray::u32(ty, v.to_vec()),
        }
    }

    /// Whether every word is finite (index words always are).
    pub fn all_finite(&self) -> bool {
        match self {
            HostWords::F32(v) => all_finite(v),
            HostWords::U32(_) => true,
        }
    }
}

/// Whether no word is NaN or infinite: an exponent-bits test without branches, which the
/// compiler vectorises (a fast pass before any search for where).
pub fn all_finite(v: &[f32]) -> bool {
    v.chunks(1024).all(|chunk| {
        chunk.iter().fold(0u32, |acc, x| {
            acc | u32::from(x.to_bits() & 0x7f80_0000 == 0x7f80_0000)
        }) == 0
    })
}

impl HostData {
    pub fn len(&self) -> usize {
        match self {
            HostData::F32(v) => v.len(),
            HostData::U32(v) => v.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn as_bytes(&self) -> &[u8] {
        match self {
            HostData::F32(v) => bytemuck::cast_slice(v),
            HostData::U32(v) => bytemuck::cast_slice(v),
        }
    }

    /// The words widened to f64 (u32 values are exact in f64).
    pub fn to_f64(&self) -> Vec<f64> {
        match self {
            HostData::F32(v) => v.iter().map(|&x| x as f64).collect(),
            HostData::U32(v) => v.iter().map(|&x| x as f64).collect(),
        }
    }
}

/// A value on the host, typed.
#[derive(Clone, Debug, PartialEq)]
pub struct HostArray {
    pub ty: ValueType,
    pub data: HostData,
}

impl HostArray {
    pub fn f32(ty: ValueType, data: Vec<f32>) -> Self {
        debug_assert_eq!(ty.words() as usize, data.len());
        HostArray {
            ty,
            data: HostData::F32(data),
        }
    }

    pub fn u32(ty: ValueType, data: Vec<u32>) -> Self {
        debug_assert_eq!(ty.words() as usize, data.len());
        HostArray {
            ty,
            data: HostData::U32(data),
        }
    }

    /// Rebuilds a typed array from raw little-endian words read back from the GPU.
    pub fn from_bytes(ty: ValueType, bytes: &[u8]) -> Self {
        let words = ty.words() as usize;
        let bytes = &bytes[..4 * words];
        match ty.elem() {
            Elem::F32 => HostArray::f32(ty, bytemuck::pod_collect_to_vec(bytes)),
            Elem::U32 => HostArray::u32(ty, bytemuck::pod_collect_to_vec(bytes)),
        }
    }

    /// Where the array holds NaN or infinite words, if anywhere (f32 arrays only: index
    /// words are always finite).
    pub fn non_finite(&self) -> Option<NonFinite> {
        let HostData::F32(v) = &self.data else {
            return None;
        };
        if all_finite(v) {
            return None;
        }
        let mut found: Option<NonFinite> = None;
        for (i, &x) in v.iter().enumerate() {
            if x.is_finite() {
                continue;
            }
            let f = found.get_or_insert(NonFinite {
                nan: 0,
                infinite: 0,
                first: i,
                first_value: x,
                len: v.len(),
            });
            if x.is_nan() {
                f.nan += 1;
            } else {
                f.infinite += 1;
            }
        }
        found
    }

    /// The same value widened to f64, as CPU references take it.
    pub fn to_ref(&self) -> RefArray {
        RefArray {
            ty: self.ty,
            data: self.data.to_f64(),
        }
    }
}

/// The NaN and infinite words of one f32 array: how many of each, and the first.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NonFinite {
    pub nan: usize,
    pub infinite: usize,
    /// Index of the first, in the array's words (row-major, as in its NPY file).
    pub first: usize,
    pub first_value: f32,
    /// Words in the array.
    pub len: usize,
}

impl fmt::Display for NonFinite {
    /// "3 NaN and 1 infinite of 30 values, the first at index 4 (NaN)".
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let counts = match (self.nan, self.infinite) {
            (n, 0) => format!("{n} NaN"),
            (0, i) => format!("{i} infinite"),
            (n, i) => format!("{n} NaN and {i} infinite"),
        };
        write!(
            f,
            "{counts} of {} values, the first at index {} ({})",
            self.len, self.first, self.first_value
        )
    }
}

/// A value in f64 for CPU references: index arrays are stored exactly as f64.
#[derive(Clone, Debug, PartialEq)]
pub struct RefArray {
    pub ty: ValueType,
    pub data: Vec<f64>,
}

impl RefArray {
    pub fn new(ty: ValueType, data: Vec<f64>) -> Self {
        debug_assert_eq!(ty.words() as usize, data.len());
        RefArray { ty, data }
    }

    /// Rounds to the GPU's word type (f32, or u32 for index arrays).
    pub fn to_host(&self) -> HostArray {
        match self.ty.elem() {
            Elem::F32 => HostArray::f32(self.ty, self.data.iter().map(|&x| x as f32).collect()),
            Elem::U32 => HostArray::u32(self.ty, self.data.iter().map(|&x| x as u32).collect()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_and_shapes() {
        let p = ValueType::Particles { n: 10, k: 3 };
        assert_eq!(p.words(), 30);
        assert_eq!(p.npy_shape(), vec![10, 3]);
        let c = ValueType::ComplexGrid {
            dims: [4, 5, 6],
            comps: 3,
        };
        assert_eq!(c.words(), 2 * 120 * 3);
        assert_eq!(c.npy_shape(), vec![3, 6, 5, 4, 2]);
        let h = ValueType::HalfComplexGrid {
            dims: [9, 5, 6],
            comps: 3,
        };
        assert_eq!(h.words(), 2 * 5 * 5 * 6 * 3);
        assert_eq!(h.npy_shape(), vec![3, 6, 5, 5, 2]);
        assert_eq!(ValueType::Scalar.npy_shape(), Vec::<u64>::new());
    }

    #[test]
    fn port_patterns() {
        let p3 = ValueType::Particles { n: 7, k: 3 };
        assert!(PortType::Particles(Some(3)).accepts(&p3));
        assert!(!PortType::Particles(Some(1)).accepts(&p3));
        assert!(PortType::RealArray.accepts(&ValueType::Scalar));
        assert!(!PortType::RealArray.accepts(&ValueType::Indices { n: 3 }));
        assert!(PortType::RealOrIndices.accepts(&ValueType::Indices { n: 3 }));
        assert!(!PortType::RealOrIndices.accepts(&ValueType::ComplexGrid {
            dims: [2, 2, 2],
            comps: 1
        }));
    }
}
