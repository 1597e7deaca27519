// MPCD collision, one thread per particle. SRD: v <- u + S R (v - u), u the cell mean
// from the cell sums, R the rotation by the angle about this cell's random axis (3D:
// uniform on the sphere, as two reflections; 2D: by +-angle), S the cell thermostat
// factor (1, plain rescaling of the relative velocities to kT, or the Monte-Carlo cell
// scaling). Each cell's draws come from one Philox block keyed by (seed, stream + j, step,
// cell), so every particle of a cell recomputes the same rotation without a pass over the
// cells. Wall-cut cells (`wall_cut`: the first and last layer along the walled axis with
// the grid shift; with MPCD-BC those of the first and last two that the plates cut)
// holding fewer than `density` solvent particles are filled up to it with virtual
// particles: u <- (n_m u + (M - n) q) / (n_m + M - n), n_m the cell's mass in units of m,
// q normal of variance kT / (m (M - n)) per component (the mean of M - n thermal
// particles); those cells skip the thermostat. MPCD-BC (rule 1): the thermostat, then
// `biased` below, where a wall-cut cell (this one or the partner) enters with its virtual
// particles' mean and mass (`filled`): the wall's cells are partners too. With a solute (m.solute = 1, sums from mpcd_bin_solute) u is the
// mass-weighted mean, the thermostat counts the relative energy and the degrees of freedom
// of both species, MPCD-BC takes the cells' masses in units of m for n1 and n2 (the counts
// without a solute; the pair reflection about the mass-weighted u_P conserves momentum
// and energy for any masses), and the same kernel run on the solute's velocities and cells
// applies the same rotation (or pair reflection) and scaling of each cell to it.
#import common/index.wgsl
#import mpcd/common.wgsl

@group(0) @binding(0) var<uniform> m: Mpcd;
@group(0) @binding(1) var<storage, read> clock: array<u32>;
@group(0) @binding(2) var<storage, read> vel: array<f32>;
@group(0) @binding(3) var<storage, read> cell: array<u32>;
@group(0) @binding(4) var<storage, read> sums: array<u32>;
@group(0) @binding(5) var<storage, read_write> vel_out: array<f32>;

fn cell_block(c: u32, step: u32, j: u32) -> vec4<u32> {
    return philox4x32_10(vec4<u32>(c, step, m.seed_hi, 0u), vec2<u32>(m.seed_lo, m.stream + j));
}

fn unit(w: u32) -> f32 {
    return f32(w >> 8u) * (1.0 / 16777216.0);
}

fn pair(i: u32) -> vec2<u32> {
    return vec2<u32>(sums[i], sums[i + 1u]);
}

// Cell c's mean velocity and mass in units of m (with a solute, its M / m-weighted count
// added: mpcd_bin_solute's layout).
fn cell_mean(c: u32) -> vec4<f32> {
    let base = c * CELL_WORDS;
    var n = f32(sums[base]);
    if (m.solute == 1u) {
        let sb = solute_base(m);
        n = n + bitcast<f32>(sums[sb + m.ncells]) * f32(sums[sb + c]);
    }
    var sv = vec3<f32>(0.0);
    for (var a = 0u; a < DIMS; a = a + 1u) {
        sv[a] = fx_to_f32(pair(base + SUM_V + 2u * a));
    }
    return vec4<f32>(sv / (select(1.0, n, n > 0.0) * m.fix_v), n);
}

// Whether the plates cut cell c in this step's grid: with SRD the first and last layer
// along the walled axis (the shift is within a/2); with MPCD-BC (L/a + 2 layers, shift s in
// [-a, a) drawn from mpcd_bin's stream) the layers whose extent [l - 1, l) a - s along the
// walled axis reaches past a plate: the first two and last two may be cut, or lie wholly
// in a wall (then they hold no particle and are all virtual).
fn wall_cut(c: u32, step: u32) -> bool {
    if (m.walls == 0u || m.shift == 0u) {
        return false;
    }
    let layer = cell_layer(m, c);
    let last = m.cells[DIMS - 1u] - 1u;
    if (m.rule == 0u) {
        return layer == 0u || layer == last;
    }
    let s = grid_shift_of(m, step, m.shift_stream)[DIMS - 1u] / m.cell;
    let lo = f32(layer) - 1.0 - s;
    return lo < 0.0 || lo + 1.0 > f32(last - 1u);
}

