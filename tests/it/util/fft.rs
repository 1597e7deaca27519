//! FFT (tests/it/fft/): seeded inputs, two-transform graphs, device limits for recipes.

use mesoflow::gpu::DeviceCaps;
use mesoflow::value::ValueType;

use super::input_decl;

/// The seed of a case's random input, from its shape.
pub fn seed(dims: [u32; 3], comps: u32) -> u64 {
    dims.iter().map(|&d| d as u64).product::<u64>() * 31 + comps as u64
}

/// A two-node graph: `first` then `second`, both over `axes`.
pub fn chain(first: &str, second: &str, ty: ValueType, axes: &str) -> String {
    format!(
        r#"{{"mesoflow": 1, "inputs": {{"x": {}}},
          "nodes": [
            {{"id": "a", "kind": "{first}", "params": {{"axes": "{axes}"}}, "inputs": {{"x": "inputs.x"}}}},
            {{"id": "b", "kind": "{second}", "params": {{"axes": "{axes}"}}, "inputs": {{"x": "a.out"}}}}
          ],
          "outputs": {{"a": "a.out", "b": "b.out"}}}}"#,
        input_decl(&ty)
    )
}

/// The baseline device with `shared` bytes of workgroup memory and `threads` invocations
/// per workgroup (the limits recipes are planned for).
pub fn caps_with(shared: u32, threads: u32) -> DeviceCaps {
    DeviceCaps {
        max_workgroup_storage: shared,
        max_invocations: threads,
        ..DeviceCaps::baseline()
    }
}
