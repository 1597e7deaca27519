// Deterministic spreading, step 1 (nodes/spread/fixed.rs): the largest |value| of the
// particles' values as f32 bits (for non-negative floats the bits order as the values;
// NaN's bits exceed infinity's), max'd per workgroup, then once into word FIXED_WORDS of
// the fixed-point grid. A max is the same in any order.
#import common/index.wgsl

struct Count { words: u32 }

@group(0) @binding(0) var<storage, read> vals: array<f32>;
@group(0) @binding(1) var<storage, read_write> grid: array<atomic<u32>>;
@group(0) @binding(2) var<uniform> count: Count;

override FIXED_WORDS: u32 = 0u;

var<workgroup> wg_max: atomic<u32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (lid == 0u) {
        atomicStore(&wg_max, 0u);
    }
    workgroupBarrier();
    if (i < count.words) {
        atomicMax(&wg_max, bitcast<u32>(abs(vals[i])));
    }
    workgroupBarrier();
    if (lid == 0u) {
        atomicMax(&grid[FIXED_WORDS], atomicLoad(&wg_max));
    }
}
