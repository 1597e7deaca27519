// template: the workgroup-wide inclusive scan of the portable scan kernels
// (scan/portable.wgsl, bin_sort/scan_portable.wgsl), without subgroup operations. The
// importer declares `Elem`, `WG` (threads) and `var<workgroup> ping: array<Elem, 2 WG>`
// (at least).

// Inclusive scan of one value per thread (Hillis-Steele, double-buffered in `ping`);
// returns the half of `ping` (0 or WG) that holds the result.
fn wg_inclusive(t: u32, x: Elem) -> u32 {
    ping[t] = x;
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
    return half;
}