// Cell c's mean velocity and mass `um` (units of m) with the virtual particles of a
// wall-cut cell holding fewer than `density` solvent particles (Lamura et al.; S2 Eq. 4.9):
// u <- (n_m u + (M - n) q) / (n_m + M - n), q normal of variance kT / (m (M - n)) per
// component (the mean of M - n thermal particles), mass n_m + M - n; other cells as given.
fn filled(c: u32, step: u32, um: vec4<f32>) -> vec4<f32> {
    let n = f32(sums[c * CELL_WORDS]);
    if (m.ghosts == 0u || n >= m.density || !wall_cut(c, step)) {
        return um;
    }
    let g = cell_block(c, step, 2u);
    let r0 = sqrt(-2.0 * log(philox_open01(g.x)));
    let r1 = sqrt(-2.0 * log(philox_open01(g.z)));
    let t0 = 6.283185307179586 * philox_open01(g.y);
    let t1 = 6.283185307179586 * philox_open01(g.w);
    let q = vec3<f32>(r0 * cos(t0), r0 * sin(t0), r1 * cos(t1)) * sqrt(m.kt / (m.mass * (m.density - n)));
    var u = (um.w * um.xyz + (m.density - n) * q) / (um.w + m.density - n);
    if (DIMS == 2u) {
        u.z = 0.0;
    }
    return vec4<f32>(u, um.w + m.density - n);
}

