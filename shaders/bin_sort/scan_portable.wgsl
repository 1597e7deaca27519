// bin_sort's one-workgroup scan (scan_common.wgsl), portable path: thread sums scanned in
// workgroup memory (scan/wg_inclusive.wgsl), no subgroup operations.
#import bin_sort/scan_common.wgsl
#import scan/wg_inclusive.wgsl

alias Elem = u32;

var<workgroup> ping: array<u32, 2048>;

@compute @workgroup_size(WG)
fn main(@builtin(local_invocation_index) t: u32) {
    let s = thread_sum(t);
    let half = wg_inclusive(t, s);
    // ping[half + t] is the inclusive sum of threads 0..=t.
    write_prefix(t, ping[half + t] - s);
}
