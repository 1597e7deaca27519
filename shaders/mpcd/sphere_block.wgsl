// The sphere block every MPCD sphere kernel binds beside `Mpcd` (nodes/mpcd/spheres.rs,
// SphereUniform).

struct Spheres {
    count: u32,            // spheres S
    per: u32,              // virtual particles per sphere
    moving: u32,           // 1: sphere_vel holds the spheres' velocities (else at rest)
    warmup: u32,           // steps before the force averages
    has_velocity: u32,     // mpcd_sphere_move: 1 when velocities are given
    has_impulse: u32,      // mpcd_sphere_move: 1 when an impulse is given (a step)
    pad0: u32,
    pad1: u32,
}
