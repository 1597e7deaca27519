// template: composed after mpcd/sums_int64.wgsl or mpcd/sums_int32.wgsl (nodes/mpcd/stream_bin.rs).
//
// MPCD streaming and binning in one kernel, one thread per particle: the particle streams
// (mpcd/stream_common.wgsl), is written out, and is binned from the values in registers
// (mpcd/bin_common.wgsl): the same arithmetic as mpcd_stream then mpcd_bin, without the
// binning's second read of positions and velocities (24 bytes a particle in 3D) or its
// launch. The cell sums start at zero (a fill before).
//
// With a reordering every few steps (nodes/mpcd/stream_bin.rs), those steps run
// `stream_cell` instead (the streamed particles and their cells to scratch), a stable sort
// of the cells, then `gather_bin` (the particles in cell order to the outputs, binned),
// so that binning, collision and the next steps touch the cell sums in order.
#import common/index.wgsl
#import mpcd/common.wgsl

@group(0) @binding(0) var<uniform> m: Mpcd;
@group(0) @binding(1) var<storage, read> clock: array<u32>;
@group(0) @binding(2) var<storage, read> pos_in: array<f32>;
@group(0) @binding(3) var<storage, read> vel_in: array<f32>;
@group(0) @binding(4) var<storage, read_write> cell: array<u32>;
@group(0) @binding(6) var<storage, read_write> pos_out: array<f32>;
@group(0) @binding(7) var<storage, read_write> vel_out: array<f32>;
@group(0) @binding(8) var<storage, read> perm: array<u32>;
@group(0) @binding(9) var<storage, read> sorted_cells: array<u32>;

#import mpcd/stream_common.wgsl
#import mpcd/bin_common.wgsl

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let p = flat_index(wid, nwg, lid, 256u);
    if (p >= m.n) {
        return;
    }
    let xv = stream_row(p);
    bin_particle(p, xv[0], xv[1]);
}

// Streaming and cells only (pos_out, vel_out and cell are scratch here).
@compute @workgroup_size(256)
fn stream_cell(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
               @builtin(local_invocation_index) lid: u32) {
    let p = flat_index(wid, nwg, lid, 256u);
    if (p >= m.n) {
        return;
    }
    let xv = stream_row(p);
    cell[p] = cell_of(m, xv[0], grid_shift(m, clock[0]));
}

// Output row p is streamed particle perm[p] (pos_in and vel_in are stream_cell's scratch,
// sorted_cells its cells in sorted order), binned.
@compute @workgroup_size(256)
fn gather_bin(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
              @builtin(local_invocation_index) lid: u32) {
    let p = flat_index(wid, nwg, lid, 256u);
    if (p >= m.n) {
        return;
    }
    let q = perm[p];
    var v = vec3<f32>(0.0);
    for (var a = 0u; a < DIMS; a = a + 1u) {
        pos_out[p * DIMS + a] = pos_in[q * DIMS + a];
        v[a] = vel_in[q * DIMS + a];
        vel_out[p * DIMS + a] = v[a];
    }
    let c = sorted_cells[p];
    cell[p] = c;
    bin_add(c, v);
}
