// template: composed with a window file (window_phi).
//
// Interpolation of particles sorted in space, box by box (see spread/box.wgsl): a
// workgroup takes up to P consecutive particles, copies the box of grid cells holding
// their supports into workgroup memory once (times the quadrature weights), then sums
// each particle's support from there: one thread per (particle, z index) sums its NS^2
// (x, y) cells, and a second step adds a particle's NS threads. A run whose box does not
// fit (larger than BMAX per axis, or more than BOX_VALUES values) reads the grid directly
// in the same layout. The adjoint of spread/spread_box.wgsl: the same weight tables.
#import common/index.wgsl
#import spread/geometry.wgsl
#import spread/box.wgsl

override NS: u32 = 4u;
override DIMS: u32 = 3u;
override COMPS: u32 = 1u;   // components in this dispatch (at most 4)
override TOTAL: u32 = 1u;   // components per particle
override HAS_WEIGHTS: bool = false;

const BOX_VALUES: u32 = 6144u;

@group(0) @binding(0) var<storage, read> pos: array<f32>;
@group(0) @binding(1) var<storage, read> grid: array<f32>;
@group(0) @binding(2) var<storage, read> quadrature: array<f32>;
@group(0) @binding(3) var<storage, read_write> out: array<f32>;
@group(0) @binding(4) var<uniform> geo: Geometry;

var<workgroup> box_g: array<f32, 6144>;        // box values, component-major, x fastest
var<workgroup> partial: array<vec4<f32>, 256>;
var<workgroup> box_load: i32;

fn dv(cell: u32) -> f32 {
    if (HAS_WEIGHTS) {
        return quadrature[cell];
    }
    return geo.dv;
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let p0 = (wid.y * nwg.x + wid.x) * P;
    let count = min(P, select(0u, geo.count - p0, p0 < geo.count));
    let b = box_setup(p0, count, lid);
    let cells = geo.n.w;
    let box_cells = b.n.x * b.n.y * b.n.z;
    if (lid == 0u) {
        box_load = select(0, 1, b.fits && box_cells * COMPS <= BOX_VALUES);
    }
    let use_box = workgroupUniformLoad(&box_load) == 1;
    if (use_box) {
        for (var e = lid; e < box_cells * COMPS; e = e + BOX_WG) {
            let c = e / box_cells;
            let r = e % box_cells;
            let cell = box_cell(b, r % b.n.x, (r / b.n.x) % b.n.y, r / (b.n.x * b.n.y));
            box_g[e] = grid[(geo.comp_offset + c) * cells + cell] * dv(cell);
        }
    }
    workgroupBarrier();
    // Threads per particle: one per z index of the support (one in 2D).
    let tpp = select(1u, NS, DIMS == 3u);
    let per_round = BOX_WG / tpp;
    for (var base = 0u; base < count; base = base + per_round) {
        let s = base + lid / tpp;
        let iz = lid % tpp;
        var acc = vec4<f32>(0.0);
        if (s < count && lid < per_round * tpp) {
            if (use_box) {
                let ox = u32(box_rel[s * 3u] - atomicLoad(&box_lo[0]));
                let oy = u32(box_rel[s * 3u + 1u] - atomicLoad(&box_lo[1]));
                var oz = 0u;
                if (DIMS == 3u) {
                    oz = u32(box_rel[s * 3u + 2u] - atomicLoad(&box_lo[2])) + iz;
                }
                let wx = (s * 3u) * BMAX;
                let wy = (s * 3u + 1u) * BMAX;
                let wz = box_w[(s * 3u + 2u) * BMAX + oz];
                for (var iy = 0u; iy < NS; iy = iy + 1u) {
                    let row = ((oz * b.n.y) + oy + iy) * b.n.x + ox;
                    var r = vec4<f32>(0.0);
                    for (var ix = 0u; ix < NS; ix = ix + 1u) {
                        let w = box_w[wx + ox + ix];
                        for (var c = 0u; c < COMPS; c = c + 1u) {
                            r[c] = fma(w, box_g[c * box_cells + row + ix], r[c]);
                        }
                    }
                    acc = fma(vec4<f32>(box_w[wy + oy + iy]), r, acc);
                }
                acc = acc * wz;
            } else {
                let wz = direct_weight(s, 2u, iz);
                for (var iy = 0u; iy < NS; iy = iy + 1u) {
                    let wy = direct_weight(s, 1u, iy);
                    for (var ix = 0u; ix < NS; ix = ix + 1u) {
                        let w = direct_weight(s, 0u, ix) * wy * wz;
                        let cell = direct_cell(s, ix, iy, iz);
                        let q = dv(cell);
                        for (var c = 0u; c < COMPS; c = c + 1u) {
                            acc[c] = fma(w * q, grid[(geo.comp_offset + c) * cells + cell], acc[c]);
                        }
                    }
                }
            }
        }
        partial[lid] = acc;
        workgroupBarrier();
        if (lid < per_round && base + lid < count) {
            var sum = vec4<f32>(0.0);
            for (var t = 0u; t < tpp; t = t + 1u) {
                sum = sum + partial[lid * tpp + t];
            }
            for (var c = 0u; c < COMPS; c = c + 1u) {
                out[(p0 + base + lid) * TOTAL + geo.comp_offset + c] = sum[c];
            }
        }
        workgroupBarrier();
    }
}
