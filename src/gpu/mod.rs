//! The GPU layer: device context and capabilities, kernels and their cache, the embedded
//! WGSL library. Knows nothing about graphs.

mod context;
mod kernel;
pub mod shaders;

pub use context::{DeviceCaps, GPU_TIMEOUT, GpuContext, GpuError};
pub use kernel::{
    Binding, Choice, CompileCtx, CompileError, Dispatch, Kernel, KernelCache, KernelSpec,
    NodeDecision, NodeIo, NodePlan, Period, Slot, WG_1D, grid_1d,
};
