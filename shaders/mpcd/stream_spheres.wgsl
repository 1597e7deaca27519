// MPCD streaming with solid spheres, one thread per particle (3D). mpcd_stream's motion
// (body force along x, plates at +-L_z/2, periodic wrap) with no-slip bounce-back on S
// spheres moving at constant velocity through the step (fixed: at rest).
//
// Each pass takes the rest of the step: the plate crossing as in mpcd/stream_common.wgsl,
// and the chord from x to where the ballistic motion would end, P1 -> P2, intersected with
// every sphere in its own frame (S2 Eqs. 5.3-5.6: a f^2 + b f + c = 0 for the relative
// chord e = P2 - P1 - V t and r = P1 - C(t), the minimum image of the start relative to
// the centre; a hit at the smaller root f1 in (0, 1), taken as 2c / (-b + sqrt(b^2 - 4ac)),
// the same root without the cancellation of -b - sqrt(...) near the surface). The earliest
// event wins: at a sphere the particle moves to P1 + f1 (P2 - P1) on the surface, its
// velocity there v becomes 2 V - v (bounce-back relative to the surface), and the sphere
// receives m (v - v') = 2 m (v - V), added exactly to its 64-bit fixed-point impulse
// (units m v_th / 2^24). A sphere whose box [C - R, C + R] the chord's box cannot reach
// (|r_a| - |e_a| > R on some axis) costs a few comparisons only.
//
// Culling per workgroup: before streaming, the workgroup's threads bound their particles'
// starts (expanded by the largest reach |v| dt + |g| dt^2 among them) and list in
// workgroup memory the spheres whose path through the step (centre C + V t, t in [0, dt],
// plus R) meets that box; a particle whose chord stays inside the box tests only those.
// Where the particles are in cell order (sort_every) a workgroup's box is a few cells
// wide and most spheres drop out; otherwise the box spans the domain and all are kept.
// Exact either way: a chord outside the box (after a bounce, or a stray fast particle)
// or a list past CULL_CAP tests every sphere.
//
// With a reordering every few steps (nodes/mpcd/spheres.rs, sort_every), those steps run
// `stream_cell` (the streamed particles and their unshifted cells to scratch), a stable
// sort of the cells, then `gather` (the particles in cell order to the outputs).
#import common/index.wgsl
#import mpcd/common.wgsl

@group(0) @binding(0) var<uniform> m: Mpcd;
@group(0) @binding(1) var<uniform> sp: Spheres;
@group(0) @binding(2) var<storage, read> pos_in: array<f32>;
@group(0) @binding(3) var<storage, read> vel_in: array<f32>;
@group(0) @binding(4) var<storage, read> centres: array<f32>;
@group(0) @binding(5) var<storage, read> radii: array<f32>;
@group(0) @binding(6) var<storage, read> sphere_vel: array<f32>;
@group(0) @binding(7) var<storage, read_write> pos_out: array<f32>;
@group(0) @binding(8) var<storage, read_write> vel_out: array<f32>;
@group(0) @binding(9) var<storage, read_write> sums64: array<atomic<u32>>;
@group(0) @binding(10) var<storage, read_write> cell: array<u32>;
@group(0) @binding(11) var<storage, read> perm: array<u32>;

const CULL_CAP: u32 = 1024u;
var<workgroup> cull_list: array<u32, CULL_CAP>;
var<workgroup> cull_count: atomic<u32>;
var<workgroup> bound_lo: array<atomic<u32>, 3>;
var<workgroup> bound_hi: array<atomic<u32>, 3>;
var<workgroup> reach_bits: atomic<u32>;
// The box the list holds for (lo, hi), and whether the list is complete for it.
var<workgroup> cull_lo: vec3<f32>;
var<workgroup> cull_hi: vec3<f32>;

#import mpcd/spheres.wgsl
#import mpcd/add64.wgsl
#import mpcd/stream_common.wgsl

// Floats as u32 in the same order (atomicMin / atomicMax on them), and back.
fn ordered(f: f32) -> u32 {
    let b = bitcast<u32>(f);
    return select(b | 0x80000000u, ~b, (b & 0x80000000u) != 0u);
}

