// template: nodes/disks/forces.rs puts `fn every_lane(b: bool) -> bool` before the source.
// Non-reciprocal pair forces of 2-D disks (Carter, Hitschfeld, Navarro, Soto 2017, S1 eqs.
// 2-3), all pairs, one thread per particle i:
//   F_i = mu_i sum_{k != i} alpha_k f(r_i - r_k),  r_i - r_k by the minimum image,
//   f(r) = r / |r|^3 (law 0, long range) or r / |r|^7 (law 1, short range),
// and 0 at |r| >= cutoff when cutoff > 0. Charges are (alpha, mu) per particle. The j
// particles come in tiles of WG through workgroup memory (Nyland, Harris, Prins), each
// thread summing the tile in the same order: no atomics, the same result every run. A
// pair at distance 0 (the particle itself, or a coincident one) adds nothing.
//
// The pair loop is what the long-range law's speed is (issue 24: half the f32 peak).
// - `bounds` (one thread per tile of WG particles) writes each tile's bounding box.
// - `main`: per tile, a thread whose particle sees the whole box of the tile through one
//   periodic image (every |x_i - shift - x_k| below half the box on each axis) shifts x_i
//   once and runs the pair loop without any minimum image: a difference, r^2, one
//   inverseSqrt, the weight and the sum. Particles in a spatial order (a lattice, the cell
//   list's order) make compact tiles, so nearly every (particle, tile) takes this path.
// - Otherwise (a tile straddling the half-box distance, or particles in no order) each
//   pair takes its own minimum image: rounding by the magic number 1.5 x 2^23
//   (fma(d, 1/L, MAGIC) - MAGIC is d/L rounded to the nearest integer for |d/L| < 2^22;
//   no division, and no round(), which NVIDIA runs on the quarter-rate special-function
//   unit beside the inverse square root).
// Both paths give the minimum image, so the result does not depend on the order; the law
// and the cutoff are decided once per thread, outside the loops.
// - The path is chosen per subgroup where the adapter has subgroups (`every_lane`, put
//   before this source by the node: subgroupAll, else the thread's own test): a warp
//   whose lanes disagree would run both loops one after the other, so it runs the exact
//   one only (about 14 % of the warps at 2^16 disks, where a tile of 128 disks near half
//   the box sees some lanes through two images).
// - Few particles fill few workgroups (2^16 disks: 512 of 128 threads, a quarter of what
//   an H100 holds at once): the tiles are then split into `slices` ranges, workgroup w
//   summing particle tile w mod tiles_i over slice w / tiles_i into `partial`, and
//   `combine` adds a particle's slices in slice order and applies mu (the same sum every
//   run). With one slice `main` writes the force itself.
#import common/index.wgsl

const WG: u32 = 128u;

// zero: 0, read from the uniform so that no compiler can see it (see minimum_image).
// slices: ranges the tiles are split into; tiles_per_slice: tiles in each (the last may
// hold fewer).
struct Params { n: u32, law: u32, cutoff2: f32, zero: u32, box_len: vec2<f32>, slices: u32,
                tiles_per_slice: u32 }

@group(0) @binding(0) var<storage, read> x: array<vec2<f32>>;
@group(0) @binding(1) var<storage, read> charges: array<vec2<f32>>;
@group(0) @binding(2) var<storage, read_write> forces: array<vec2<f32>>;
@group(0) @binding(3) var<uniform> params: Params;
// Per tile: (lower x, lower y, upper x, upper y).
@group(0) @binding(4) var<storage, read_write> tile_box: array<vec4<f32>>;
// With slices > 1: slice s's sum for particle i at s n + i (mu not applied).
@group(0) @binding(5) var<storage, read_write> partial: array<vec2<f32>>;

var<workgroup> tile: array<vec4<f32>, WG>;

const MAGIC: f32 = 12582912.0;

// r by the minimum image: d less the nearest multiple of the box (an open axis, L = 0 and
// inv_l = 0, keeps d). The rounded sum passes through an integer XOR with the uniform's
// zero: without it a compiler that reassociates floats (lavapipe's LLVM does) folds
// (t + MAGIC) - MAGIC to t and the rounding is lost. The XOR runs on the integer pipe.
fn minimum_image(d: vec2<f32>, l: vec2<f32>, inv_l: vec2<f32>) -> vec2<f32> {
    let t = fma(d, inv_l, vec2<f32>(MAGIC));
    let k = bitcast<vec2<f32>>(bitcast<vec2<u32>>(t) ^ vec2<u32>(params.zero)) - vec2<f32>(MAGIC);
    return fma(-l, k, d);
}

// The long-range law without cutoff over one tile, each pair by its minimum image.
fn tile_long(xi: vec2<f32>, l: vec2<f32>, inv_l: vec2<f32>) -> vec2<f32> {
    var f = vec2<f32>(0.0);
    for (var k = 0u; k < WG; k = k + 1u) {
        let p = tile[k];
        let r = minimum_image(xi - p.xy, l, inv_l);
        let r2 = dot(r, r);
        let inv = select(0.0, inverseSqrt(r2), r2 > 0.0);
        f = f + (p.z * inv * inv * inv) * r;
    }
    return f;
}

