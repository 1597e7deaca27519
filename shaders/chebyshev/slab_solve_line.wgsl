// template: nodes/slab_solve.rs prepends the constants WG, KS and POINTS, and WRITTEN_OUT
// with the function values_written_out (`written_out_transform`; empty where WRITTEN_OUT
// is false).
//
// slab_solve's kernel of a thread per line (nodes/slab_solve.rs), for lines longer than
// slab_solve.wgsl's three a thread fit in registers (past `THREE_LINES_UP_TO` points): the
// same solve. A workgroup takes KS wave numbers with 6 threads each, one per
// (component c, real or imaginary part), laid out c first, then k, then the part, so a
// component's words of KS neighbouring k are read by neighbouring threads. Each thread
// keeps its line (POINTS words, fixed when the kernel is built, so the loops unroll) in
// registers; the pressure (the threads of component 0 solve it, one per part) and the end
// values of the velocity cross between a k's threads through workgroup memory. The end
// values are taken from the coefficients before the inverse transform, so each value
// along z is written, with the walls' flow, as the transform makes it: no line of values
// is held across the barrier (on an H100: 0.531 -> 0.330 ms at 10^6 spheres).
// f, out: word 2 ((c n + z) nk + k) + part. bvp: chebyshev_bvp's strided per-k tables.
// points: the inverse transform's matrix (n x n), zeta_j, the weights of dv/dz at the top
// from the values (slab_staged.wgsl's; this kernel takes the slope from the coefficients).
// minv: the slit's 6 x 6 complex inverse per k, word ((r 6 + c) 2 + part) nk + k.
#import common/index.wgsl
#import stokes_slab/slab.wgsl
#import chebyshev/slab_lines.wgsl
#import stokes_slab/wall_flow.wgsl
#import chebyshev/slab_fused.wgsl

// A line a thread (chebyshev/slab_lines.wgsl).
alias Lane = f32;

@group(0) @binding(0) var<storage, read> f: array<f32>;

// The pressure's coefficients per (k slot, part), then its values at the ends per (slot,
// part): top, bottom; the velocity's values at the ends per (slot, component, part).
var<workgroup> pressure: array<f32, KS * 2u * POINTS>;
var<workgroup> pressure_ends: array<f32, KS * 4u>;
var<workgroup> velocity_ends: array<f32, KS * 12u>;

// The velocity's value at end e (0 top, 1 bottom) of component c of slot `slot`.
fn velocity_end(slot: u32, c: u32, e: u32) -> vec2<f32> {
    let b = slot * 6u + c * 2u;
    return vec2<f32>(velocity_ends[b * 2u + e], velocity_ends[(b + 1u) * 2u + e]);
}

