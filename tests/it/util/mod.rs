//! Every helper the test modules share, each defined once; test modules import from here
//! and never from each other. The general helpers are re-exported at `crate::util`:
//! - `graphs`: writing and loading graph files, one-node graphs, load and validation errors;
//! - `run`: planning, compiling and running graphs in-process, compile errors, altered
//!   device capabilities;
//! - `data`: a seeded generator, random points and keys, arrays built from rows and read
//!   back;
//! - `compare`: a kind's f64 CPU reference, error measures, WGSL validation.
//!
//! The helpers of one topic (several test files each) stay in their own module:
//! `mobility` (FCM and PSE: f64 mobility references, one-step evaluation, noise
//! statistics), `disks` (packings, headings, a disk graph's inputs, runs with their loops'
//! iterations), `mpcd`, `spread`, `fft`, `probe` (test kinds: `countdown`, counting its
//! launches, and `countdown_in_place`; graphs of them loaded).

mod compare;
mod data;
pub mod disks;
pub mod fft;
mod graphs;
pub mod mobility;
pub mod mpcd;
pub mod probe;
mod run;
pub mod spread;

use std::path::PathBuf;
use std::sync::{Mutex, MutexGuard, OnceLock};

use mesoflow::gpu::GpuContext;
use mesoflow::node::Registry;

pub use compare::*;
pub use data::*;
pub use graphs::*;
pub use run::*;

static GPU: OnceLock<Option<Mutex<GpuContext>>> = OnceLock::new();

/// The shared GPU context, locked for the caller (tests submit from one thread at a time),
/// or `None` when there is no adapter and MESOFLOW_REQUIRE_GPU is not set.
pub fn gpu() -> Option<MutexGuard<'static, GpuContext>> {
    let slot = GPU.get_or_init(|| match GpuContext::new() {
        Ok(g) => Some(Mutex::new(g)),
        Err(e) => {
            if std::env::var_os("MESOFLOW_REQUIRE_GPU").is_some() {
                panic!("MESOFLOW_REQUIRE_GPU is set but no GPU context: {e}");
            }
            eprintln!("skipping GPU tests: {e}");
            None
        }
    });
    slot.as_ref()
        .map(|m| m.lock().unwrap_or_else(|p| p.into_inner()))
}

/// The standard registry of node kinds, built once.
pub fn registry() -> &'static Registry {
    static R: OnceLock<Registry> = OnceLock::new();
    R.get_or_init(mesoflow::nodes::registry)
}

/// The repository root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A fresh temporary folder for one test.
pub fn tmpdir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("mesoflow-it-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}