// The same when the whole tile is seen through one image: xs is x_i shifted to it. The
// squared distance is clamped at R2_FLOOR instead of tested (one instruction, not two): a
// pair at r = 0 (the particle itself) then adds 0 x 1e30 alpha, nothing; only a pair
// closer than 1e-10 but not coincident, which f32 positions of disks never make, would
// differ from the exact law.
const R2_FLOOR: f32 = 1e-20;
fn tile_long_one_image(xs: vec2<f32>) -> vec2<f32> {
    var f = vec2<f32>(0.0);
    for (var k = 0u; k < WG; k = k + 1u) {
        let p = tile[k];
        let r = xs - p.xy;
        let inv = inverseSqrt(max(dot(r, r), R2_FLOOR));
        // alpha / r^3 as (alpha / r) (1 / r^2): two independent products, then one.
        f = f + ((p.z * inv) * (inv * inv)) * r;
    }
    return f;
}

// Either law, with the cutoff: S1's short-range law when it runs all pairs.
fn tile_general(xi: vec2<f32>, l: vec2<f32>, inv_l: vec2<f32>) -> vec2<f32> {
    var f = vec2<f32>(0.0);
    let cut2 = select(3.4e38, params.cutoff2, params.cutoff2 > 0.0);
    let short = params.law == 1u;
    for (var k = 0u; k < WG; k = k + 1u) {
        let p = tile[k];
        let r = minimum_image(xi - p.xy, l, inv_l);
        let r2 = dot(r, r);
        let ok = r2 > 0.0 && r2 < cut2;
        let inv = select(0.0, inverseSqrt(r2), ok);
        let inv3 = inv * inv * inv;
        let w = select(inv3, inv3 * inv3 * inv, short);
        f = f + (p.z * w) * r;
    }
    return f;
}

@compute @workgroup_size(128)
fn bounds(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
          @builtin(local_invocation_index) lid: u32) {
    let t = flat_index(wid, nwg, lid, WG);
    if (t * WG >= params.n) {
        return;
    }
    var lo = x[t * WG];
    var hi = lo;
    for (var j = t * WG + 1u; j < min(params.n, (t + 1u) * WG); j = j + 1u) {
        lo = min(lo, x[j]);
        hi = max(hi, x[j]);
    }
    tile_box[t] = vec4<f32>(lo, hi);
}

@compute @workgroup_size(128)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let tiles = (params.n + WG - 1u) / WG;
    let w = wid.y * nwg.x + wid.x;
    let slice = w / tiles;
    if (slice >= params.slices) {
        return;
    }
    let i = (w % tiles) * WG + lid;
    let inside = i < params.n;
    let xi = x[min(i, params.n - 1u)];
    let l = max(params.box_len, vec2<f32>(0.0));
    let periodic = l > vec2<f32>(0.0);
    let inv_l = select(vec2<f32>(0.0), 1.0 / l, periodic);
    let half = select(vec2<f32>(3.4e38), 0.5 * l, periodic);
    let fast = params.law == 0u && params.cutoff2 <= 0.0;
    var f = vec2<f32>(0.0);
    let first = slice * params.tiles_per_slice;
    let last = min(tiles, first + params.tiles_per_slice);
    for (var t = first; t < last; t = t + 1u) {
        let j = t * WG + lid;
        if (j < params.n) {
            tile[lid] = vec4<f32>(x[j], charges[j].x, 0.0);
        } else {
            // Past the last particle: no charge, adds nothing.
            tile[lid] = vec4<f32>(xi, 0.0, 0.0);
        }
        workgroupBarrier();
        if (fast) {
            // The image of the tile's centre; one image serves the tile when every
            // difference stays strictly within half the box (ties take the exact path).
            let b = tile_box[t];
            let xs = xi - l * round((xi - 0.5 * (b.xy + b.zw)) * inv_l);
            if (every_lane(all(xs - b.xy < half) && all(b.zw - xs < half))) {
                f = f + tile_long_one_image(xs);
            } else {
                f = f + tile_long(xi, l, inv_l);
            }
        } else {
            f = f + tile_general(xi, l, inv_l);
        }
        workgroupBarrier();
    }
    if (!inside) {
        return;
    }
    if (params.slices == 1u) {
        forces[i] = charges[i].y * f;
    } else {
        partial[slice * params.n + i] = f;
    }
}

// With slices > 1, after `main`: each particle's slices added in slice order, times mu.
@compute @workgroup_size(128)
fn combine(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
           @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, WG);
    if (i >= params.n) {
        return;
    }
    var f = vec2<f32>(0.0);
    for (var s = 0u; s < params.slices; s = s + 1u) {
        f = f + partial[s * params.n + i];
    }
    forces[i] = charges[i].y * f;
}
