// template: composed after mpcd/sums_int64.wgsl or mpcd/sums_int32.wgsl (nodes/mpcd/collide.rs).
//
// MPCD binning, one thread per particle: the cell of each particle in the randomly shifted
// grid of this step, and per cell the count, sum v and (with `energy`) sum |v|^2 as exact
// 64-bit fixed-point sums (mpcd/bin_common.wgsl), by atomics. The sums start at zero (a
// fill before). The file composed before it declares binding 5 and the add_* functions.
#import common/index.wgsl
#import mpcd/common.wgsl

@group(0) @binding(0) var<uniform> m: Mpcd;
@group(0) @binding(1) var<storage, read> clock: array<u32>;
@group(0) @binding(2) var<storage, read> pos_in: array<f32>;
@group(0) @binding(3) var<storage, read> vel_in: array<f32>;
@group(0) @binding(4) var<storage, read_write> cell: array<u32>;

#import mpcd/bin_common.wgsl
#import mpcd/rows.wgsl

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let p = flat_index(wid, nwg, lid, 256u);
    if (p >= m.n) {
        return;
    }
    let r = load_row(p);
    bin_particle(p, r[0], r[1]);
}
