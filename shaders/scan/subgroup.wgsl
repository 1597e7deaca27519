// Exclusive scan, subgroup path (see scan/common.wgsl for the scheme). Each subgroup owns
// a contiguous run of ROWS * subgroup_size vec4s, read lane-striped (coalesced); rows are
// scanned with subgroupExclusiveAdd and carried in registers, so the workgroup needs one
// barrier. Works for any subgroup size from 4 to 128 that fills its subgroups.
#import common/index.wgsl
#import scan/common.wgsl

// One total per subgroup (at most WG / 4 subgroups).
var<workgroup> partial: array<Elem, 64>;

// partial[0] + ... + partial[end - 1], computed by a whole subgroup in chunks of its
// width, so that any number of subgroups works with any subgroup size.
fn partial_sum_below(end: u32, nsg: u32, lane: u32, sg_size: u32) -> Elem {
    var acc = Elem(0);
    for (var c = 0u; c < nsg; c += sg_size) {
        let k = c + lane;
        var v = Elem(0);
        if (k < end) {
            v = partial[k];
        }
        acc += subgroupAdd(v);
    }
    return acc;
}

// First vec4 of this lane: subgroup `sg` owns ROWS * sg_size consecutive vec4s of the tile.
fn first_vec(tile: u32, sg: u32, lane: u32, sg_size: u32) -> u32 {
    return tile * (TILE / 4u) + sg * ROWS * sg_size + lane;
}

@compute @workgroup_size(256)
fn reduce(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
          @builtin(subgroup_id) sg: u32, @builtin(num_subgroups) nsg: u32,
          @builtin(subgroup_size) sg_size: u32, @builtin(subgroup_invocation_id) lane: u32) {
    let tile = flat_index(wid, nwg, 0u, 1u);
    if (tile >= tiles()) {
        return;
    }
    let q = first_vec(tile, sg, lane, sg_size);
    var v: array<vec4<Elem>, ROWS>;
    if (tile_is_full(tile)) {
        for (var r = 0u; r < ROWS; r++) {
            v[r] = src[q + r * sg_size];
        }
    } else {
        for (var r = 0u; r < ROWS; r++) {
            v[r] = load4(q + r * sg_size);
        }
    }
    var s = Elem(0);
    for (var r = 0u; r < ROWS; r++) {
        s += sum4(v[r]);
    }
    let t = subgroupAdd(s);
    if (lane == 0u) {
        partial[sg] = t;
    }
    workgroupBarrier();
    let total = partial_sum_below(nsg, nsg, lane, sg_size);
    if (sg == 0u && lane == 0u) {
        store_sum(tile, total);
    }
}

@compute @workgroup_size(256)
fn downsweep(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
             @builtin(subgroup_id) sg: u32, @builtin(num_subgroups) nsg: u32,
             @builtin(subgroup_size) sg_size: u32, @builtin(subgroup_invocation_id) lane: u32) {
    let tile = flat_index(wid, nwg, 0u, 1u);
    if (tile >= tiles()) {
        return;
    }
    let q = first_vec(tile, sg, lane, sg_size);
    let full = tile_is_full(tile);
    var v: array<vec4<Elem>, ROWS>;
    if (full) {
        for (var r = 0u; r < ROWS; r++) {
            v[r] = src[q + r * sg_size];
        }
    } else {
        for (var r = 0u; r < ROWS; r++) {
            v[r] = load4(q + r * sg_size);
        }
    }
    var ex: array<Elem, ROWS>;
    var carry = Elem(0);
    for (var r = 0u; r < ROWS; r++) {
        let s = sum4(v[r]);
        ex[r] = carry + subgroupExclusiveAdd(s);
        carry += subgroupAdd(s);
    }
    if (lane == 0u) {
        partial[sg] = carry;
    }
    var base = Elem(0);
    if (params.use_offsets != 0u) {
        base = offsets[tile];
    }
    workgroupBarrier();
    base += partial_sum_below(sg, nsg, lane, sg_size);
    if (full) {
        for (var r = 0u; r < ROWS; r++) {
            dst[q + r * sg_size] = prefix4(base + ex[r], v[r]);
        }
    } else {
        for (var r = 0u; r < ROWS; r++) {
            store4(q + r * sg_size, prefix4(base + ex[r], v[r]));
        }
    }
}
