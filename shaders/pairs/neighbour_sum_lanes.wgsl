// template: composed after a pair kernel (pair_term, self_term; shaders/pairs/*.wgsl).
//
// neighbour_sum.wgsl with a segment of SEG subgroup lanes per particle (SEG a power of
// two, at most the subgroup): the lanes of a segment walk the same candidates, lane l
// taking every SEG-th, and add their sums by shuffles. One thread per particle left the
// GPU mostly idle at 10^4 particles (about 80 warps per SM-equivalent of latency, each
// thread walking 27 cells in its own loop); a segment keeps SEG times more threads in
// flight and walks each run of candidates in step.
//
// Candidates come in runs: the three cells along x of one (y, z) neighbour row are
// consecutive keys of the linear cell order, so their particles are one contiguous run of
// the sorted positions unless the row wraps across the periodic x face (then cell by
// cell). With a neighbour list (LIST_WIDTH > 0) a particle whose neighbours all fit it
// reads them from there instead.
#import common/index.wgsl
#import pairs/cells.wgsl
#import pairs/neighbour_sum_io.wgsl

override SEG: u32 = 8u;          // lanes per particle

// This lane's share of the candidates first..last (sorted slots) of particle i at xi.
fn run_sum(xi: vec3<f32>, vi: Row, i: u32, first: u32, last: u32, lane: u32) -> Row {
    var acc = row4(vec4<f32>(0.0));
    for (var j = first + lane; j < last; j += SEG) {
        let xj = load3(j);
        let r = minimum_image(xi - xj);
        let r2 = dot(r, r);
        if (j != i && r2 <= geo.cutoff2) {
            acc = row_add(acc, pair_term(xi, xj, r, r2, vi, value_row(j)));
        }
    }
    return acc;
}

// Particles of cells a..=b of one row (consecutive linear keys), slots clamped to the
// particles (`cell_slots`).
fn cells_run(xi: vec3<f32>, vi: Row, i: u32, a: u32, b: u32, lane: u32) -> Row {
    return run_sum(xi, vi, i, cell_slots(a).x, cell_slots(b).y, lane);
}

fn own_sum(i: u32, lane: u32) -> Row {
    let xi = load3(i);
    let vi = value_row(i);
    var acc = row4(vec4<f32>(0.0));
    if (LIST_WIDTH > 0u) {
        let m = list_count[i];
        if (m <= LIST_WIDTH) {
            for (var k = lane; k < m; k += SEG) {
                // A list from any indices port: entries clamped to the particles.
                let j = min(list[k * geo.n + i], geo.n - 1u);
                let xj = load3(j);
                let r = minimum_image(xi - xj);
                let r2 = dot(r, r);
                // A list built with a skin (a larger cutoff) holds pairs beyond this one.
                if (r2 <= geo.cutoff2) {
                    acc = row_add(acc, pair_term(xi, xj, r, r2, vi, value_row(j)));
                }
            }
            return acc;
        }
    }
    let per = geo.periodic.xyz == vec3<u32>(1u);
    let n = vec3<i32>(geo.cells.xyz);
    let c = cell_coords(keys[i]);
    let ox = offsets(c.x, n.x, per.x);
    let oy = offsets(c.y, n.y, per.y);
    let oz = offsets(c.z, n.z, per.z);
    let lo = c.x + ox.x;
    let hi = c.x + ox.y;
    let contiguous = lo >= 0 && hi < n.x;
    for (var dz = oz.x; dz <= oz.y; dz++) {
        let cz = (c.z + dz + n.z) % n.z;
        for (var dy = oy.x; dy <= oy.y; dy++) {
            let cy = (c.y + dy + n.y) % n.y;
            let row = n.x * (cy + n.y * cz);
            if (contiguous) {
                acc = row_add(acc, cells_run(xi, vi, i, u32(row + lo), u32(row + hi), lane));
            } else {
                for (var dx = ox.x; dx <= ox.y; dx++) {
                    let cell = u32((c.x + dx + n.x) % n.x + row);
                    acc = row_add(acc, cells_run(xi, vi, i, cell, cell, lane));
                }
            }
        }
    }
    return acc;
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32,
        @builtin(subgroup_invocation_id) sub_lane: u32) {
    let lane = sub_lane % SEG;
    let i = flat_index(wid, nwg, lid, 256u) / SEG;
    let live = i < geo.n;
    var acc = row4(vec4<f32>(0.0));
    if (live) {
        acc = own_sum(i, lane);
    }
    // Every lane reaches the shuffles (none returned): the segment's sum in each lane.
    for (var m = SEG / 2u; m > 0u; m >>= 1u) {
        acc.a += subgroupShuffleXor(acc.a, m);
        if (VALUE_COMPS > 4u || OUT_FIRST + OUT_COMPS > 4u) {
            acc.b += subgroupShuffleXor(acc.b, m);
        }
    }
    if (live && lane == 0u) {
        let xi = load3(i);
        store_out(i, row_add(acc, self_term(xi, value_row(i))));
    }
}
