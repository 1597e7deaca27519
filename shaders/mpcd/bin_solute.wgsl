// MPCD binning of a solute (particles of mass M = ratio * m) into the cell sums of the
// solvent (mpcd_bin), one thread per solute particle. `copy` first writes the solvent's
// sums (cell blocks and, when present, energies), zero solute counts and the f32 bits of
// M / m; `main` then adds each solute particle: count + 1 in the solute block
// (solute_base + c), round(ratio v fix_v) to the cell's velocity sums and, with energies,
// round(ratio |v|^2 fix_e) to its energy sum (exact 64-bit
// integer sums, order independent), so the cell means become mass-weighted:
// u = (m sum v + M sum V) / (m n + M n_s). The grid shift is the solvent's (the same seed,
// stream and step), of width a for SRD and 2a for MPCD-BC (m.rule: give the node mpcd_bin's
// `rule`).
#import common/index.wgsl
#import mpcd/common.wgsl
#import mpcd/add64.wgsl

@group(0) @binding(0) var<uniform> m: Mpcd;
@group(0) @binding(1) var<storage, read> clock: array<u32>;
@group(0) @binding(2) var<storage, read> pos: array<f32>;
@group(0) @binding(3) var<storage, read> vel: array<f32>;
@group(0) @binding(4) var<storage, read> solvent: array<u32>;
@group(0) @binding(5) var<storage, read_write> cell: array<u32>;
@group(0) @binding(6) var<storage, read_write> sums64: array<atomic<u32>>;

@compute @workgroup_size(256)
fn copy(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    let words = solute_base(m);
    if (i < words) {
        atomicStore(&sums64[i], solvent[i]);
    } else if (i < words + m.ncells) {
        atomicStore(&sums64[i], 0u);
    } else if (i == words + m.ncells) {
        atomicStore(&sums64[i], bitcast<u32>(m.ratio));
    }
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let p = flat_index(wid, nwg, lid, 256u);
    if (p >= m.n) {
        return;
    }
    let s = grid_shift(m, clock[0]);
    var x = vec3<f32>(0.0);
    var v = vec3<f32>(0.0);
    for (var a = 0u; a < DIMS; a = a + 1u) {
        x[a] = pos[p * DIMS + a];
        v[a] = vel[p * DIMS + a];
    }
    let c = cell_of(m, x, s);
    cell[p] = c;
    let base = c * CELL_WORDS;
    atomicAdd(&sums64[solute_base(m) + c], 1u);
    for (var a = 0u; a < DIMS; a = a + 1u) {
        add64(base + SUM_V + 2u * a, fx_of_signed((v[a] * m.fix_v) * m.ratio));
    }
    if (m.energy == 1u) {
        add64(energy_word(m, c), fx_of_f32((dot(v, v) * m.fix_e) * m.ratio));
    }
}
