// A drawn MPCD solvent moved out of the solid spheres, one thread per particle (3D): a
// particle inside a sphere (the nearest periodic image of its centre) is drawn again,
// uniform in the box, from Philox at "step" k = 1, 2, ... of (seed, stream) (mpcd_init
// draws at step 0), until it lies outside every sphere or EXCLUDE_TRIES draws are spent.
#import common/index.wgsl
#import mpcd/common.wgsl

@group(0) @binding(0) var<uniform> m: Mpcd;
@group(0) @binding(1) var<uniform> sp: Spheres;
@group(0) @binding(2) var<storage, read> pos_in: array<f32>;
@group(0) @binding(3) var<storage, read> centres: array<f32>;
@group(0) @binding(4) var<storage, read> radii: array<f32>;
@group(0) @binding(5) var<storage, read> sphere_vel: array<f32>;
@group(0) @binding(6) var<storage, read_write> pos_out: array<f32>;

#import mpcd/spheres.wgsl

const EXCLUDE_TRIES: u32 = 64u;

fn inside_any(x: vec3<f32>) -> bool {
    for (var j = 0u; j < sp.count; j = j + 1u) {
        let r = min_image(x - sphere_centre(j));
        if (dot(r, r) < radii[j] * radii[j]) {
            return true;
        }
    }
    return false;
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let p = flat_index(wid, nwg, lid, 256u);
    if (p >= m.n) {
        return;
    }
    var x = vec3<f32>(pos_in[3u * p], pos_in[3u * p + 1u], pos_in[3u * p + 2u]);
    for (var k = 1u; k <= EXCLUDE_TRIES && inside_any(x); k = k + 1u) {
        for (var a = 0u; a < 3u; a = a + 1u) {
            let u = philox_uniform(3u * p + a, k, m.seed_lo, m.seed_hi, m.stream);
            x[a] = min((u - 0.5) * m.box[a], 0.5 * m.box[a]);
        }
    }
    for (var a = 0u; a < 3u; a = a + 1u) {
        pos_out[3u * p + a] = x[a];
    }
}
