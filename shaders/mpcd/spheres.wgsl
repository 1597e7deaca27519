// template: the solid spheres of the MPCD sphere kernels (nodes/mpcd/spheres.rs), which
// declare the parameter block `m`, the sphere block `sp` and the bindings `centres`
// (S x 3), `radii` (S) and `sphere_vel` (S x 3, read only when sp.moving = 1).
#import mpcd/common.wgsl
#import mpcd/sphere_block.wgsl

fn sphere_centre(j: u32) -> vec3<f32> {
    return vec3<f32>(centres[3u * j], centres[3u * j + 1u], centres[3u * j + 2u]);
}

fn sphere_velocity(j: u32) -> vec3<f32> {
    if (sp.moving == 0u) {
        return vec3<f32>(0.0);
    }
    return vec3<f32>(sphere_vel[3u * j], sphere_vel[3u * j + 1u], sphere_vel[3u * j + 2u]);
}

// The minimum image of a displacement on the periodic axes (the walled axis, z, kept).
fn min_image(r: vec3<f32>) -> vec3<f32> {
    let l = m.box.xyz;
    let w = r - l * floor(r / l + vec3<f32>(0.5));
    return select(w, r, vec3<bool>(false, false, m.walls == 1u));
}
