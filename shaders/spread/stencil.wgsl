// template: imported by spread/spread.wgsl and spread/interpolate.wgsl, which define NS,
// DIMS, pos, geo and (through a window file) window_phi.
//
// Stencil set-up shared by spreading and interpolation.
//
// A workgroup of WG threads (64, 128 or 256) serves PPW = WG / SEG particles: each
// particle gets a segment of SEG threads (SEG = NS^2 rounded up to a power of two, at
// most 64), and each thread of a
// segment owns one (x, y) column of the NS^3 support and walks it along z. The window
// weights and the wrapped cell offsets of every axis are computed once per particle into
// workgroup memory, so the inner loop is two loads, a multiply and an add per cell.
// Particles are taken in the decorrelated order of spread/slots.wgsl.

#import spread/slots.wgsl

override WG: u32 = 64u;

// Tables of the workgroup's particles: slot s, axis a, support index k at
// s*DIMS*NS + a*NS + k. 384 entries suffice: a segment holds at least NS^2 threads (or
// 64), so PPW * NS <= WG / NS and PPW * 3 * NS <= 3 * 256 / 2 = 384 (for NS > 8, PPW <= 4
// and NS <= 32).
var<workgroup> stencil_w: array<f32, 384>;  // window weights per unit length
var<workgroup> stencil_o: array<u32, 384>;  // wrapped cell offsets (times the axis stride)
var<workgroup> stencil_p: array<u32, 128>;  // particle of each slot (geo.count: none)

fn seg_size() -> u32 {
    var s = 1u;
    loop {
        if (s >= NS * NS || s >= 64u) { break; }
        s = s * 2u;
    }
    return s;
}

// Fills the stencil tables of the PPW particles of this workgroup. The caller puts one
// workgroupBarrier() after it (and after any other loads of its own).
fn stencil_setup(first_slot: u32, lid: u32, ppw: u32) {
    if (lid < ppw) {
        stencil_p[lid] = slot_particle(first_slot + lid);
    }
    let per = DIMS * NS;
    for (var e = lid; e < ppw * per; e = e + WG) {
        let s = e / per;
        let a = (e / NS) % DIMS;
        let k = e % NS;
        let p = slot_particle(first_slot + s);
        var w = 0.0;
        var off = 0u;
        if (p < geo.count) {
            let t = centre_units(pos[p * DIMS + a], a);
            let j0 = floor(t - 0.5 * f32(NS)) + 1.0;
            w = window_phi(j0 + f32(k) - t, geo.win[a]) * geo.inv_h[a];
            var stride = 1u;
            if (a >= 1u) { stride = geo.n.x; }
            if (a == 2u) { stride = geo.n.x * geo.n.y; }
            off = wrap_cell(i32(j0) + i32(k), geo.n[a]) * stride;
        }
        stencil_w[e] = w;
        stencil_o[e] = off;
    }
}
