//! Node implementations, each beside its f64 CPU reference. Kernels live in `shaders/`.

pub mod pointwise;
pub mod scan;
pub mod sort;

use crate::node::Registry;

/// Adds every shipped node kind to the registry.
pub fn register_all(r: &mut Registry) {
    pointwise::register(r);
    scan::register(r);
    sort::register(r);
}
