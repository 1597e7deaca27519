// template: nodes/slab_solve.rs prepends the constants WG, KS and POINTS, and WRITTEN_OUT
// with the function values_written_out (`written_out_transform`; empty where WRITTEN_OUT
// is false).
//
// slab_solve (nodes/slab_solve.rs): the doubly periodic Stokes solve of one wave number k
// from the forcing's Chebyshev coefficients to the velocity's values along z with the
// walls, the chain chebyshev_derivative, slab_pressure_source, chebyshev_bvp,
// chebyshev_derivative, slab_velocity_source, chebyshev_bvp, chebyshev (inverse),
// slab_walls in one kernel, up to `THREE_LINES_UP_TO` points (past them,
// slab_solve_line.wgsl: a thread per line). A workgroup takes KS wave numbers with 2
// threads each, one per part (real or imaginary) of the velocity: thread 2 slot + part,
// so a component's words of neighbouring k are read by neighbouring threads, the
// forcing's (re, im) pairs as one vec2 load (0.249 -> 0.231 ms at 10^6 spheres against
// two f32 loads, H100 2026-12-07 08:40Z). A thread holds its part's three velocity lines
// side by side in registers (Lane = vec3: x, y, z; the loops over a line,
// bounded by the constant POINTS, unroll), so each step runs on three lines at once and
// reads a per-k table entry once for them. The pressure couples the parts (i k p), so
// both threads of a k solve it whole, in lanes x (real) and y (imaginary): no pressure
// crosses between threads. Only the velocity's end values do, for the walls (one
// barrier). The end values are taken from the coefficients, so each value along z is
// written, with the walls' flow, as the inverse transform makes it: no line of values is
// held across the barrier.
// On an H100 (2026-12-07) this takes 0.231 ms at 10^6 spheres (31 points) where the
// thread-per-line kernel took 0.330: a third of the threads, each with three independent
// chains, and each table entry read once for three lines; past about 32 points the three
// lines no longer fit in registers (35 points: 0.42 ms against 0.27).
// f: (re, im) word pairs (c n + z) nk + k. out: word 2 ((c n + z) nk + k) + part.
// bvp: chebyshev_bvp's strided per-k tables.
// points: the inverse transform's matrix (n x n), zeta_j, the weights of dv/dz at the top
// from the values (slab_staged.wgsl's; this kernel takes the slope from the coefficients).
// minv: the slit's 6 x 6 complex inverse per k, word ((r 6 + c) 2 + part) nk + k.
#import common/index.wgsl
#import stokes_slab/slab.wgsl
#import chebyshev/slab_lines.wgsl
#import stokes_slab/wall_flow.wgsl
#import chebyshev/slab_fused.wgsl

// Three lines a thread (chebyshev/slab_lines.wgsl).
alias Lane = vec3<f32>;

@group(0) @binding(0) var<storage, read> f: array<vec2<f32>>;

// The velocity's values at the ends per (slot, part, component): top, bottom.
var<workgroup> velocity_ends: array<f32, KS * 12u>;

// Component c's coefficient z of k, complex.
fn forcing(c: u32, z: u32, k: u32) -> vec2<f32> {
    return f[(c * POINTS + z) * u.slab.nk + k];
}

// The velocity's value at end e (0 top, 1 bottom) of component c of slot `slot`.
fn velocity_end(slot: u32, c: u32, e: u32) -> vec2<f32> {
    return vec2<f32>(velocity_ends[((slot * 2u) * 3u + c) * 2u + e],
                     velocity_ends[((slot * 2u + 1u) * 3u + c) * 2u + e]);
}

