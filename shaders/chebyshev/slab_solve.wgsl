// template: nodes/slab_solve.rs prepends the constants WG, KS, POINTS, HALF ((POINTS + 1)
// / 2) and POOL (the pool's words), and WRITTEN_OUT with the function sums_written_out
// (`written_out_sums`; empty where WRITTEN_OUT is false).
//
// slab_solve (nodes/slab_solve.rs): the doubly periodic Stokes solve of one wave number k
// from the forcing's Chebyshev coefficients to the velocity's values along z with the
// walls, the chain chebyshev_derivative, slab_pressure_source, chebyshev_bvp,
// chebyshev_derivative, slab_velocity_source, chebyshev_bvp, chebyshev (inverse),
// slab_walls in one kernel.
//
// Two threads share each line: one holds its even z (or Chebyshev index m), the other its
// odd ones, HALF words each in registers. Everything the solve does to a line keeps the
// parities apart but for three sums: chebyshev_bvp's banded elimination runs along each
// parity on its own, the coefficients of y (from the a's of y'') take a's of their own
// parity, the Chebyshev derivative takes the other parity's coefficients (read from
// memory: f, or the pressure in workgroup memory), and the boundary rows' sums r0, r1, the
// end values and the inverse transform's even and odd sums meet through workgroup memory.
// So each thread keeps half a line (half the registers of a thread per line: more threads
// resident) and half the serial chain.
//
// Threads: lid = ((parity 3 + component c) KS + slot) 2 + part, so with KS = 16 a warp of
// 32 is one (parity, component): the parity's branches are uniform, and a load of z reads
// 16 neighbouring k's words (re, im) in one run. The pressure is solved by component 0's
// threads (4 a k: part, parity) and handed to the others through workgroup memory.
// f, out: word 2 ((c n + z) nk + k) + part. bvp: chebyshev_bvp's strided per-k tables.
// points: the inverse transform's matrix (n x n), zeta_j, the weights of dv/dz at the top
// from the values (slab_staged.wgsl's; this kernel takes the slope from the coefficients).
// minv: the slit's 6 x 6 complex inverse per k, word ((r 6 + c) 2 + part) nk + k.
#import common/index.wgsl
#import stokes_slab/slab.wgsl
#import stokes_slab/slit.wgsl

struct Solve {
    slab: Slab,
    // (H/2)^2 on the sources, H/2 on the boundary values, 2 / H on a derivative.
    f_scale: f32,
    bc_scale: f32,
    dz_scale: f32,
    pad: u32,
}

@group(0) @binding(0) var<storage, read> f: array<f32>;
@group(0) @binding(1) var<storage, read_write> out: array<f32>;
@group(0) @binding(2) var<storage, read> bvp: array<f32>;
@group(0) @binding(3) var<storage, read> points: array<f32>;
@group(0) @binding(4) var<storage, read> minv_table: array<f32>;
@group(0) @binding(5) var<uniform> u: Solve;

// The pool, in two lives. Through the solves: the pressure's coefficients, word (slot 2 +
// part) POINTS + z, then each thread's partial boundary sums r0, r1 at PRESSURE_WORDS +
// 2 lid. After the velocity's solve: each thread's inverse-transform sums, word j WG +
// lid (no bank conflicts).
const PRESSURE_WORDS: u32 = 2u * POINTS * KS;
var<workgroup> pool: array<f32, POOL>;
// Each thread's partial end sum (its parity's coefficients summed) and partial slope
// (-sum m^2 c_m), words 2 lid and 2 lid + 1: the pressure's, then the velocity's.
var<workgroup> ends: array<f32, 2u * WG>;

// This thread's half line: word i is z (or m) = 2 i + parity; past the line's end, 0.
var<private> line: array<f32, HALF>;

fn entry(row: u32, k: u32) -> f32 {
    return bvp[row * u.slab.nk + k];
}

fn word(c: u32, z: u32, k: u32) -> u32 {
    return slab_word(c, z, k, POINTS, u.slab.nk);
}

fn minv(r: u32, c: u32, k: u32) -> vec2<f32> {
    let w = ((r * 6u + c) * 2u) * u.slab.nk + k;
    return vec2<f32>(minv_table[w], minv_table[w + u.slab.nk]);
}

fn cmul(a: vec2<f32>, b: vec2<f32>) -> vec2<f32> {
    return vec2<f32>(a.x * b.x - a.y * b.y, a.x * b.y + a.y * b.x);
}

// The thread of parity `parity` of (component c, slot, part).
fn thread_of(parity: u32, c: u32, slot: u32, part: u32) -> u32 {
    return ((parity * 3u + c) * KS + slot) * 2u + part;
}

