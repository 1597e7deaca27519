//! The integration tests: one binary (one link on a 2-core machine), topic modules; the
//! MPCD topic (tests/it/mpcd/) links as its own binary, tests/mpcd.rs, to keep lavapipe's
//! per-dispatch recompilations of its kernels out of this process.
//! GPU tests run on whatever Vulkan adapter is present (lavapipe in CI); with
//! MESOFLOW_REQUIRE_GPU=1 (set by .ci/run) a missing adapter fails them instead of
//! skipping them.

mod bin_sort;
mod bonds;
mod cells;
mod chebyshev;
mod cli;
mod determinism;
mod disks;
mod dpstokes;
mod fcm;
mod fft;
mod fuzz;
mod graph_files;
mod integrators;
mod lanczos;
mod layout;
mod nbody;
mod nodes;
mod pairs;
mod plan;
mod poisson;
mod pse;
mod random;
mod reduce;
mod repeat;
mod run;
mod scan;
mod scene;
mod shaders;
mod sort;
mod spread;
mod stokes_slab;
mod untrusted;
// Some helpers serve only the MPCD binary (tests/mpcd.rs).
#[allow(dead_code)]
mod util;