// The velocity's values v (three components) at point j, with the walls' flow there, to
// `out` (out_word: component x's word).
fn put(j: u32, v: Lane) {
    let x = with_walls(j, v);
    let w = out_word + 2u * j * u.slab.nk;
    let component = 2u * POINTS * u.slab.nk;
    out[w] = x.x;
    out[w + component] = x.y;
    out[w + 2u * component] = x.z;
}

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let nk = u.slab.nk;
    let part = lid % 2u;
    let slot = lid / 2u;
    let k = (wid.y * nwg.x + wid.x) * KS + slot;
    // Threads past the last k skip the work but meet the barrier.
    let valid = k < nk;
    // (i z) of part `part` is sign z of the other part.
    let sign = select(-1.0, 1.0, part == 1u);
    let q = slab_wave(u.slab, k, true);
    let kk = slab_wave(u.slab, k, false);
    let kabs = length(kk);
    var top = Lane(0.0);
    var bottom = Lane(0.0);

    if (valid) {
        // The pressure, both parts (lanes x, y): p'' - k^2 p = i k.f + df_z/dz, decaying
        // conditions.
        for (var z = 0u; z < POINTS; z++) {
            line[z] = Lane(forcing(2u, z, k), 0.0);
        }
        differentiate_line();
        for (var z = 0u; z < POINTS; z++) {
            let ikf = times_i(q.x * forcing(0u, z, k) + q.y * forcing(1u, z, k));
            line[z] = u.f_scale * (Lane(ikf, 0.0) + line[z]);
        }
        solve(k, Lane(0.0), Lane(0.0));
        var p_top = Lane(0.0);
        var p_bottom = Lane(0.0);
        for (var z = 0u; z < POINTS; z++) {
            p_top += coef[z];
            p_bottom += select(coef[z], -coef[z], z % 2u == 1u);
        }

        // The velocity: eta (v'' - k^2 v) = (i k p, dp/dz) - f with the force-free
        // exterior's boundary values. Its sources from the pressure's coefficients, from
        // the top down: x, y take i k_c p (sign times the other part), z this part's
        // dp/dz, by chebyshev_derivative's recurrence d_(m-1) = d_(m+1) + 2 m p_m (d_0
        // halved).
        let scale = u.f_scale * u.slab.inv_eta;
        var next = 0.0;
        var here = 0.0;
        for (var i = 0u; i < POINTS; i++) {
            let m = POINTS - 1u - i;
            let p = coef[m];
            let own = select(p.x, p.y, part == 1u);
            let other = select(p.y, p.x, part == 1u);
            var dp = u.dz_scale * here;
            if (m == 0u) {
                dp = 0.5 * dp;
            } else {
                let prev = next + 2.0 * f32(m) * own;
                next = here;
                here = prev;
            }
            let fx = forcing(0u, m, k)[part];
            let fy = forcing(1u, m, k)[part];
            let fz = forcing(2u, m, k)[part];
            line[m] = scale * Lane(sign * q.x * other - fx, sign * q.y * other - fy, dp - fz);
        }
        var alpha = Lane(0.0);
        var beta = Lane(0.0);
        if (kabs != 0.0) {
            let h = 0.5 * u.slab.inv_eta * u.bc_scale;
            let own_top = select(p_top.x, p_top.y, part == 1u);
            let own_bottom = select(p_bottom.x, p_bottom.y, part == 1u);
            let other_top = select(p_top.y, p_top.x, part == 1u);
            let other_bottom = select(p_bottom.y, p_bottom.x, part == 1u);
            let g = sign * q * h / kabs;
            alpha = Lane(-g * other_top, h * own_top);
            beta = Lane(g * other_bottom, h * own_bottom);
        }
        solve(k, alpha, beta);
        // The values at the ends, top = sum c_m and bottom = sum (-1)^m c_m, as the
        // inverse transform's first row (entries 1) sums them: even terms, odd terms.
        var even = Lane(0.0);
        var odd = Lane(0.0);
        for (var m = 0u; m < POINTS; m += 2u) {
            even += coef[m];
        }
        for (var m = 1u; m < POINTS; m += 2u) {
            odd += coef[m];
        }
        top = even + odd;
        bottom = even - odd;
        for (var c = 0u; c < 3u; c++) {
            let e = ((slot * 2u + part) * 3u + c) * 2u;
            velocity_ends[e] = top[c];
            velocity_ends[e + 1u] = bottom[c];
        }
    }
    workgroupBarrier();
    if (!valid) {
        return;
    }

    // The walls (slab_walls) as this thread's value at zeta, v + (a1 zeta + b1)
    // exp(-|k| zeta) + (a2 zeta + b2) exp(|k| (zeta - H)) (`put`), from the end values of
    // the velocity's three components, both parts: its values along z are then written
    // as the inverse transform makes them, no line of them kept.
    out_word = word(0u, 0u, k) + part;
    out_kabs = kabs;
    let walls = u.slab.walls;
    if (kabs == 0.0) {
        // The k = 0 mode: zero but for the bottom wall's and the slit's shear flows (x,
        // y).
        out_keep = Lane(0.0);
        out_walls = true;
        if (walls != 0u) {
            out_keep = Lane(1.0, 1.0, 0.0);
            out_b1 = Lane(-bottom.xy, 0.0);
            if (walls == 1u) {
                // dv/dz at the top from the coefficients: (2 / H) sum m^2 c_m.
                var slope = Lane(0.0);
                for (var m = 1u; m < POINTS; m++) {
                    slope -= f32(m * m) * coef[m];
                }
                out_a1 = Lane(u.dz_scale * slope.xy, 0.0);
            } else {
                out_a1 = Lane((bottom.xy - top.xy) / u.slab.height, 0.0);
            }
        }
    } else if (walls != 0u) {
        out_walls = true;
        // The walls' constants and factors (stokes_slab/wall_flow.wgsl).
        let cd = wall_constants(walls, velocity_ends_at(slot, 1u), velocity_ends_at(slot, 0u), k);
        let ab = wall_factors(cd, kk, kabs);
        out_b1 = Lane(cd.c[0][part], cd.c[1][part], cd.c[2][part]);
        out_b2 = Lane(cd.d[0][part], cd.d[1][part], cd.d[2][part]);
        out_a1 = Lane(times_i(-kk.x * ab[0])[part], times_i(-kk.y * ab[0])[part], kabs * ab[0][part]);
        out_a2 = Lane(times_i(kk.x * ab[1])[part], times_i(kk.y * ab[1])[part], kabs * ab[1][part]);
    }
    // Values at the points, with the walls' flow (slab_fused.wgsl).
    if (WRITTEN_OUT) {
        values_written_out();
    } else {
        values_by_loop();
    }
}