// The k's pressure coefficient m of part `part` (0 past the end).
fn pressure_at(slot: u32, part: u32, m: u32) -> f32 {
    if (m >= POINTS) {
        return 0.0;
    }
    return pool[(slot * 2u + part) * POINTS + m];
}

// Coefficient m of the forcing's component c, part `part` (0 past the end).
fn forcing_at(c: u32, m: u32, k: u32, part: u32) -> f32 {
    if (m >= POINTS) {
        return 0.0;
    }
    return f[word(c, m, k) + part];
}

// The derivative's coefficients at this thread's parity into the line, times 2 / H
// (chebyshev_derivative's recurrence d_(m-1) = d_(m+1) + 2 m c_m from d_(n-1) = 0, d_0
// halved): they take the other parity's coefficients c_(z+1), read from `source` (0: the
// forcing's z component, part `part`; 1: the pressure's part `part`).
fn differentiate_half(source: u32, parity: u32, slot: u32, k: u32, part: u32) {
    var acc = 0.0;
    for (var t = 0u; t < HALF; t++) {
        let i = HALF - 1u - t;
        let z = 2u * i + parity;
        if (z < POINTS) {
            let m = z + 1u;
            var cm: f32;
            if (source == 0u) {
                cm = forcing_at(2u, m, k, part);
            } else {
                cm = pressure_at(slot, part, m);
            }
            acc = acc + 2.0 * f32(m) * cm;
            line[i] = u.dz_scale * acc;
        }
    }
    if (parity == 0u) {
        line[0] = 0.5 * line[0];
    }
}

// This thread's partial boundary sums r0 = -alpha + sum_z B0_z f_z, r1 = -beta + sum_z
// B1_z f_z over its parity (alpha and beta on the even thread's), to the pool.
fn boundary_sums(k: u32, parity: u32, lid: u32, alpha: f32, beta: f32) {
    var r0 = 0.0;
    var r1 = 0.0;
    if (parity == 0u) {
        r0 = -alpha;
        r1 = -beta;
    }
    for (var i = 0u; i < HALF; i++) {
        let z = 2u * i + parity;
        if (z < POINTS) {
            r0 += entry(3u * POINTS + z, k) * line[i];
            r1 += entry(4u * POINTS + z, k) * line[i];
        }
    }
    pool[PRESSURE_WORDS + 2u * lid] = r0;
    pool[PRESSURE_WORDS + 2u * lid + 1u] = r1;
}

// chebyshev_bvp's solve of k (shaders/chebyshev/bvp.wgsl) on this thread's parity, from
// the pair's boundary sums (even's + odd's, the same in both threads): leaves y's
// coefficients of this parity in the line and returns their sum.
fn solve_half(k: u32, parity: u32, even: u32, odd: u32) -> f32 {
    let r0 = pool[PRESSURE_WORDS + 2u * even] + pool[PRESSURE_WORDS + 2u * odd];
    let r1 = pool[PRESSURE_WORDS + 2u * even + 1u] + pool[PRESSURE_WORDS + 2u * odd + 1u];
    let y0 = entry(5u * POINTS, k) * r0 + entry(5u * POINTS + 1u, k) * r1;
    let p0 = entry(5u * POINTS + 2u, k) * r0 + entry(5u * POINTS + 3u, k) * r1;
    let kappa2 = entry(5u * POINTS + 4u, k);
    line[0] += kappa2 * select(p0, y0, parity == 0u);
    for (var i = 1u; i < HALF; i++) {
        let z = 2u * i + parity;
        if (z < POINTS) {
            line[i] -= entry(z, k) * line[i - 1u];
        }
    }
    for (var t = 0u; t < HALF; t++) {
        let i = HALF - 1u - t;
        let z = 2u * i + parity;
        if (z < POINTS) {
            var up = 0.0;
            if (z + 2u < POINTS) {
                up = entry(2u * POINTS + z, k) * line[i + 1u];
            }
            line[i] = (line[i] - up) * entry(POINTS + z, k);
        }
    }
    // y's coefficients from the a's of its own parity, in place: c_m = (y'_(m-1) -
    // y'_(m+1)) / (2 m) with y'_j = (a_(j-1) - a_(j+1)) / (2 j) (y'_1 = a_0 - a_2 / 2,
    // y'_0 = p0, 0 from n on), c_0 = y0.
    var below = 0.0;
    var sum = 0.0;
    for (var i = 0u; i < HALF; i++) {
        let m = 2u * i + parity;
        if (m < POINTS) {
            let here = line[i];
            var above = 0.0;
            if (i + 1u < HALF && m + 2u < POINTS) {
                above = line[i + 1u];
            }
            var v: f32;
            if (m == 0u) {
                v = y0;
            } else if (m == 1u) {
                var d2 = 0.0;
                if (2u < POINTS) {
                    d2 = (here - above) / 4.0;
                }
                v = p0 - 0.5 * d2;
            } else {
                var d_below: f32;
                if (m == 2u) {
                    d_below = below - 0.5 * here;
                } else {
                    d_below = (below - here) / (2.0 * f32(m - 1u));
                }
                var d_above = 0.0;
                if (m + 1u < POINTS) {
                    d_above = (here - above) / (2.0 * f32(m + 1u));
                }
                v = (d_below - d_above) / (2.0 * f32(m));
            }
            below = here;
            line[i] = v;
            sum += v;
        }
    }
    return sum;
}

