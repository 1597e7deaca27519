//! The GPU layer: device context and capabilities, kernels and their cache, the embedded
//! WGSL library, and what the driver makes of a kernel (`driver_stats`, a tool for kernel
//! work). Knows nothing about graphs.

mod context;
pub mod driver_stats;
mod kernel;
pub mod shaders;

pub use context::{DeviceCaps, GPU_TIMEOUT, GpuContext, GpuError};
pub use kernel::{
    Binding, Choice, CompileCtx, CompileError, Dispatch, Kernel, KernelCache, KernelSpec,
    NodeDecision, NodeIo, NodePlan, Period, Slot, WG_1D, grid_1d,
};
