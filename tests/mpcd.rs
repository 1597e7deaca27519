//! The MPCD integration tests (tests/it/mpcd/), in a binary of their own rather than in
//! `it`: on lavapipe (Mesa 22.3.6, CI's driver) some MPCD kernels are still recompiled at
//! every dispatch after a pipeline bind (its uniform inlining), and every compiled copy
//! stays until the process ends, so thousands of MPCD steps would otherwise add up with
//! every other topic's memory in one process (ARCHITECTURE.md, Testing). Same helpers
//! (tests/it/util/) and the same GPU rules as `it`.

// The shared helpers include some that only the other topics call.
#![allow(dead_code)]

#[path = "it/mpcd/mod.rs"]
mod mpcd;
#[path = "it/util/mod.rs"]
mod util;