// The velocity's value v at point j, with the walls' flow there, to `out`.
fn put(j: u32, v: Lane) {
    out[out_word + 2u * j * u.slab.nk] = with_walls(j, v);
}

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let n = POINTS;
    let nk = u.slab.nk;
    let part = lid % 2u;
    let slot = (lid / 2u) % KS;
    let c = lid / (2u * KS);
    let k = (wid.y * nwg.x + wid.x) * KS + slot;
    // Threads past the last k skip the work but meet every barrier.
    let valid = k < nk;
    let other = 1u - part;
    // (i z) of part `part` is sign z of the other part.
    let sign = select(-1.0, 1.0, part == 1u);
    let q = slab_wave(u.slab, k, true);
    let kk = slab_wave(u.slab, k, false);
    let kabs = length(kk);

    // The pressure: p'' - k^2 p = i k.f + df_z/dz, decaying conditions (component 0's
    // threads, one per part).
    if (c == 0u && valid) {
        for (var z = 0u; z < POINTS; z++) {
            line[z] = f[word(2u, z, k) + part];
        }
        differentiate_line();
        for (var z = 0u; z < POINTS; z++) {
            let ikf = sign * (q.x * f[word(0u, z, k) + other] + q.y * f[word(1u, z, k) + other]);
            line[z] = u.f_scale * (ikf + line[z]);
        }
        solve(k, 0.0, 0.0);
        var top = 0.0;
        var bottom = 0.0;
        let base = (slot * 2u + part) * n;
        for (var z = 0u; z < POINTS; z++) {
            let p = coef[z];
            pressure[base + z] = p;
            top += p;
            bottom += select(p, -p, z % 2u == 1u);
        }
        pressure_ends[(slot * 2u + part) * 2u] = top;
        pressure_ends[(slot * 2u + part) * 2u + 1u] = bottom;
    }
    workgroupBarrier();

    // The velocity: eta (v'' - k^2 v) = (i k p, dp/dz) - f with the force-free
    // exterior's boundary values, then its values along z.
    if (valid) {
        let scale = u.f_scale * u.slab.inv_eta;
        if (c == 2u) {
            let base = (slot * 2u + part) * n;
            for (var z = 0u; z < POINTS; z++) {
                line[z] = pressure[base + z];
            }
            differentiate_line();
            for (var z = 0u; z < POINTS; z++) {
                line[z] = scale * (line[z] - f[word(2u, z, k) + part]);
            }
        } else {
            let base = (slot * 2u + other) * n;
            let qc = q[c];
            for (var z = 0u; z < POINTS; z++) {
                line[z] = scale * (sign * qc * pressure[base + z] - f[word(c, z, k) + part]);
            }
        }
        var alpha = 0.0;
        var beta = 0.0;
        if (kabs != 0.0) {
            let h = 0.5 * u.slab.inv_eta * u.bc_scale;
            if (c == 2u) {
                alpha = h * pressure_ends[(slot * 2u + part) * 2u];
                beta = h * pressure_ends[(slot * 2u + part) * 2u + 1u];
            } else {
                let g = sign * q[c] * h / kabs;
                alpha = -g * pressure_ends[(slot * 2u + other) * 2u];
                beta = g * pressure_ends[(slot * 2u + other) * 2u + 1u];
            }
        }
        solve(k, alpha, beta);
        // The values at the ends, top = sum c_m and bottom = sum (-1)^m c_m, as the
        // inverse transform's first row (entries 1) sums them: even terms, odd terms.
        var even = 0.0;
        var odd = 0.0;
        for (var m = 0u; m < POINTS; m += 2u) {
            even += coef[m];
        }
        for (var m = 1u; m < POINTS; m += 2u) {
            odd += coef[m];
        }
        let e = (slot * 6u + c * 2u + part) * 2u;
        velocity_ends[e] = even + odd;
        velocity_ends[e + 1u] = even - odd;
    }
    workgroupBarrier();
    if (!valid) {
        return;
    }

    // The walls (slab_walls) as this thread's value at zeta, v + (a1 zeta + b1)
    // exp(-|k| zeta) + (a2 zeta + b2) exp(|k| (zeta - H)) (`put`), from the end values of
    // the velocity's three components: its values along z are then written as the inverse
    // transform makes them, no line of them kept.
    out_word = word(c, 0u, k) + part;
    out_kabs = kabs;
    let walls = u.slab.walls;
    if (kabs == 0.0) {
        // The k = 0 mode: zero but for the bottom wall's and the slit's shear flows.
        out_keep = 0.0;
        out_walls = true;
        let top = velocity_end(slot, c, 0u)[part];
        let bottom = velocity_end(slot, c, 1u)[part];
        if (c < 2u && walls != 0u) {
            out_keep = 1.0;
            out_b1 = -bottom;
            if (walls == 1u) {
                // dv/dz at the top from the coefficients: (2 / H) sum m^2 c_m.
                var slope = 0.0;
                for (var m = 1u; m < POINTS; m++) {
                    slope -= f32(m * m) * coef[m];
                }
                out_a1 = u.dz_scale * slope;
            } else {
                out_a1 = (bottom - top) / u.slab.height;
            }
        }
    } else if (walls != 0u) {
        out_walls = true;
        // The walls' constants and factors (stokes_slab/wall_flow.wgsl).
        let cd = wall_constants(walls, velocity_ends_at(slot, 1u), velocity_ends_at(slot, 0u), k);
        let ab = wall_factors(cd, kk, kabs);
        let a = ab[0];
        let b = ab[1];
        out_b1 = cd.c[c][part];
        out_b2 = cd.d[c][part];
        if (c == 2u) {
            out_a1 = kabs * a[part];
            out_a2 = kabs * b[part];
        } else {
            out_a1 = times_i(-kk[c] * a)[part];
            out_a2 = times_i(kk[c] * b)[part];
        }
    }
    // Values at the points, with the walls' flow (slab_fused.wgsl).
    if (WRITTEN_OUT) {
        values_written_out();
    } else {
        values_by_loop();
    }
}
