// S1 section 4.3, step 2a: the edges (each once, by its smaller slot) whose end points
// passed through each other in a move: r0 . r1 < 0 for the edge vector r = x_c - x_b
// before (r0) and after (r1), both by the minimum image. Counted into `count` (zeroed by
// the node's fill before this kernel).
#import common/index.wgsl

struct Params { slots: u32, pad: u32, box_len: vec2<f32> }

@group(0) @binding(0) var<storage, read> before: array<vec2<f32>>;
@group(0) @binding(1) var<storage, read> after: array<vec2<f32>>;
@group(0) @binding(2) var<storage, read> mesh: array<u32>;
@group(0) @binding(3) var<storage, read_write> count: array<atomic<u32>>;
@group(0) @binding(4) var<uniform> params: Params;

// p - q by the minimum image. The image shift goes on p before the difference: p - k L
// is exact (both are multiples of p's ulp) and so is the difference of two nearby
// values, while (p - q) - k L first rounds p - q at the box's scale (an ulp of 1.2e-4 in
// a box of 1257, enough to make the in-circle test of a quad across the periodic
// boundary disagree with itself after a flip, which then never ends).
fn image_difference(p: vec2<f32>, q: vec2<f32>) -> vec2<f32> {
    return (p - params.box_len * round((p - q) / params.box_len)) - q;
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let s = flat_index(wid, nwg, lid, 256u);
    if (s >= params.slots) {
        return;
    }
    let t = s / 3u;
    let k = s % 3u;
    if (mesh[6u * t + 3u + k] <= s) {
        return;
    }
    let b = mesh[6u * t + (k + 1u) % 3u];
    let c = mesh[6u * t + (k + 2u) % 3u];
    let r0 = image_difference(before[c], before[b]);
    let r1 = image_difference(after[c], after[b]);
    if (dot(r0, r1) < 0.0) {
        atomicAdd(&count[0], 1u);
    }
}
