// bin_sort's one-workgroup scan, subgroup path. The counters are taken in QUADS chunks of
// WG vec4 each, thread t holding quad j * WG + t of chunk j, so every load and store is
// coalesced, and all QUADS loads are issued before anything waits on them (a thread
// walking its own 32 consecutive counters, one load after the other, took 28 us for
// 32768 bins on an H200: one L2 round trip per load). Each chunk's thread sums are
// scanned by subgroupExclusiveAdd and the subgroup totals of every chunk go through
// workgroup memory at once (one barrier). Needs full power-of-two subgroups of 4 to 128
// lanes. load4 / store4 come from scan_common.wgsl (zero and not written past `len`).
#import bin_sort/scan_common.wgsl

// vec4 of counters per thread (Shape.quads, at most 8).
override QUADS: u32 = 8u;

// One total per subgroup and chunk (at most 8 chunks x 1024 / 4 subgroups).
var<workgroup> partial: array<u32, 2048>;

@compute @workgroup_size(WG)
fn main(@builtin(local_invocation_index) t: u32,
        @builtin(subgroup_id) sg: u32, @builtin(num_subgroups) nsg: u32,
        @builtin(subgroup_size) sg_size: u32, @builtin(subgroup_invocation_id) lane: u32) {
    var v: array<vec4<u32>, 8>;
    for (var j = 0u; j < QUADS; j++) {
        v[j] = load4(j * WG + t);
    }
    var ex: array<u32, 8>;
    for (var j = 0u; j < QUADS; j++) {
        let s = (v[j].x + v[j].y) + (v[j].z + v[j].w);
        ex[j] = subgroupExclusiveAdd(s);
        let total = subgroupAdd(s);
        if (lane == 0u) {
            partial[j * nsg + sg] = total;
        }
    }
    workgroupBarrier();
    // Chunk j starts after every earlier chunk; inside it, this subgroup after the
    // subgroups before it.
    var base = 0u;
    for (var j = 0u; j < QUADS; j++) {
        var below = 0u;
        var total = 0u;
        for (var c = 0u; c < nsg; c += sg_size) {
            let k = c + lane;
            var x = 0u;
            if (k < nsg) {
                x = partial[j * nsg + k];
            }
            below += subgroupAdd(select(0u, x, k < sg));
            total += subgroupAdd(x);
        }
        let p = base + below + ex[j];
        let y = p + v[j].x;
        let z = y + v[j].y;
        store4(j * WG + t, v[j], vec4<u32>(p, y, z, z + v[j].z));
        base += total;
    }
}
