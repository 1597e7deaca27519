// template: composed with a window file (window_phi) and an add file (grid_add, binding 2).
//
// Tiled spreading for particles sorted by cell (Morton or linear order): a workgroup takes
// P consecutive particles, whose supports overlap when the particles are close, adds
// their contributions into a box of cells in workgroup memory, then adds each touched
// cell to the grid once. The grid then sees one atomic per box cell instead of one per
// particle and support cell (about 6x fewer at support 8 and density 1).
//
// wgpu has no float atomics in workgroup memory, and compare-and-swap on the bits is
// slower than global float atomics (measured on an H100), so the box accumulates in
// fixed point with native i32 atomics: each workgroup scales its contributions so that
// the bound sum |F| max(w) over its particles maps to 2^30. No cell can overflow, and
// rounding costs at most P / 2^31 of that bound per cell, below f32 rounding of the
// largest cell. A workgroup whose particles do not fit a box of CAP cells (unsorted
// input) adds straight to the grid. One component per dispatch (geo.comp_offset).
#import common/index.wgsl
#import spread/geometry.wgsl

override NS: u32 = 8u;
override DIMS: u32 = 3u;
override TOTAL: u32 = 1u;   // components per particle
override P: u32 = 32u;      // particles per workgroup (P * DIMS * NS <= 1536)
const WG: u32 = 256u;
const CAP: u32 = 4096u;     // cells in the workgroup box

@group(0) @binding(0) var<storage, read> pos: array<f32>;
@group(0) @binding(1) var<storage, read> vals: array<f32>;
@group(0) @binding(3) var<uniform> geo: Geometry;

