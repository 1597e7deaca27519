//! The Force Coupling Method's own pieces: its planner (grid and window from a radius and
//! a tolerance, in f64) and the f64 periodic mobility its benchmark measures errors
//! against. The operators themselves are generic nodes (spread, rfft, `stokes`, `curl`,
//! `stokes_noise`, irfft, interpolate) composed by graphs/fcm.json.

pub mod bound;
pub mod plan;
pub mod reference;
