// MPCD streaming, one thread per particle: ballistic motion for dt under the body force
// (acceleration g along x: x += v t + g t^2 / 2, v_x += g t, exact for a constant force;
// the sine force is evaluated at the start of the step), plates perpendicular to the last
// axis at +-L/2 (each crossing found exactly from the wall-normal motion, which the force
// does not change: bounce-back v -> -v or specular v_z -> -v_z, then the rest of the step),
// and a periodic wrap into [-L/2, L/2) on the other axes.
#import common/index.wgsl
#import mpcd/common.wgsl

@group(0) @binding(0) var<uniform> m: Mpcd;
@group(0) @binding(1) var<storage, read> pos_in: array<f32>;
@group(0) @binding(2) var<storage, read> vel_in: array<f32>;
@group(0) @binding(3) var<storage, read_write> pos_out: array<f32>;
@group(0) @binding(4) var<storage, read_write> vel_out: array<f32>;

#import mpcd/stream_common.wgsl

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let p = flat_index(wid, nwg, lid, 256u);
    if (p >= m.n) {
        return;
    }
    _ = stream_row(p);
}
