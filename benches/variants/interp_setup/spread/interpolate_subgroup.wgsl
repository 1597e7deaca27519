// template: composed with a window file (window_phi).
//
// Interpolation reducing each particle's segment with subgroup shuffles: a butterfly over
// min(segment, subgroup) lanes, then (segments wider than a subgroup) one workgroup-memory
// step. One barrier instead of log2(segment). Assumes full subgroups of consecutive
// invocations, as every driver gives for workgroups that are multiples of the subgroup.
#import spread/interpolate_common.wgsl

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32, @builtin(subgroup_size) sg: u32,
        @builtin(subgroup_invocation_id) lane: u32) {
    let seg = seg_size();
    let ppw = WG / seg;
    let first_slot = (wid.y * nwg.x + wid.x) * ppw;
    stencil_setup(first_slot, lid, ppw);
    workgroupBarrier();
    var v = vec4<f32>(stencil_w[lid % 384u]);
    let g = min(seg, sg);
    for (var o = g / 2u; o > 0u; o = o >> 1u) {
        v = v + subgroupShuffleXor(v, o);
    }
    // Segments wider than a subgroup: one partial per subgroup, combined below.
    if (seg > sg && lane == 0u) {
        partial[lid / sg] = v;
    }
    workgroupBarrier();
    if (seg <= sg) {
        if (lid % seg == 0u) {
            for (var c = 0u; c < COMPS; c = c + 1u) {
                store(lid / seg, c, v[c]);
            }
        }
    } else if (lid < ppw * COMPS) {
        let slot = lid / COMPS;
        let parts = seg / sg;
        var sum = 0.0;
        for (var j = 0u; j < parts; j = j + 1u) {
            sum = sum + partial[slot * parts + j][lid % COMPS];
        }
        store(slot, lid % COMPS, sum);
    }
}
