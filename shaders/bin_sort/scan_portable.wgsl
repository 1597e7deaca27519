// bin_sort's one-workgroup scan (scan_common.wgsl), portable path: thread sums scanned in
// workgroup memory (Hillis-Steele, double-buffered), no subgroup operations.
#import bin_sort/scan_common.wgsl

var<workgroup> ping: array<u32, 2048>;

@compute @workgroup_size(WG)
fn main(@builtin(local_invocation_index) t: u32) {
    let s = thread_sum(t);
    ping[t] = s;
    workgroupBarrier();
    var half = 0u;
    for (var d = 1u; d < WG; d <<= 1u) {
        var y = ping[half + t];
        if (t >= d) {
            y = ping[half + t - d] + y;
        }
        ping[WG - half + t] = y;
        half = WG - half;
        workgroupBarrier();
    }
    // ping[half + t] is the inclusive sum of threads 0..=t.
    write_prefix(t, ping[half + t] - s);
}
