// One round of the overlap correction of S1 section 2.3 (eq. 4) and Algorithm 2, along
// the edges of the torus mesh (nodes/disks/mesh.rs layout), without float atomics: each
// particle gathers over its own edges (the fan of triangles around it, walked by twins
// from its lowest corner) the displacement delta (sigma - r) r_hat away from every
// neighbour closer than sigma, clamps its length to sigma / 4, moves and wraps into the
// box. A pair at distance 0 has no direction and pushes nothing. Entries:
// - `clear`: every particle's first corner to 0xFFFFFFFF, the count to 0;
// - `corners`: every corner offers itself to its vertex by atomicMin (the lowest wins:
//   the walk, and so the float sums, in a fixed order);
// - `correct`: one thread per particle; counts each overlapping pair once (by its lower
//   id) in `count`: the overlaps of the positions read, so a round that counts 0 moved
//   nothing.
#import common/index.wgsl

// The longest fan walked: a vertex with more edges (none in a Delaunay mesh of disks) is
// corrected by its first MAX_FAN only.
const MAX_FAN: u32 = 128u;

// limit: sigma less the tolerance (nodes/disks/overlap.rs `overlap_tolerance`): closer pairs overlap.
struct Params { n: u32, slots: u32, sigma: f32, delta: f32, box_len: vec2<f32>, max_step: f32, limit: f32 }

@group(0) @binding(0) var<storage, read> x: array<vec2<f32>>;
@group(0) @binding(1) var<storage, read> mesh: array<u32>;
@group(0) @binding(2) var<storage, read_write> out: array<vec2<f32>>;
@group(0) @binding(3) var<storage, read_write> first_corner: array<atomic<u32>>;
@group(0) @binding(4) var<storage, read_write> count: array<atomic<u32>>;
@group(0) @binding(5) var<uniform> params: Params;

fn minimum_image(r: vec2<f32>) -> vec2<f32> {
    return r - params.box_len * round(r / params.box_len);
}

fn wrap(p: vec2<f32>) -> vec2<f32> {
    return p - params.box_len * floor((p + 0.5 * params.box_len) / params.box_len);
}

@compute @workgroup_size(256)
fn clear(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i < params.n) {
        atomicStore(&first_corner[i], 0xFFFFFFFFu);
    }
    if (i == 0u) {
        atomicStore(&count[0], 0u);
    }
}

@compute @workgroup_size(256)
fn corners(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
           @builtin(local_invocation_index) lid: u32) {
    let c = flat_index(wid, nwg, lid, 256u);
    if (c >= params.slots) {
        return;
    }
    let v = mesh[6u * (c / 3u) + c % 3u];
    if (v < params.n) {
        atomicMin(&first_corner[v], c);
    }
}

@compute @workgroup_size(256)
fn correct(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
           @builtin(local_invocation_index) lid: u32) {
    let v = flat_index(wid, nwg, lid, 256u);
    if (v >= params.n) {
        return;
    }
    let xv = x[v];
    let start = atomicLoad(&first_corner[v]);
    var shift = vec2<f32>(0.0);
    var overlaps = 0u;
    var c = start;
    for (var step = 0u; step < MAX_FAN && c < params.slots; step = step + 1u) {
        let t = c / 3u;
        let k = c % 3u;
        // The edge v -> v_(k+1) of this corner; the next corner is across it.
        let w = mesh[6u * t + (k + 1u) % 3u];
        let r = minimum_image(x[w] - xv);
        let len = length(r);
        if (len < params.limit && len > 0.0) {
            shift = shift - (params.delta * (params.sigma - len) / len) * r;
            overlaps = overlaps + select(0u, 1u, w > v);
        }
        let u = mesh[6u * t + 3u + (k + 2u) % 3u];
        c = 3u * (u / 3u) + (u % 3u + 2u) % 3u;
        if (c == start) {
            break;
        }
    }
    let s = length(shift);
    if (s > params.max_step) {
        shift = shift * (params.max_step / s);
    }
    out[v] = wrap(xv + shift);
    if (overlaps > 0u) {
        atomicAdd(&count[0], overlaps);
    }
}
