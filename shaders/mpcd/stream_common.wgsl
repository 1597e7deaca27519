// template: the MPCD streaming of one particle, shared by mpcd/stream.wgsl and
// mpcd/stream_bin.wgsl (which declare the parameter block `m` and the bindings `pos_in`,
// `vel_in`, `pos_out`, `vel_out`). Ballistic motion for dt
// under the body force
// (acceleration g along x: x += v t + g t^2 / 2, v_x += g t, exact for a constant force;
// the sine force is evaluated at the start of the step), plates perpendicular to the last
// axis at +-L/2 (each crossing found exactly from the wall-normal motion, which the force
// does not change: bounce-back v -> -v or specular v_z -> -v_z, then the rest of the step),
// and a periodic wrap into [-L/2, L/2) on the other axes.
#import mpcd/common.wgsl
#import mpcd/rows.wgsl

// Moves (x, v) ballistically for time t under acceleration g along x.
fn advance(x: ptr<function, vec3<f32>>, v: ptr<function, vec3<f32>>, g: f32, t: f32) {
    *x = *x + *v * t;
    (*x).x = (*x).x + 0.5 * g * t * t;
    (*v).x = (*v).x + g * t;
}

// One particle's step: x, v at the start of the step in, wrapped x and v at its end out.
fn stream_particle(xp: ptr<function, vec3<f32>>, vp: ptr<function, vec3<f32>>) {
    var x = *xp;
    var v = *vp;
    let w = DIMS - 1u;
    var g = m.accel;
    if (m.force_shape == 1u) {
        g = m.accel * sin(6.283185307179586 * x[w] / m.box[w]);
    }
    if (m.walls == 0u) {
        advance(&x, &v, g, m.dt);
    } else {
        let h = 0.5 * m.box[w];
        var left = m.dt;
        // Each pass ends at a wall or at the end of the step; a particle crosses the gap at
        // most once per L / |v_z| of time, so a few passes are enough for any sane dt.
        for (var k = 0u; k < 16u && left > 0.0; k = k + 1u) {
            let vz = v[w];
            var hit = left;
            var wall = 0.0;
            if (vz > 0.0) {
                hit = max((h - x[w]) / vz, 0.0);
                wall = h;
            } else if (vz < 0.0) {
                hit = max((-h - x[w]) / vz, 0.0);
                wall = -h;
            }
            if (hit >= left) {
                advance(&x, &v, g, left);
                left = 0.0;
            } else {
                advance(&x, &v, g, hit);
                x[w] = wall;
                if (m.wall_slip == 1u) {
                    v[w] = -v[w];
                } else {
                    v = -v;
                }
                left = left - hit;
            }
        }
        x[w] = clamp(x[w], -h, h);
    }
    for (var a = 0u; a < DIMS; a = a + 1u) {
        if (m.walls == 0u || a != w) {
            let l = m.box[a];
            var y = x[a] - l * floor(x[a] / l + 0.5);
            if (y >= 0.5 * l) {
                y = y - l;
            }
            x[a] = y;
        }
    }
    *xp = x;
    *vp = v;
}

// Particle p streamed from pos_in, vel_in and written to pos_out, vel_out.
fn stream_row(p: u32) -> array<vec3<f32>, 2> {
    let r = load_row(p);
    var x = r[0];
    var v = r[1];
    stream_particle(&x, &v);
    for (var a = 0u; a < DIMS; a = a + 1u) {
        pos_out[p * DIMS + a] = x[a];
        vel_out[p * DIMS + a] = v[a];
    }
    return array<vec3<f32>, 2>(x, v);
}
