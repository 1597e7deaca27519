// Non-reciprocal pair forces of 2-D disks (Carter, Hitschfeld, Navarro, Soto 2017, S1 eqs.
// 2-3), all pairs, one thread per particle i:
//   F_i = mu_i sum_{k != i} alpha_k f(r_i - r_k),  r_i - r_k by the minimum image,
//   f(r) = r / |r|^3 (law 0, long range) or r / |r|^7 (law 1, short range),
// and 0 at |r| >= cutoff when cutoff > 0. Charges are (alpha, mu) per particle. The j
// particles come in tiles of WG through workgroup memory (Nyland, Harris, Prins), each
// thread summing the tile in the same order: no atomics, the same result every run. A
// pair at distance 0 (the particle itself, or a coincident one) adds nothing.
#import common/index.wgsl

const WG: u32 = 128u;

struct Params { n: u32, law: u32, cutoff2: f32, pad: u32, box_len: vec2<f32> }

@group(0) @binding(0) var<storage, read> x: array<vec2<f32>>;
@group(0) @binding(1) var<storage, read> charges: array<vec2<f32>>;
@group(0) @binding(2) var<storage, read_write> forces: array<vec2<f32>>;
@group(0) @binding(3) var<uniform> params: Params;

var<workgroup> tile: array<vec4<f32>, WG>;

fn minimum_image(r: vec2<f32>) -> vec2<f32> {
    let l = params.box_len;
    let wrapped = r - l * round(r / max(l, vec2<f32>(1e-30)));
    return select(r, wrapped, l > vec2<f32>(0.0));
}

@compute @workgroup_size(128)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, WG);
    let inside = i < params.n;
    let xi = x[min(i, params.n - 1u)];
    var f = vec2<f32>(0.0);
    let tiles = (params.n + WG - 1u) / WG;
    for (var t = 0u; t < tiles; t = t + 1u) {
        let j = t * WG + lid;
        if (j < params.n) {
            tile[lid] = vec4<f32>(x[j], charges[j].x, 0.0);
        } else {
            // Past the last particle: no charge, adds nothing.
            tile[lid] = vec4<f32>(xi, 0.0, 0.0);
        }
        workgroupBarrier();
        for (var k = 0u; k < WG; k = k + 1u) {
            let p = tile[k];
            let r = minimum_image(xi - p.xy);
            let r2 = dot(r, r);
            var ok = r2 > 0.0;
            if (params.cutoff2 > 0.0) {
                ok = ok && r2 < params.cutoff2;
            }
            let inv2 = 1.0 / select(1.0, r2, ok);
            var w = inv2 * sqrt(inv2);
            if (params.law == 1u) {
                w = inv2 * inv2 * inv2 * sqrt(inv2);
            }
            f = f + select(0.0, p.z * w, ok) * r;
        }
        workgroupBarrier();
    }
    if (inside) {
        forces[i] = charges[i].y * f;
    }
}
