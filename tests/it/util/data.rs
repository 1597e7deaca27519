//! Test data: a seeded generator, random points and keys, arrays built from rows and read
//! back.

use mesoflow::value::{Elem, HostArray, HostData, ValueType};

/// A small deterministic generator for test data (xorshift), so tests need no seed plumbing.
pub struct Rng(u64);

impl Rng {
    /// A generator whose draws depend only on `seed`.
    pub fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        self.0 = x;
        x
    }

    /// Uniform in [lo, hi).
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * ((self.next_u64() >> 11) as f64 / (1u64 << 53) as f64)
    }

    /// A standard normal draw (Box-Muller).
    pub fn normal(&mut self) -> f64 {
        let u = 1.0 - self.uniform(0.0, 1.0);
        let v = self.uniform(0.0, 1.0);
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }

    /// An array of type `ty` with every word uniform in [lo, hi) (truncated for u32).
    pub fn array(&mut self, ty: ValueType, lo: f64, hi: f64) -> HostArray {
        match ty.elem() {
            Elem::F32 => HostArray::f32(
                ty,
                (0..ty.words())
                    .map(|_| self.uniform(lo, hi) as f32)
                    .collect(),
            ),
            Elem::U32 => HostArray::u32(
                ty,
                (0..ty.words())
                    .map(|_| self.uniform(lo, hi) as u32)
                    .collect(),
            ),
        }
    }
}

/// `n` points uniform in the box of side `lengths` (one per axis, any number of axes)
/// centred at the origin, one row after another.
pub fn random_points(rng: &mut Rng, n: usize, lengths: &[f64]) -> Vec<f64> {
    let d = lengths.len();
    (0..n * d)
        .map(|i| rng.uniform(-0.5 * lengths[i % d], 0.5 * lengths[i % d]))
        .collect()
}

/// The range of [`random_keys`] that takes every u32.
pub const ANY_U32: u64 = 1 << 32;

/// `n` random keys below `range` (seeded).
pub fn random_keys(n: usize, range: u64, seed: u64) -> Vec<u32> {
    let mut rng = Rng::new(seed);
    (0..n).map(|_| (rng.next_u64() % range) as u32).collect()
}

/// Flat f64 values, `k` per row, as an f32 particle array.
pub fn flat_particles(values: &[f64], k: u32) -> HostArray {
    HostArray::f32(
        ValueType::Particles {
            n: values.len() as u32 / k,
            k,
        },
        values.iter().map(|&x| x as f32).collect(),
    )
}

/// Rows of f64 values as an f32 particle array, one row per particle (at least one row:
/// the first gives the number of columns).
pub fn particles<R: AsRef<[f64]>>(rows: &[R]) -> HostArray {
    let k = rows[0].as_ref().len();
    let values: Vec<f64> = rows.iter().flat_map(|r| r.as_ref().to_vec()).collect();
    flat_particles(&values, k as u32)
}

/// The rows of `a`, `k` values each, in f64.
pub fn rows(a: &HostArray, k: usize) -> Vec<Vec<f64>> {
    a.data.to_f64().chunks(k).map(|c| c.to_vec()).collect()
}

/// The rows of a 3-column array as 3-vectors (positions, forces, velocities).
pub fn vectors(a: &HostArray) -> Vec<[f64; 3]> {
    a.data
        .to_f64()
        .chunks(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect()
}

/// An index array of these values.
pub fn indices(values: &[u32]) -> HostArray {
    HostArray::u32(
        ValueType::Indices {
            n: values.len() as u32,
        },
        values.to_vec(),
    )
}

/// The words of a u32 array (indices, keys, cell sums).
pub fn u32s(a: &HostArray) -> Vec<u32> {
    match &a.data {
        HostData::U32(v) => v.clone(),
        other => panic!("expected u32 data, got {other:?}"),
    }
}

/// The words of an f32 array.
pub fn f32s(a: &HostArray) -> Vec<f32> {
    match &a.data {
        HostData::F32(v) => v.clone(),
        other => panic!("expected f32 data, got {other:?}"),
    }
}

/// The value of a scalar output.
pub fn scalar(a: &HostArray) -> f64 {
    a.data.to_f64()[0]
}
