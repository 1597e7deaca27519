// template: imported by spread/spread.wgsl and spread/interpolate.wgsl, which define NS,
// DIMS, pos, geo and (through a window file) window_phi.
//
// Stencil set-up shared by spreading and interpolation.
//
// A workgroup of 64 threads serves PPW particles: each particle gets a segment of SEG
// threads (SEG = NS^2 rounded up to a power of two, at most 64), and each thread of a
// segment owns one (x, y) column of the NS^3 support and walks it along z. The window
// weights and the wrapped cell offsets of every axis are computed once per particle into
// workgroup memory, so the inner loop is two loads, a multiply and an add per cell.
//
// Particles are taken in a decorrelated order: slot g serves particle
// (g % CHUNKS) * chunk + g / CHUNKS, so workgroups running at the same time work far apart
// even when the particles are sorted in space (sorted input otherwise piles every
// concurrent access onto the same few cache lines).

const WG: u32 = 64u;
const CHUNKS: u32 = 1024u;
const MAX_NS: u32 = 32u;
const MAX_PPW: u32 = 16u;

var<workgroup> stencil_w: array<f32, 1536>;   // MAX_PPW * 3 * MAX_NS weights
var<workgroup> stencil_o: array<u32, 1536>;   // wrapped cell offsets (times the axis stride)
var<workgroup> stencil_p: array<u32, 16>;     // particle of each slot (count: none)

fn seg_size() -> u32 {
    var s = 1u;
    loop {
        if (s >= NS * NS || s >= WG) { break; }
        s = s * 2u;
    }
    return s;
}

// Particle served by global slot g, or geo.count when the slot is empty.
fn slot_particle(g: u32) -> u32 {
    let chunk = (geo.count + CHUNKS - 1u) / CHUNKS;
    let p = (g % CHUNKS) * chunk + g / CHUNKS;
    return select(geo.count, p, p < geo.count);
}

// Fills the stencil tables of the PPW particles of this workgroup.
fn stencil_setup(first_slot: u32, lid: u32, ppw: u32) {
    if (lid < ppw) {
        stencil_p[lid] = slot_particle(first_slot + lid);
    }
    workgroupBarrier();
    let per = DIMS * NS;
    for (var e = lid; e < ppw * per; e = e + WG) {
        let s = e / per;
        let a = (e / NS) % DIMS;
        let k = e % NS;
        let p = stencil_p[s];
        var w = 0.0;
        var off = 0u;
        if (p < geo.count) {
            let t = centre_units(pos[p * DIMS + a], a, geo);
            let j0 = floor(t - 0.5 * f32(NS)) + 1.0;
            w = window_phi(j0 + f32(k) - t, geo.win[a]) * geo.inv_h[a];
            var stride = 1u;
            if (a >= 1u) { stride = geo.n.x; }
            if (a == 2u) { stride = geo.n.x * geo.n.y; }
            off = wrap_cell(i32(j0) + i32(k), geo.n[a]) * stride;
        }
        stencil_w[s * 3u * MAX_NS + a * MAX_NS + k] = w;
        stencil_o[s * 3u * MAX_NS + a * MAX_NS + k] = off;
    }
    workgroupBarrier();
}