// MPCD-BC (Ihle's biased collisions) for a particle of cell c with velocity v (after the
// thermostat), its cell of mass n1 (units of m: the count without a solute) and mean u1. The supercell (2 x 2 (x 2) cells)
// draws one collision type per step (3D: x, y, z, xy, xz, yz, xyz with weights 1/13 per
// direction: 1, 1, 1, 2, 2, 2, 4 thirteenths; 2D: x, y, diagonal with 1/4, 1/4, 1/2), which
// pairs every cell with the one across the type's direction. The pair collides with
// probability tanh(A du n1 n2) when du = s.(u1 - u2) > 0 (s the unit vector from this cell
// to its partner: the cells approach), one uniform per pair (keyed by its lower cell); a
// collision reverses the velocity components along s relative to the pair's mean velocity
// u_P: v <- v + 2 s (s.(u_P - v)), conserving the pair's momentum and energy.
fn biased(c: u32, step: u32, u1: vec3<f32>, n1: f32, v: vec3<f32>) -> vec3<f32> {
    let nx = m.cells.x;
    let ny = m.cells.y;
    var i = vec3<u32>(c % nx, (c / nx) % ny, 0u);
    if (DIMS == 3u) {
        i.z = c / (nx * ny);
    }
    let sc = (i.x >> 1u) + (nx >> 1u) * ((i.y >> 1u) + (ny >> 1u) * (i.z >> 1u));
    let t = unit(cell_block(sc, step, 3u).x);
    var flip = vec3<u32>(1u, 1u, 0u);
    if (DIMS == 3u) {
        let k = t * 13.0;
        if (k < 1.0) {
            flip = vec3<u32>(1u, 0u, 0u);
        } else if (k < 2.0) {
            flip = vec3<u32>(0u, 1u, 0u);
        } else if (k < 3.0) {
            flip = vec3<u32>(0u, 0u, 1u);
        } else if (k < 5.0) {
            flip = vec3<u32>(1u, 1u, 0u);
        } else if (k < 7.0) {
            flip = vec3<u32>(1u, 0u, 1u);
        } else if (k < 9.0) {
            flip = vec3<u32>(0u, 1u, 1u);
        } else {
            flip = vec3<u32>(1u, 1u, 1u);
        }
    } else if (t < 0.25) {
        flip = vec3<u32>(1u, 0u, 0u);
    } else if (t < 0.5) {
        flip = vec3<u32>(0u, 1u, 0u);
    }
    let j = i ^ flip;
    let cp = j.x + nx * (j.y + ny * j.z);
    let o = vec3<f32>(i & vec3<u32>(1u));
    let sgn = (vec3<f32>(1.0) - 2.0 * o) * vec3<f32>(flip);
    let s = sgn / sqrt(dot(sgn, sgn));
    let other = filled(cp, step, cell_mean(cp));
    let n2 = other.w;
    let du = dot(s, u1 - other.xyz);
    var p = 0.0;
    if (du > 0.0 && n2 > 0.0) {
        p = tanh(m.accept_a * du * n1 * n2);
    }
    let w = cell_block(min(c, cp), step, 4u);
    if (unit(w.x) < p) {
        let up = (n1 * u1 + n2 * other.xyz) / (n1 + n2);
        return v + 2.0 * s * dot(s, up - v);
    }
    return v;
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let p = flat_index(wid, nwg, lid, 256u);
    if (p >= m.n) {
        return;
    }
    let step = clock[0];
    let c = cell[p];
    let base = c * CELL_WORDS;
    let count = sums[base];
    let n = f32(count);
    // The cell's mass in units of m: n, plus (M / m) n_s with a solute (mpcd_bin_solute's
    // sums; the solute's velocity sums are already weighted by M / m).
    // count_all: particles of both species (the thermostat's degrees of freedom).
    var mass_n = n;
    var count_all = count;
    if (m.solute == 1u) {
        let sb = solute_base(m);
        mass_n = n + bitcast<f32>(sums[sb + m.ncells]) * f32(sums[sb + c]);
        count_all = count + sums[sb + c];
    }
    var sv = vec3<f32>(0.0);
    var v = vec3<f32>(0.0);
    for (var a = 0u; a < DIMS; a = a + 1u) {
        sv[a] = fx_to_f32(pair(base + SUM_V + 2u * a));
        v[a] = vel[p * DIMS + a];
    }
    var u = sv / (mass_n * m.fix_v);
    var rel = 0.0;
    if (m.thermostat != 0u) {
        rel = max(fx_to_f32(pair(energy_word(m, c))) / m.fix_e - mass_n * dot(u, u), 0.0);
    }
    var scale = 1.0;
    // A wall-cut cell with virtual particles: their mean and mass, no thermostat.
    var mass_eff = mass_n;
    if (m.ghosts == 1u && n < m.density && wall_cut(c, step)) {
        let f = filled(c, step, vec4<f32>(u, mass_n));
        u = f.xyz;
        mass_eff = f.w;
    } else if (m.thermostat != 0u && count_all >= 2u && rel > 0.0) {
        let dof = f32(DIMS * (count_all - 1u));
        if (m.thermostat == 1u) {
            scale = sqrt(dof * m.kt / (m.mass * rel));
        } else {
            let t = cell_block(c, step, 1u);
            let psi = 1.0 + m.mc_c * unit(t.x);
            let s = select(1.0 / psi, psi, unit(t.y) < 0.5);
            let log_accept = dof * log(s) - 0.5 * m.mass / m.kt * rel * (s * s - 1.0);
            if (log(philox_open01(t.z)) < log_accept) {
                scale = s;
            }
        }
    }
    let d = v - u;
    if (m.rule == 1u) {
        let out = biased(c, step, u, mass_eff, u + scale * d);
        for (var a = 0u; a < DIMS; a = a + 1u) {
            vel_out[p * DIMS + a] = out[a];
        }
        return;
    }
    let r = cell_block(c, step, 0u);
    var rd = vec3<f32>(0.0);
    if (DIMS == 3u) {
        let cz = 2.0 * unit(r.x) - 1.0;
        let phi = 6.283185307179586 * unit(r.y);
        let sz = sqrt(max(1.0 - cz * cz, 0.0));
        let k = vec3<f32>(sz * cos(phi), sz * sin(phi), cz);
        // The rotation about k by the angle as two reflections d -> d - 2 w (w.d) / (w.w),
        // across e1 and then across e1 cos(angle/2) + e2 sin(angle/2) (e1 = k x x or k x y,
        // e2 = k x e1): each keeps |d| whatever the lengths of k and w, so f32 rotations do
        // not heat or cool the fluid (Rodrigues' formula with an f32 axis of length
        // 1 + eps scales |d| by about 1 + eps in every collision).
        var e1 = cross(k, vec3<f32>(1.0, 0.0, 0.0));
        if (abs(k.x) > 0.5) {
            e1 = cross(k, vec3<f32>(0.0, 1.0, 0.0));
        }
        let e2 = cross(k, e1);
        let w2 = e1 * m.half_cos + e2 * m.half_sin;
        let d1 = d - e1 * (2.0 * dot(e1, d) / dot(e1, e1));
        rd = d1 - w2 * (2.0 * dot(w2, d1) / dot(w2, w2));
    } else {
        let sa = select(m.sin_a, -m.sin_a, (r.x & 0x80000000u) != 0u);
        rd = vec3<f32>(d.x * m.cos_a - d.y * sa, d.x * sa + d.y * m.cos_a, 0.0);
    }
    let out = u + scale * rd;
    for (var a = 0u; a < DIMS; a = a + 1u) {
        vel_out[p * DIMS + a] = out[a];
    }
}
