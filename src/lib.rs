//! mesoflow: complex-fluid simulation algorithms on the GPU as graphs of compute nodes.
//!
//! The path of a graph through the engine, one type per stage:
//! graph file --[`graph::load`]--> [`graph::Graph`] --[`plan::plan`]--> [`plan::Plan`]
//! --[`exec::Program::compile`]--> [`exec::Program`] --run--> outputs.
//! See ARCHITECTURE.md for the code map and the invariants.

pub mod exec;
pub mod expr;
pub mod gpu;
pub mod graph;
pub mod gsd;
pub mod ids;
pub mod node;
pub mod npy;
pub mod plan;
pub mod scene;
pub mod transform;
pub mod value;

#[path = "../nodes/mod.rs"]
pub mod nodes;