fn unordered(u: u32) -> f32 {
    return bitcast<f32>(select(~u, u & 0x7fffffffu, (u & 0x80000000u) != 0u));
}

// Lists the spheres that can meet the workgroup's particles this step (see the header).
// Called by every thread of the workgroup (uniform control flow); `valid`: a particle.
fn cull_spheres(lid: u32, valid: bool, x: vec3<f32>, v: vec3<f32>) {
    if (lid == 0u) {
        atomicStore(&cull_count, 0u);
        atomicStore(&reach_bits, 0u);
        for (var a = 0u; a < 3u; a = a + 1u) {
            atomicStore(&bound_lo[a], 0xffffffffu);
            atomicStore(&bound_hi[a], 0u);
        }
    }
    workgroupBarrier();
    if (valid) {
        for (var a = 0u; a < 3u; a = a + 1u) {
            atomicMin(&bound_lo[a], ordered(x[a]));
            atomicMax(&bound_hi[a], ordered(x[a]));
        }
        // A non-negative float's bits order as the float.
        atomicMax(&reach_bits, bitcast<u32>(length(v) * m.dt + abs(m.accel) * m.dt * m.dt));
    }
    workgroupBarrier();
    let reach = bitcast<f32>(atomicLoad(&reach_bits));
    var lo = vec3<f32>(0.0);
    var hi = vec3<f32>(0.0);
    for (var a = 0u; a < 3u; a = a + 1u) {
        lo[a] = unordered(atomicLoad(&bound_lo[a])) - reach;
        hi[a] = unordered(atomicLoad(&bound_hi[a])) + reach;
    }
    let mid = 0.5 * (lo + hi);
    let half = 0.5 * (hi - lo);
    for (var j = lid; j < sp.count; j = j + 256u) {
        let vs = sphere_velocity(j) * m.dt;
        let sweep = 0.5 * abs(vs) + vec3<f32>(radii[j]);
        let d = abs(min_image(sphere_centre(j) + 0.5 * vs - mid));
        // An axis culls only where a single image can meet the box (the nearest one), with
        // a margin for f32 rounding.
        let slack = half + sweep + vec3<f32>(1e-3 * m.cell);
        let single = 2.0 * slack < m.box.xyz;
        let periodic = vec3<bool>(true, true, m.walls == 0u);
        let apart = d > slack & (single | !periodic);
        if (!any(apart)) {
            let k = atomicAdd(&cull_count, 1u);
            if (k < CULL_CAP) {
                cull_list[k] = j;
            }
        }
    }
    if (lid == 0u) {
        cull_lo = lo;
        cull_hi = hi;
    }
    workgroupBarrier();
}

// The earliest sphere hit on the chord dx from x over time `left`, `now` into the step:
// (f1, sphere) or (1, S) when none. Only the workgroup's listed spheres where the chord
// stays inside the box they were listed for.
fn first_hit(x: vec3<f32>, dx: vec3<f32>, now: f32, left: f32) -> vec2<f32> {
    var best = 1.0;
    var hit = sp.count;
    let listed = atomicLoad(&cull_count);
    let y = x + dx;
    let inside = all(x >= cull_lo & x <= cull_hi & y >= cull_lo & y <= cull_hi);
    let use_list = inside && listed <= CULL_CAP;
    let count = select(sp.count, listed, use_list);
    for (var i = 0u; i < count; i = i + 1u) {
        let j = select(i, cull_list[i], use_list);
        let vs = sphere_velocity(j);
        let r = min_image(x - sphere_centre(j) - vs * now);
        let e = dx - vs * left;
        let rad = radii[j];
        if (any(abs(r) - abs(e) > vec3<f32>(rad))) {
            continue;
        }
        let a = dot(e, e);
        let b = 2.0 * dot(e, r);
        let c = dot(r, r) - rad * rad;
        let disc = b * b - 4.0 * a * c;
        if (b < 0.0 && c > 0.0 && disc > 0.0) {
            let f = 2.0 * c / (-b + sqrt(disc));
            if (f < best) {
                best = f;
                hit = j;
            }
        }
    }
    return vec2<f32>(best, bitcast<f32>(hit));
}

