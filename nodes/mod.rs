//! Node implementations, each beside its f64 CPU reference. Kernels live in `shaders/`.

pub mod bin_sort;
pub mod bonds;
pub mod cells;
pub mod chebyshev;
pub mod chebyshev_bvp;
pub mod chebyshev_spread;
pub mod disks;
pub mod fcm;
pub mod fft;
pub mod lanczos;
pub mod mpcd;
pub mod pairs;
pub mod permute;
pub mod planners;
pub mod pointwise;
pub mod poisson;
pub mod pse;
pub mod random;
pub mod record;
pub mod reduce;
pub mod repeat;
pub mod scan;
pub mod slab_solve;
pub mod sort;
pub mod spectral;
pub mod spread;
pub mod stokes_slab;

use crate::node::Registry;

/// Every shipped node kind and host function.
pub fn registry() -> Registry {
    let mut r = Registry::default();
    register_all(&mut r);
    r
}

/// Adds every shipped node kind and host function to the registry.
pub fn register_all(r: &mut Registry) {
    planners::register(r);
    bin_sort::register(r);
    bonds::register(r);
    chebyshev::register(r);
    chebyshev_bvp::register(r);
    chebyshev_spread::register(r);
    fft::register(r);
    pointwise::register(r);
    cells::register(r);
    disks::register(r);
    lanczos::register(r);
    mpcd::register(r);
    pairs::register(r);
    permute::register(r);
    random::register(r);
    record::register(r);
    reduce::register(r);
    repeat::register(r);
    spread::register(r);
    stokes_slab::register(r);
    slab_solve::register(r);
    scan::register(r);
    sort::register(r);
    spectral::register(r);
}
