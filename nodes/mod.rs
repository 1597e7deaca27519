//! Node implementations, each beside its f64 CPU reference. Kernels live in `shaders/`.

pub mod fft;
pub mod pointwise;
pub mod spectral;

use crate::node::Registry;

/// Adds every shipped node kind to the registry.
pub fn register_all(r: &mut Registry) {
    fft::register(r);
    pointwise::register(r);
    spectral::register(r);
}
