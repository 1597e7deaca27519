//! The Force Coupling Method's own pieces: its planner (grid and window from a radius)
//! and the Stokes operators in Fourier space.

pub mod plan;
