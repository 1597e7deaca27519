// Exclusive scan, portable path without subgroup operations (see scan/common.wgsl for the
// scheme). Thread t owns ROWS consecutive vec4s of its tile, sums them sequentially, and
// the thread sums are scanned in workgroup memory (Hillis-Steele, double-buffered).
#import common/index.wgsl
#import scan/common.wgsl
#import scan/wg_inclusive.wgsl

var<workgroup> ping: array<Elem, 512>;

fn thread_vec(tile: u32, t: u32) -> u32 {
    return tile * (TILE / 4u) + t * ROWS;
}

@compute @workgroup_size(256)
fn reduce(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
          @builtin(local_invocation_index) t: u32) {
    let tile = flat_index(wid, nwg, 0u, 1u);
    if (tile >= tiles()) {
        return;
    }
    let q = thread_vec(tile, t);
    var s = Elem(0);
    for (var r = 0u; r < ROWS; r++) {
        s += sum4(load4(q + r));
    }
    let half = wg_inclusive(t, s);
    if (t == 0u) {
        store_sum(tile, ping[half + WG - 1u]);
    }
}

@compute @workgroup_size(256)
fn downsweep(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
             @builtin(local_invocation_index) t: u32) {
    let tile = flat_index(wid, nwg, 0u, 1u);
    if (tile >= tiles()) {
        return;
    }
    let q = thread_vec(tile, t);
    var v: array<vec4<Elem>, ROWS>;
    var s = Elem(0);
    for (var r = 0u; r < ROWS; r++) {
        v[r] = load4(q + r);
        s += sum4(v[r]);
    }
    let half = wg_inclusive(t, s);
    var p = Elem(0);
    if (params.use_offsets != 0u) {
        p = offsets[tile];
    }
    if (t > 0u) {
        p += ping[half + t - 1u];
    }
    for (var r = 0u; r < ROWS; r++) {
        let o = prefix4(p, v[r]);
        store4(q + r, o);
        p = o.w + v[r].w;
    }
}
