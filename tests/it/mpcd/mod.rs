//! MPCD (nodes/mpcd/, graphs/mpcd.json) by topic: streaming and walls against an f64
//! event schedule, binning with exact cell sums and the collisions' per-cell conservation
//! laws and f64 references, the whole graph (initial state, measurement, momentum over
//! many steps, bad input), the thermostats, viscosity against kinetic theory and measured
//! values, solute coupling, solid spheres, given data checked on the host before it runs, and params
//! beyond what the f32 kernels carry refused. Shared helpers: `crate::util::mpcd`.

mod collide;
mod graph;
mod inputs;
mod params;
mod solute;
mod spheres;
mod streaming;
mod thermostats;
mod viscosity;
