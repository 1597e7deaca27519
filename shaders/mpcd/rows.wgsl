// template: particle rows of the MPCD per-particle kernels, which declare `pos_in` and
// `vel_in` (and, for `stream_row`, `pos_out` and `vel_out`; mpcd/stream_common.wgsl).
#import mpcd/common.wgsl

// Position and velocity of particle p.
fn load_row(p: u32) -> array<vec3<f32>, 2> {
    var x = vec3<f32>(0.0);
    var v = vec3<f32>(0.0);
    for (var a = 0u; a < DIMS; a = a + 1u) {
        x[a] = pos_in[p * DIMS + a];
        v[a] = vel_in[p * DIMS + a];
    }
    return array<vec3<f32>, 2>(x, v);
}
