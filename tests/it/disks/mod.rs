//! The 2-D Brownian disks of S1 (Carter et al. 2017, nodes/disks/): pair forces against
//! their f64 sums, the moves against their references and the paper's noise statistics.
//! Shared helpers: `crate::util::disks`.

mod flip;
mod forces;
mod graph;
mod loops;
mod order;
mod overlap;
mod short_range;
mod start;
mod step;
mod table1;
