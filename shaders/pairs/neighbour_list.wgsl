// The neighbour list of neighbour_list (nodes/pairs/mod.rs): the same cell walk as
// neighbour_sum.wgsl, recording each neighbour within the cutoff, neighbour k of
// particle i at list[k * N + i] (the first LIST_WIDTH of them; count holds them all).
#import common/index.wgsl
#import pairs/cells.wgsl

override LIST_WIDTH: u32 = 32u;

@group(0) @binding(0) var<storage, read> pos: array<f32>;
@group(0) @binding(1) var<storage, read> keys: array<u32>;
@group(0) @binding(2) var<storage, read> cell_start: array<u32>;
@group(0) @binding(3) var<storage, read> cell_count: array<u32>;
@group(0) @binding(4) var<storage, read_write> list: array<u32>;
@group(0) @binding(5) var<storage, read_write> count: array<u32>;
@group(0) @binding(6) var<uniform> geo: Geometry;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i >= geo.n) {
        return;
    }
    let xi = load3(i);
    let per = geo.periodic.xyz == vec3<u32>(1u);
    let n = vec3<i32>(geo.cells.xyz);
    let key = keys[i];
    let c = cell_coords(key);
    let ox = offsets(c.x, n.x, per.x);
    let oy = offsets(c.y, n.y, per.y);
    let oz = offsets(c.z, n.z, per.z);
    var found = 0u;
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
                    let r = displacement(xi, j);
                    if (dot(r, r) <= geo.cutoff2) {
                        if (found < LIST_WIDTH) {
                            list[found * geo.n + i] = j;
                        }
                        found++;
                    }
                }
            }
        }
    }
    count[i] = found;
}
