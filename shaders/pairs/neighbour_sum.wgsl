// template: composed after a pair kernel (pair_term, self_term; shaders/pairs/*.wgsl).
//
// One thread per particle (in the cell list's sorted order): the self term, then every
// particle of the neighbouring cells (3 per axis, or the distinct ones on axes of fewer
// than 3 cells, or those inside on open axes) within the cutoff, minimum image on
// periodic axes. With a neighbour list (LIST_WIDTH > 0, from neighbour_list.wgsl) a
// particle whose neighbours all fit it reads them from there instead.
#import common/index.wgsl
#import pairs/cells.wgsl
#import pairs/neighbour_sum_io.wgsl


@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i >= geo.n) {
        return;
    }
    let xi = load3(i);
    let vi = value_row(i);
    var acc = self_term(xi, vi);
    let per = geo.periodic.xyz == vec3<u32>(1u);
    if (LIST_WIDTH > 0u) {
        let m = list_count[i];
        if (m <= LIST_WIDTH) {
            for (var k = 0u; k < m; k++) {
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
            store_out(i, acc);
            return;
        }
    }
    let n = vec3<i32>(geo.cells.xyz);
    let key = keys[i];
    let c = cell_coords(key);
    let ox = offsets(c.x, n.x, per.x);
    let oy = offsets(c.y, n.y, per.y);
    let oz = offsets(c.z, n.z, per.z);
    for (var dz = oz.x; dz <= oz.y; dz++) {
        let cz = (c.z + dz + n.z) % n.z;
        for (var dy = oy.x; dy <= oy.y; dy++) {
            let cy = (c.y + dy + n.y) % n.y;
            for (var dx = ox.x; dx <= ox.y; dx++) {
                let cx = (c.x + dx + n.x) % n.x;
                let cell = u32(cx + n.x * (cy + n.y * cz));
                let slots = cell_slots(cell);
                for (var j = slots.x; j < slots.y; j++) {
                    if (j == i) {
                        continue;
                    }
                    let xj = load3(j);
                    let r = minimum_image(xi - xj);
                    let r2 = dot(r, r);
                    if (r2 <= geo.cutoff2) {
                        acc = row_add(acc, pair_term(xi, xj, r, r2, vi, value_row(j)));
                    }
                }
            }
        }
    }
    store_out(i, acc);
}
