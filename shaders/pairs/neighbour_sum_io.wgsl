// template: the bindings and value loads of both neighbour_sum traversals
// (neighbour_sum.wgsl, neighbour_sum_lanes.wgsl; nodes/pairs/mod.rs binds them in this
// order). VALUE_COMPS, OUT_FIRST, OUT_COMPS: pairs/values.wgsl.

override LIST_WIDTH: u32 = 0u;   // neighbour list entries per particle (0: no list)

@group(0) @binding(0) var<storage, read> pos: array<f32>;
@group(0) @binding(1) var<storage, read> vals: array<f32>;
@group(0) @binding(2) var<storage, read> keys: array<u32>;
@group(0) @binding(3) var<storage, read> cell_start: array<u32>;
@group(0) @binding(4) var<storage, read> cell_count: array<u32>;
@group(0) @binding(5) var<storage, read_write> out: array<f32>;
@group(0) @binding(6) var<uniform> geo: Geometry;
@group(0) @binding(7) var<storage, read> pair_params: array<f32>;
@group(0) @binding(8) var<storage, read> pair_table: array<f32>;
@group(0) @binding(9) var<storage, read> list: array<u32>;
@group(0) @binding(10) var<storage, read> list_count: array<u32>;

#import pairs/values.wgsl