fn stream_with_spheres(xp: ptr<function, vec3<f32>>, vp: ptr<function, vec3<f32>>) {
    var x = *xp;
    var v = *vp;
    var g = m.accel;
    if (m.force_shape == 1u) {
        g = m.accel * sin(6.283185307179586 * x.z / m.box.z);
    }
    let h = 0.5 * m.box.z;
    var left = m.dt;
    for (var k = 0u; k < 16u && left > 0.0; k = k + 1u) {
        var hit = left;
        var wall = 0.0;
        if (m.walls == 1u) {
            if (v.z > 0.0) {
                hit = max((h - x.z) / v.z, 0.0);
                wall = h;
            } else if (v.z < 0.0) {
                hit = max((-h - x.z) / v.z, 0.0);
                wall = -h;
            }
        }
        var x2 = x;
        var v2 = v;
        advance(&x2, &v2, g, left);
        let dx = x2 - x;
        let found = first_hit(x, dx, m.dt - left, left);
        let j = bitcast<u32>(found.y);
        let ts = found.x * left;
        if (j < sp.count && ts < hit) {
            x = x + found.x * dx;
            v.x = v.x + g * ts;
            let out = 2.0 * sphere_velocity(j) - v;
            let q = (v - out) * m.fix_v;
            add64(6u * j, fx_of_signed(q.x));
            add64(6u * j + 2u, fx_of_signed(q.y));
            add64(6u * j + 4u, fx_of_signed(q.z));
            v = out;
            left = left - ts;
        } else if (hit >= left) {
            x = x2;
            v = v2;
            left = 0.0;
        } else {
            advance(&x, &v, g, hit);
            x.z = wall;
            if (m.wall_slip == 1u) {
                v.z = -v.z;
            } else {
                v = -v;
            }
            left = left - hit;
        }
    }
    if (m.walls == 1u) {
        x.z = clamp(x.z, -h, h);
    }
    for (var a = 0u; a < 3u; a = a + 1u) {
        if (m.walls == 0u || a != 2u) {
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

// Streams particle p and stores it (pos_out, vel_out): its new position and 1, or 0 past
// the last particle. Every thread of the workgroup calls it (the sphere list is built
// together, with barriers).
fn stream_and_store(p: u32, lid: u32) -> vec4<f32> {
    let valid = p < m.n;
    var r = array<vec3<f32>, 2>(vec3<f32>(0.0), vec3<f32>(0.0));
    if (valid) {
        r = load_row(p);
    }
    cull_spheres(lid, valid, r[0], r[1]);
    if (!valid) {
        return vec4<f32>(0.0);
    }
    var x = r[0];
    var v = r[1];
    stream_with_spheres(&x, &v);
    for (var a = 0u; a < 3u; a = a + 1u) {
        pos_out[p * 3u + a] = x[a];
        vel_out[p * 3u + a] = v[a];
    }
    return vec4<f32>(x, 1.0);
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    _ = stream_and_store(flat_index(wid, nwg, lid, 256u), lid);
}

// Streaming (pos_out, vel_out to scratch) and each particle's unshifted cell.
@compute @workgroup_size(256)
fn stream_cell(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
               @builtin(local_invocation_index) lid: u32) {
    let p = flat_index(wid, nwg, lid, 256u);
    let x = stream_and_store(p, lid);
    if (x.w > 0.0) {
        cell[p] = cell_of(m, x.xyz, vec3<f32>(0.0));
    }
}

// Output row p is streamed particle perm[p] (pos_in and vel_in are stream_cell's scratch).
@compute @workgroup_size(256)
fn gather(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
          @builtin(local_invocation_index) lid: u32) {
    let p = flat_index(wid, nwg, lid, 256u);
    if (p >= m.n) {
        return;
    }
    let q = perm[p];
    for (var a = 0u; a < 3u; a = a + 1u) {
        pos_out[p * 3u + a] = pos_in[q * 3u + a];
        vel_out[p * 3u + a] = vel_in[q * 3u + a];
    }
}
