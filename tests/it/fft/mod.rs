//! FFT nodes, by topic: transforms against rustfft in f64, round trips and Hermitian
//! consistency; plans without a GPU (size rules, recipes, generated WGSL, `inspect`);
//! spectral nodes folded into a transform. Shared helpers: `crate::util::fft`.

mod folding;
mod poisson;
mod recipes;
mod transforms;