// -sum m^2 c_m over this thread's parity.
fn slope_half(parity: u32) -> f32 {
    var slope = 0.0;
    for (var i = 0u; i < HALF; i++) {
        let m = 2u * i + parity;
        if (m < POINTS) {
            slope -= f32(m * m) * line[i];
        }
    }
    return slope;
}

// The velocity's values (top, bottom) at the ends of component c of slot `slot`, both
// parts: top = even + odd partial sums, bottom = even - odd.
fn velocity_end(slot: u32, c: u32, e: u32) -> vec2<f32> {
    var v: vec2<f32>;
    for (var part = 0u; part < 2u; part++) {
        let even = ends[2u * thread_of(0u, c, slot, part)];
        let odd = ends[2u * thread_of(1u, c, slot, part)];
        v[part] = select(even - odd, even + odd, e == 0u);
    }
    return v;
}

// This thread's output: its first word, the factor on the transform's value (0 where
// the k = 0 mode is zero) and the walls' flow (a1 zeta + b1) exp(-|k| zeta) + (a2 zeta +
// b2) exp(|k| (zeta - H)) for its part, where `out_walls`.
var<private> out_word: u32;
var<private> out_keep: f32 = 1.0;
var<private> out_walls: bool = false;
var<private> out_kabs: f32;
var<private> out_a1: f32;
var<private> out_b1: f32;
var<private> out_a2: f32;
var<private> out_b2: f32;