var<workgroup> acc: array<atomic<i32>, 4096>;
var<workgroup> weights: array<f32, 1536>;   // particle s, axis a, index k at s*DIMS*NS + a*NS + k
var<workgroup> first: array<i32, 96>;       // unwrapped first support cell, s*3 + a
var<workgroup> start: array<u32, 96>;       // first support cell inside the box, s*3 + a
var<workgroup> value: array<f32, 32>;
var<workgroup> box_lo: array<i32, 3>;       // box origin relative to particle 0's first cell
var<workgroup> box_n: array<u32, 3>;        // box cells per axis
var<workgroup> use_box: u32;
var<workgroup> bound: array<f32, 32>;       // |F| times the peak weight, per particle
var<workgroup> scale: f32;                  // fixed-point units per unit of the grid

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let p0 = (wid.y * nwg.x + wid.x) * P;
    let count = min(P, select(0u, geo.count - p0, p0 < geo.count));
    let per = DIMS * NS;
    // Window weights and first cells of the P particles.
    for (var e = lid; e < P * per; e = e + WG) {
        let s = e / per;
        let a = (e / NS) % DIMS;
        let k = e % NS;
        var w = 0.0;
        if (s < count) {
            let t = centre_units(pos[(p0 + s) * DIMS + a], a, geo);
            let j0 = floor(t - 0.5 * f32(NS)) + 1.0;
            w = window_phi(j0 + f32(k) - t, geo.win[a]) * geo.inv_h[a];
            if (k == 0u) {
                first[s * 3u + a] = i32(j0);
            }
        }
        weights[e] = w;
    }
    if (lid < P) {
        var v = 0.0;
        if (lid < count) {
            v = vals[(p0 + lid) * TOTAL + geo.comp_offset];
        }
        value[lid] = v;
    }
    workgroupBarrier();
    if (lid < count) {
        var peak = abs(value[lid]);
        for (var a = 0u; a < DIMS; a = a + 1u) {
            var m = 0.0;
            for (var k = 0u; k < NS; k = k + 1u) {
                m = max(m, abs(weights[lid * per + a * NS + k]));
            }
            peak = peak * m;
        }
        bound[lid] = peak;
    }
    // The box: along each axis, the span of the first cells (minimal image relative to
    // particle 0) plus the support.
    if (lid < DIMS && count > 0u) {
        let a = lid;
        let n = i32(geo.n[a]);
        var lo = 0;
        var hi = 0;
        for (var s = 0u; s < count; s = s + 1u) {
            var d = ((first[s * 3u + a] - first[a]) % n + n) % n;
            if (d >= n / 2) {
                d = d - n;
            }
            lo = min(lo, d);
            hi = max(hi, d);
            start[s * 3u + a] = u32(d);
        }
        box_lo[a] = lo;
        box_n[a] = u32(hi - lo) + NS;
        for (var s = 0u; s < count; s = s + 1u) {
            start[s * 3u + a] = u32(i32(start[s * 3u + a]) - lo);
        }
    }
    workgroupBarrier();
    if (lid == 0u) {
        var fits = count > 0u;
        var cells = 1u;
        for (var a = 0u; a < DIMS; a = a + 1u) {
            fits = fits && box_n[a] <= geo.n[a];
            cells = cells * box_n[a];
        }
        var total_bound = 0.0;
        for (var s = 0u; s < count; s = s + 1u) {
            total_bound = total_bound + bound[s];
        }
        // An empty (all-zero) run spreads nothing; 2^30 keeps one bit of headroom.
        fits = fits && total_bound > 0.0;
        scale = select(0.0, 1073741824.0 / total_bound, total_bound > 0.0);
        use_box = select(0u, 1u, fits && cells <= CAP);
        if (DIMS == 2u) {
            box_n[2] = 1u;
        }
    }
    let tiled = workgroupUniformLoad(&use_box) == 1u;
    let cells = geo.n.w;
    let nz = select(1u, NS, DIMS == 3u);
    if (tiled) {
        let bx = box_n[0];
        let by = box_n[1];
        let total = bx * by * box_n[2];
        for (var c = lid; c < total; c = c + WG) {
            atomicStore(&acc[c], 0);
        }
        let units = scale;
        workgroupBarrier();
        for (var q = lid; q < count * NS * NS; q = q + WG) {
            let s = q / (NS * NS);
            let ix = q % NS;
            let iy = (q / NS) % NS;
            let w0 = s * per;
            let wxy = weights[w0 + ix] * weights[w0 + NS + iy] * value[s] * units;
            let lxy = (start[s * 3u] + ix) + bx * (start[s * 3u + 1u] + iy);
            for (var iz = 0u; iz < nz; iz = iz + 1u) {
                var w = wxy;
                var lz = 0u;
                if (DIMS == 3u) {
                    w = w * weights[w0 + 2u * NS + iz];
                    lz = start[s * 3u + 2u] + iz;
                }
                atomicAdd(&acc[lxy + bx * by * lz], i32(round(w)));
            }
        }
        workgroupBarrier();
        let inv = 1.0 / units;
        for (var c = lid; c < total; c = c + WG) {
            let q = atomicLoad(&acc[c]);
            if (q != 0) {
                let v = f32(q) * inv;
                let lx = i32(c % bx) + box_lo[0] + first[0];
                let ly = i32((c / bx) % by) + box_lo[1] + first[1];
                var cz = 0u;
                if (DIMS == 3u) {
                    cz = wrap_cell(i32(c / (bx * by)) + box_lo[2] + first[2], geo.n.z);
                }
                let cell = wrap_cell(lx, geo.n.x) + geo.n.x * (wrap_cell(ly, geo.n.y) + geo.n.y * cz);
                grid_add(geo.comp_offset * cells + cell, v);
            }
        }
    } else {
        for (var q = lid; q < count * NS * NS; q = q + WG) {
            let s = q / (NS * NS);
            let ix = q % NS;
            let iy = (q / NS) % NS;
            let w0 = s * per;
            let wxy = weights[w0 + ix] * weights[w0 + NS + iy] * value[s];
            let cxy = wrap_cell(first[s * 3u] + i32(ix), geo.n.x) + geo.n.x * wrap_cell(first[s * 3u + 1u] + i32(iy), geo.n.y);
            for (var iz = 0u; iz < nz; iz = iz + 1u) {
                var w = wxy;
                var cz = 0u;
                if (DIMS == 3u) {
                    w = w * weights[w0 + 2u * NS + iz];
                    cz = wrap_cell(first[s * 3u + 2u] + i32(iz), geo.n.z);
                }
                grid_add(geo.comp_offset * cells + cxy + geo.n.x * geo.n.y * cz, w);
            }
        }
    }
}
