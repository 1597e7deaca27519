// Harmonic bonds, one thread per particle: particle i sums over its partners
// partner[start[i] .. start[i + 1]] the force k (r - r0) r_vec / r (r_vec = x_j - x_i,
// the minimum image along axes with a box length > 0) and half of each bond's energy
// k (r - r0)^2 / 2 (each bond is listed at both its ends). A gather: no atomics, the
// same sums in the same order every run. A partner index past the last particle is
// skipped; a bond of zero length pulls nowhere.
#import common/index.wgsl

struct Params { n: u32, partners: u32, k: f32, r0: f32, box_lengths: vec4<f32> }

@group(0) @binding(0) var<storage, read> x: array<f32>;
@group(0) @binding(1) var<storage, read> start: array<u32>;
@group(0) @binding(2) var<storage, read> partner: array<u32>;
@group(0) @binding(3) var<storage, read_write> forces: array<f32>;
@group(0) @binding(4) var<storage, read_write> energy: array<f32>;
@group(0) @binding(5) var<uniform> params: Params;

fn minimum_image(r: f32, length: f32) -> f32 {
    if (length > 0.0) {
        return r - length * round(r / length);
    }
    return r;
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i >= params.n) {
        return;
    }
    let xi = vec3<f32>(x[3u * i], x[3u * i + 1u], x[3u * i + 2u]);
    let first = min(start[i], params.partners);
    let last = min(start[i + 1u], params.partners);
    var f = vec3<f32>(0.0, 0.0, 0.0);
    var e = 0.0;
    for (var b = first; b < last; b = b + 1u) {
        let j = partner[b];
        if (j >= params.n) {
            continue;
        }
        let xj = vec3<f32>(x[3u * j], x[3u * j + 1u], x[3u * j + 2u]);
        let r = vec3<f32>(
            minimum_image(xj.x - xi.x, params.box_lengths.x),
            minimum_image(xj.y - xi.y, params.box_lengths.y),
            minimum_image(xj.z - xi.z, params.box_lengths.z));
        let d = length(r);
        let stretch = d - params.r0;
        e = e + 0.25 * params.k * stretch * stretch;
        if (d > 0.0) {
            f = f + (params.k * stretch / d) * r;
        }
    }
    forces[3u * i] = f.x;
    forces[3u * i + 1u] = f.y;
    forces[3u * i + 2u] = f.z;
    energy[i] = e;
}
