// Records a snapshot of a particle array into a trajectory every `every` steps: after
// step s with (s + 1) % every == 0, frame (s + 1) / every - 1 (if there is one) gets the
// array. Other steps the threads return at once: the dispatch costs almost nothing.
#import common/index.wgsl

struct Shape { len: u32, every: u32, frames: u32, pad: u32 }

@group(0) @binding(0) var<storage, read> src: array<f32>;
@group(0) @binding(1) var<storage, read_write> dst: array<f32>;
@group(0) @binding(2) var<uniform> shape: Shape;
@group(0) @binding(3) var<storage, read> clock: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    let done = clock[0] + 1u;
    if (i >= shape.len || done % shape.every != 0u) {
        return;
    }
    let frame = done / shape.every - 1u;
    if (frame < shape.frames) {
        dst[frame * shape.len + i] = src[i];
    }
}
