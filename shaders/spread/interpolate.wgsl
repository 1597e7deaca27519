// template: composed with a window file (window_phi).
//
// Interpolation with a workgroup-memory tree per particle segment (any adapter).
#import spread/interpolate_common.wgsl

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let seg = seg_size();
    let ppw = WG / seg;
    let first_slot = (wid.y * nwg.x + wid.x) * ppw;
    stencil_setup(first_slot, lid, ppw);
    workgroupBarrier();
    partial[lid] = column_sums(lid, seg, ppw);
    workgroupBarrier();
    for (var h = seg / 2u; h > 0u; h = h >> 1u) {
        if (lid % seg < h) {
            partial[lid] = partial[lid] + partial[lid + h];
        }
        workgroupBarrier();
    }
    if (lid < ppw * COMPS) {
        let slot = lid / COMPS;
        store(slot, lid % COMPS, partial[slot * seg][lid % COMPS]);
    }
}
