// bin_sort's one-workgroup scan (scan_common.wgsl), subgroup path: thread sums scanned by
// subgroupExclusiveAdd, subgroup totals through workgroup memory (one barrier). Needs
// full power-of-two subgroups of 4 to 128 lanes.
#import bin_sort/scan_common.wgsl

// One total per subgroup (at most 1024 / 4 subgroups).
var<workgroup> partial: array<u32, 256>;

// partial[0] + ... + partial[end - 1], by a whole subgroup in chunks of its width.
fn partial_sum_below(end: u32, nsg: u32, lane: u32, sg_size: u32) -> u32 {
    var acc = 0u;
    for (var c = 0u; c < nsg; c += sg_size) {
        let k = c + lane;
        var v = 0u;
        if (k < end) {
            v = partial[k];
        }
        acc += subgroupAdd(v);
    }
    return acc;
}

@compute @workgroup_size(WG)
fn main(@builtin(local_invocation_index) t: u32,
        @builtin(subgroup_id) sg: u32, @builtin(num_subgroups) nsg: u32,
        @builtin(subgroup_size) sg_size: u32, @builtin(subgroup_invocation_id) lane: u32) {
    let s = thread_sum(t);
    let ex = subgroupExclusiveAdd(s);
    let total = subgroupAdd(s);
    if (lane == 0u) {
        partial[sg] = total;
    }
    workgroupBarrier();
    write_prefix(t, ex + partial_sum_below(sg, nsg, lane, sg_size));
}
