// Solid spheres' motion, one thread per sphere. Fixed (sp.moving = 0): positions copied,
// velocities zero. Moving: without an impulse (the initial state) positions and
// velocities copied (zero when none are given); with this step's impulse J (64-bit fixed
// point, units m v_th / 2^24: mpcd_sphere_force) the explicit step of the solvent's
// streaming, x += V dt (wrapped into the box), then Newton's V += J m / (fix_v M).
#import common/index.wgsl
#import mpcd/common.wgsl
#import mpcd/sphere_block.wgsl

@group(0) @binding(0) var<uniform> m: Mpcd;
@group(0) @binding(1) var<uniform> sp: Spheres;
@group(0) @binding(2) var<storage, read> centres: array<f32>;
@group(0) @binding(3) var<storage, read> sphere_vel: array<f32>;
@group(0) @binding(4) var<storage, read> masses: array<f32>;
@group(0) @binding(5) var<storage, read> impulse: array<u32>;
@group(0) @binding(6) var<storage, read_write> pos_out: array<f32>;
@group(0) @binding(7) var<storage, read_write> vel_out: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let j = flat_index(wid, nwg, lid, 64u);
    if (j >= sp.count) {
        return;
    }
    var x = vec3<f32>(centres[3u * j], centres[3u * j + 1u], centres[3u * j + 2u]);
    var v = vec3<f32>(0.0);
    if (sp.moving == 1u && sp.has_velocity == 1u) {
        v = vec3<f32>(sphere_vel[3u * j], sphere_vel[3u * j + 1u], sphere_vel[3u * j + 2u]);
    }
    if (sp.moving == 1u && sp.has_impulse == 1u) {
        x = x + v * m.dt;
        let unit = m.mass / (m.fix_v * masses[j]);
        for (var a = 0u; a < 3u; a = a + 1u) {
            let k = 6u * j + 2u * a;
            v[a] = v[a] + fx_to_f32(vec2<u32>(impulse[k], impulse[k + 1u])) * unit;
            if (m.walls == 0u || a != 2u) {
                let l = m.box[a];
                var y = x[a] - l * floor(x[a] / l + 0.5);
                if (y >= 0.5 * l) {
                    y = y - l;
                }
                x[a] = y;
            }
        }
    }
    for (var a = 0u; a < 3u; a = a + 1u) {
        pos_out[3u * j + a] = x[a];
        vel_out[3u * j + a] = v[a];
    }
}