// The velocity's value v at point j, with the walls' flow there, to `out`.
fn put(j: u32, v: f32) {
    var x = v;
    if (out_walls) {
        let zeta = points[POINTS * POINTS + j];
        let decay = exp(-out_kabs * zeta);
        let grow = exp(out_kabs * (zeta - u.slab.height));
        x = out_keep * v + (out_a1 * zeta + out_b1) * decay + (out_a2 * zeta + out_b2) * grow;
    }
    out[out_word + 2u * j * u.slab.nk] = x;
}

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let nk = u.slab.nk;
    let part = lid % 2u;
    let slot = (lid / 2u) % KS;
    let c = (lid / (2u * KS)) % 3u;
    let parity = lid / (6u * KS);
    let k = (wid.y * nwg.x + wid.x) * KS + slot;
    let even = thread_of(0u, c, slot, part);
    let odd = thread_of(1u, c, slot, part);
    // Threads past the last k skip the work but meet every barrier.
    let valid = k < nk;
    let other = 1u - part;
    // (i z) of part `part` is sign z of the other part.
    let sign = select(-1.0, 1.0, part == 1u);
    let q = slab_wave(u.slab, k, true);
    let kk = slab_wave(u.slab, k, false);
    let kabs = length(kk);
    for (var i = 0u; i < HALF; i++) {
        line[i] = 0.0;
    }

    // The pressure: p'' - k^2 p = i k.f + df_z/dz, decaying conditions (component 0's
    // threads, a pair per part).
    let pressure_thread = c == 0u && valid;
    if (pressure_thread) {
        differentiate_half(0u, parity, slot, k, part);
        for (var i = 0u; i < HALF; i++) {
            let z = 2u * i + parity;
            if (z < POINTS) {
                let ikf = sign * (q.x * f[word(0u, z, k) + other] + q.y * f[word(1u, z, k) + other]);
                line[i] = u.f_scale * (ikf + line[i]);
            }
        }
        boundary_sums(k, parity, lid, 0.0, 0.0);
    }
    workgroupBarrier();
    if (pressure_thread) {
        ends[2u * lid] = solve_half(k, parity, even, odd);
        for (var i = 0u; i < HALF; i++) {
            let z = 2u * i + parity;
            if (z < POINTS) {
                pool[(slot * 2u + part) * POINTS + z] = line[i];
            }
        }
    }
    workgroupBarrier();

    // The velocity: eta (v'' - k^2 v) = (i k p, dp/dz) - f with the force-free
    // exterior's boundary values.
    if (valid) {
        let scale = u.f_scale * u.slab.inv_eta;
        if (c == 2u) {
            differentiate_half(1u, parity, slot, k, part);
            for (var i = 0u; i < HALF; i++) {
                let z = 2u * i + parity;
                if (z < POINTS) {
                    line[i] = scale * (line[i] - f[word(2u, z, k) + part]);
                }
            }
        } else {
            let qc = q[c];
            for (var i = 0u; i < HALF; i++) {
                let z = 2u * i + parity;
                if (z < POINTS) {
                    let p = pool[(slot * 2u + other) * POINTS + z];
                    line[i] = scale * (sign * qc * p - f[word(c, z, k) + part]);
                }
            }
        }
        var alpha = 0.0;
        var beta = 0.0;
        if (kabs != 0.0) {
            let h = 0.5 * u.slab.inv_eta * u.bc_scale;
            // The pressure's end values of part p: even + odd (top), even - odd (bottom).
            let p = select(other, part, c == 2u);
            let pe = ends[2u * thread_of(0u, 0u, slot, p)];
            let po = ends[2u * thread_of(1u, 0u, slot, p)];
            if (c == 2u) {
                alpha = h * (pe + po);
                beta = h * (pe - po);
            } else {
                let g = sign * q[c] * h / kabs;
                alpha = -g * (pe + po);
                beta = g * (pe - po);
            }
        }
        boundary_sums(k, parity, lid, alpha, beta);
    }
    workgroupBarrier();
    if (valid) {
        ends[2u * lid] = solve_half(k, parity, even, odd);
        ends[2u * lid + 1u] = slope_half(parity);
    }
    workgroupBarrier();

    // The walls (slab_walls) as this thread's value at zeta, v + (a1 zeta + b1)
    // exp(-|k| zeta) + (a2 zeta + b2) exp(|k| (zeta - H)) (`put`), from the end values of
    // the velocity's three components.
    if (valid) {
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
                    out_a1 = u.dz_scale * (ends[2u * even + 1u] + ends[2u * odd + 1u]);
                } else {
                    out_a1 = (bottom - top) / u.slab.height;
                }
            }
        } else if (walls != 0u) {
            out_walls = true;
            var big_c: array<vec2<f32>, 3>;
            var big_d: array<vec2<f32>, 3>;
            for (var i = 0u; i < 3u; i++) {
                big_c[i] = -velocity_end(slot, i, 1u);
                big_d[i] = vec2<f32>(0.0);
            }
            if (walls == 2u) {
                var w: array<vec2<f32>, 6>;
                for (var i = 0u; i < 3u; i++) {
                    w[i] = big_c[i];
                    w[3u + i] = -velocity_end(slot, i, 0u);
                }
                for (var i = 0u; i < 3u; i++) {
                    big_c[i] = slit_row(i, w, k);
                    big_d[i] = slit_row(3u + i, w, k);
                }
            }
            let a = big_c[2] - times_i(kk.x * big_c[0] + kk.y * big_c[1]) / kabs;
            let b = -big_d[2] - times_i(kk.x * big_d[0] + kk.y * big_d[1]) / kabs;
            out_b1 = big_c[c][part];
            out_b2 = big_d[c][part];
            if (c == 2u) {
                out_a1 = kabs * a[part];
                out_a2 = kabs * b[part];
            } else {
                out_a1 = times_i(-kk[c] * a)[part];
                out_a2 = times_i(kk[c] * b)[part];
            }
        }
    }
    // The inverse transform by parity: the points are symmetric (z_(n-1-j) = -z_j) and
    // T_m(-z) = (-1)^m T_m(z), so the even and the odd terms' sums at the upper half's
    // points give both halves. Each thread sums its parity's terms at the upper half's
    // points (HALF of them) into the pool; then the even thread writes the upper half,
    // even + odd, the odd thread the lower half, even - odd. Up to 64 points the host
    // writes the sums out with the matrix's entries as literals (`sums_written_out`).
    // (The pool's first life ended at the barrier above: its last reads were the
    // velocity's boundary sums.)
    if (valid) {
        if (WRITTEN_OUT) {
            sums_written_out(parity, lid);
        } else {
            for (var j = 0u; j < HALF; j++) {
                var s = 0.0;
                for (var i = 0u; i < HALF; i++) {
                    let m = 2u * i + parity;
                    if (m < POINTS) {
                        s += points[j * POINTS + m] * line[i];
                    }
                }
                pool[j * WG + lid] = s;
            }
        }
    }
    workgroupBarrier();
    if (!valid) {
        return;
    }
    for (var j = 0u; j < HALF; j++) {
        let e = pool[j * WG + even];
        let o = pool[j * WG + odd];
        if (parity == 0u) {
            put(j, e + o);
        } else if (POINTS - 1u - j != j) {
            put(POINTS - 1u - j, e - o);
        }
    }
}
