// template: imported by the box spreading kernel that nodes/spread/boxgen.rs generates,
// which defines NS, DIMS, pos, geo and (through a window file) window_phi.
//
// The box of a run of particles sorted in space: a workgroup takes up to P consecutive
// particles, and the box is the smallest block of cells (at most BMAX per axis) that
// holds all their supports, placed by the minimal image of each particle's first cell
// relative to particle 0's (so runs that straddle a periodic face stay compact). The
// window weights are tabulated box-relative and zero-padded: box_w[(s*3 + a)*BMAX + k]
// is particle s's weight at box cell k along axis a (0 outside its support; on the
// missing z axis of a 2D grid, 1 at k = 0). Spreading over the box is then a dense sum
// over box cells with no index arithmetic per particle.

const P: u32 = 64u;        // particles per workgroup, at most (geo.run of them: nodes/spread/mod.rs box_run)
const BMAX: u32 = 16u;     // box cells per axis, at most
const BOX_WG: u32 = 256u;  // threads per workgroup

var<workgroup> box_t: array<f32, 192>;       // position in cell-centre units, s*3 + a
var<workgroup> box_first: array<i32, 192>;   // first support cell (unwrapped), s*3 + a
var<workgroup> box_rel: array<i32, 192>;     // first cell relative to particle 0's (minimal image)
var<workgroup> box_lo: array<atomic<i32>, 3>;
var<workgroup> box_hi: array<atomic<i32>, 3>;
var<workgroup> box_shape: array<i32, 6>;     // n (3), origin (3)
var<workgroup> box_fits: i32;
var<workgroup> box_w: array<f32, 3072>;      // P * 3 * BMAX zero-padded weights
var<workgroup> box_wrap: array<u32, 48>;     // a*BMAX + k: wrapped cell of box cell k times the axis stride

struct Box {
    fits: bool,
    n: vec3<u32>,        // box cells per axis (1 on a missing axis)
    origin: vec3<i32>,   // unwrapped cell of box cell 0 per axis
}

// Sets up the box of particles p0 .. p0 + count and, when it fits, its weight table.
// Every thread of the workgroup must call it (it holds barriers).
fn box_setup(p0: u32, count: u32, lid: u32) -> Box {
    if (lid < 3u) {
        atomicStore(&box_lo[lid], 1 << 30u);
        atomicStore(&box_hi[lid], -(1 << 30u));
    }
    if (lid < count * DIMS) {
        let s = lid / DIMS;
        let a = lid % DIMS;
        let t = centre_units(pos[(p0 + s) * DIMS + a], a);
        box_t[s * 3u + a] = t;
        box_first[s * 3u + a] = first_cell(t);
    }
    workgroupBarrier();
    if (lid < count * DIMS) {
        let s = lid / DIMS;
        let a = lid % DIMS;
        let n = i32(geo.n[a]);
        var d = ((box_first[s * 3u + a] - box_first[a]) % n + n) % n;
        if (d >= (n + 1) / 2) {
            d = d - n;
        }
        box_rel[s * 3u + a] = d;
        atomicMin(&box_lo[a], d);
        atomicMax(&box_hi[a], d);
    }
    workgroupBarrier();
    if (lid == 0u) {
        var fits = 1;
        for (var a = 0u; a < 3u; a = a + 1u) {
            var n = 1;
            var origin = 0;
            if (a < DIMS) {
                let lo = atomicLoad(&box_lo[a]);
                n = atomicLoad(&box_hi[a]) - lo + i32(NS);
                origin = box_first[a] + lo;
            }
            box_shape[a] = n;
            box_shape[3u + a] = origin;
            if (n > i32(BMAX)) {
                fits = 0;
            }
        }
        box_fits = select(0, fits, count > 0u);
    }
    var b: Box;
    b.fits = workgroupUniformLoad(&box_fits) == 1;
    b.n = vec3<u32>(u32(box_shape[0]), u32(box_shape[1]), u32(box_shape[2]));
    b.origin = vec3<i32>(box_shape[3], box_shape[4], box_shape[5]);
    if (b.fits) {
        if (lid < 3u * BMAX) {
            let a = lid / BMAX;
            let k = i32(lid % BMAX);
            var stride = 1u;
            if (a >= 1u) { stride = geo.n.x; }
            if (a == 2u) { stride = geo.n.x * geo.n.y; }
            box_wrap[lid] = wrap_cell(b.origin[a] + k, geo.n[a]) * stride;
        }
        for (var e = lid; e < count * 3u * BMAX; e = e + BOX_WG) {
            let s = e / (3u * BMAX);
            let a = (e / BMAX) % 3u;
            let k = i32(e % BMAX);
            var w = 0.0;
            if (s < count) {
                if (a < DIMS) {
                    let o = k - (box_rel[s * 3u + a] - atomicLoad(&box_lo[a]));
                    if (o >= 0 && o < i32(NS)) {
                        let j = box_first[s * 3u + a] + o;
                        w = window_phi(f32(j) - box_t[s * 3u + a], geo.win[a]) * geo.inv_h[a];
                    }
                } else if (k == 0) {
                    w = 1.0;
                }
            }
            box_w[e] = w;
        }
    }
    workgroupBarrier();
    return b;
}

// Weight of particle s on axis a at support index k (computed from the tables, for the
// paths that do not use the box).
fn direct_weight(s: u32, a: u32, k: u32) -> f32 {
    if (a >= DIMS) {
        return select(0.0, 1.0, k == 0u);
    }
    let j = box_first[s * 3u + a] + i32(k);
    return window_phi(f32(j) - box_t[s * 3u + a], geo.win[a]) * geo.inv_h[a];
}

// Grid cell of particle s's support index (ix, iy, iz).
fn direct_cell(s: u32, ix: u32, iy: u32, iz: u32) -> u32 {
    let cx = wrap_cell(box_first[s * 3u] + i32(ix), geo.n.x);
    let cy = wrap_cell(box_first[s * 3u + 1u] + i32(iy), geo.n.y);
    var cz = 0u;
    if (DIMS == 3u) {
        cz = wrap_cell(box_first[s * 3u + 2u] + i32(iz), geo.n.z);
    }
    return cx + geo.n.x * (cy + geo.n.y * cz);
}
