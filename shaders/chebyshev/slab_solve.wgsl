// template: nodes/slab_solve.rs prepends the constants WG, KS, POINTS and Q.
//
// slab_solve (nodes/slab_solve.rs): the doubly periodic Stokes solve of one wave number k
// from the forcing's Chebyshev coefficients to the velocity's values along z with the
// walls, the chain chebyshev_derivative, slab_pressure_source, chebyshev_bvp,
// chebyshev_derivative, slab_velocity_source, chebyshev_bvp, chebyshev (inverse),
// slab_walls in one kernel. A workgroup takes KS wave numbers and WG threads (a multiple
// of 6 KS). The solves: the first 6 KS threads, one per line (component c, real or
// imaginary part), lid = (c KS + slot) 2 + part, so a component's words of KS
// neighbouring k are read by neighbouring threads; each keeps its line (POINTS words,
// fixed when the kernel is built, so the loops unroll) in registers; the pressure (the
// threads of component 0 solve it, one per part) and the end values of the velocity cross
// between a k's threads through workgroup memory. The velocity's coefficients then go to
// workgroup memory (vec4s along m) and all WG threads share the dense inverse transform
// and the walls: output (c, z, slot, part) by thread lid, lid + WG, ... (neighbouring
// threads write neighbouring words).
// f, out: word 2 ((c n + z) nk + k) + part. bvp: chebyshev_bvp's strided per-k tables.
// points: the inverse transform's matrix (n rows of Q vec4s, zero past n), then zeta_j.
// minv: the slit's 6 x 6 complex inverse per k, word ((r 6 + c) 2 + part) nk + k.
#import common/index.wgsl
#import stokes_slab/slab.wgsl

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
@group(0) @binding(3) var<storage, read> points: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> minv_table: array<f32>;
@group(0) @binding(5) var<uniform> u: Solve;

const LINES: u32 = 6u * KS;

// The lines' words: first the pressure's coefficients, word (slot 2 + part) n + z, then
// (once every thread has read them) the velocity's coefficients, vec4 q m / 4 + line at
// q LINES + line. The pressure's values at the ends per (slot, part): top, bottom; the
// velocity's values at the ends per (slot, component, part); the k = 0 slope per line
// (slot 6 + c 2 + part); the walls' C and D per (slot, component), then a and b per slot.
var<workgroup> lines: array<vec4<f32>, Q * LINES>;
var<workgroup> pressure_ends: array<f32, KS * 4u>;
var<workgroup> velocity_ends: array<f32, KS * 12u>;
var<workgroup> slopes: array<f32, KS * 6u>;
var<workgroup> wall_cd: array<vec2<f32>, KS * 6u>;
var<workgroup> wall_ab: array<vec2<f32>, KS * 2u>;

// This thread's line, and the solve's coefficients of y.
var<private> line: array<f32, POINTS>;
var<private> coef: array<f32, POINTS>;

fn point_word(i: u32) -> f32 {
    return points[i / 4u][i % 4u];
}

fn pressure_at(i: u32) -> f32 {
    return lines[i / 4u][i % 4u];
}

fn entry(row: u32, k: u32) -> f32 {
    return bvp[row * u.slab.nk + k];
}

fn word(c: u32, z: u32, k: u32) -> u32 {
    return slab_word(c, z, k, POINTS, u.slab.nk);
}

// The line's derivative coefficients in place, times 2 / H (chebyshev_derivative's
// recurrence d_{m-1} = d_{m+1} + 2 m c_m from d_{n-1} = 0, d_0 halved).
fn differentiate_line() {
    var next = 0.0;
    var here = 0.0;
    for (var i = 0u; i + 1u < POINTS; i++) {
        let m = POINTS - 1u - i;
        let cm = line[m];
        line[m] = u.dz_scale * here;
        let prev = next + 2.0 * f32(m) * cm;
        next = here;
        here = prev;
    }
    line[0] = u.dz_scale * 0.5 * here;
}

// chebyshev_bvp's solve of k (shaders/chebyshev/bvp.wgsl): the line holds f (scaled by
// (H/2)^2), alpha and beta are scaled; leaves y's coefficients in coef.
fn solve(k: u32, alpha: f32, beta: f32) {
    let n = POINTS;
    var r0 = -alpha;
    var r1 = -beta;
    for (var z = 0u; z < n; z++) {
        r0 += entry(3u * n + z, k) * line[z];
        r1 += entry(4u * n + z, k) * line[z];
    }
    let y0 = entry(5u * n, k) * r0 + entry(5u * n + 1u, k) * r1;
    let p0 = entry(5u * n + 2u, k) * r0 + entry(5u * n + 3u, k) * r1;
    let kappa2 = entry(5u * n + 4u, k);
    line[0] += kappa2 * y0;
    if (n > 1u) {
        line[1] += kappa2 * p0;
    }
    for (var z = 2u; z < n; z++) {
        line[z] -= entry(z, k) * line[z - 2u];
    }
    for (var i = 0u; i < n; i++) {
        let z = n - 1u - i;
        var up = 0.0;
        if (z + 2u < n) {
            up = entry(2u * n + z, k) * line[z + 2u];
        }
        line[z] = (line[z] - up) * entry(n + z, k);
    }
    for (var m = 0u; m < n; m++) {
        var v: f32;
        if (m == 0u) {
            v = y0;
        } else if (m == 1u) {
            v = p0 - 0.5 * derivative(2u, p0);
        } else {
            v = (derivative(m - 1u, p0) - derivative(m + 1u, p0)) / (2.0 * f32(m));
        }
        coef[m] = v;
    }
}

// a_j of the line (0 past the end).
fn a_at(j: u32) -> f32 {
    if (j >= POINTS) {
        return 0.0;
    }
    return line[j];
}

// y'_m from the a's (0 for m >= n).
fn derivative(m: u32, p0: f32) -> f32 {
    if (m >= POINTS) {
        return 0.0;
    }
    if (m == 0u) {
        return p0;
    }
    if (m == 1u) {
        return a_at(0u) - 0.5 * a_at(2u);
    }
    return (a_at(m - 1u) - a_at(m + 1u)) / (2.0 * f32(m));
}

fn cmul(a: vec2<f32>, b: vec2<f32>) -> vec2<f32> {
    return vec2<f32>(a.x * b.x - a.y * b.y, a.x * b.y + a.y * b.x);
}

fn minv(r: u32, c: u32, k: u32) -> vec2<f32> {
    let w = ((r * 6u + c) * 2u) * u.slab.nk + k;
    return vec2<f32>(minv_table[w], minv_table[w + u.slab.nk]);
}

// The velocity's value at end e (0 top, 1 bottom) of component c of slot `slot`.
fn velocity_end(slot: u32, c: u32, e: u32) -> vec2<f32> {
    let b = slot * 6u + c * 2u;
    return vec2<f32>(velocity_ends[b * 2u + e], velocity_ends[(b + 1u) * 2u + e]);
}

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let n = POINTS;
    let nk = u.slab.nk;
    let walls = u.slab.walls;
    let k0 = (wid.y * nwg.x + wid.x) * KS;
    let part = lid % 2u;
    let slot = (lid / 2u) % KS;
    let c = lid / (2u * KS);
    let k = k0 + slot;
    // Threads past the last k or the solves' lines skip the work but meet every barrier.
    let solver = lid < LINES && k < nk;
    let other = 1u - part;
    // (i z) of part `part` is sign z of the other part.
    let sign = select(-1.0, 1.0, part == 1u);
    let q = slab_wave(u.slab, k, true);
    let kk = slab_wave(u.slab, k, false);
    let kabs = length(kk);

    // The pressure: p'' - k^2 p = i k.f + df_z/dz, decaying conditions (component 0's
    // threads, one per part).
    if (c == 0u && solver) {
        for (var z = 0u; z < n; z++) {
            line[z] = f[word(2u, z, k) + part];
        }
        differentiate_line();
        for (var z = 0u; z < n; z++) {
            let ikf = sign * (q.x * f[word(0u, z, k) + other] + q.y * f[word(1u, z, k) + other]);
            line[z] = u.f_scale * (ikf + line[z]);
        }
        solve(k, 0.0, 0.0);
        var top = 0.0;
        var bottom = 0.0;
        let base = (slot * 2u + part) * n;
        for (var z = 0u; z < n; z++) {
            let p = coef[z];
            let i = base + z;
            lines[i / 4u][i % 4u] = p;
            top += p;
            bottom += select(p, -p, z % 2u == 1u);
        }
        pressure_ends[(slot * 2u + part) * 2u] = top;
        pressure_ends[(slot * 2u + part) * 2u + 1u] = bottom;
    }
    workgroupBarrier();

    // The velocity: eta (v'' - k^2 v) = (i k p, dp/dz) - f with the force-free
    // exterior's boundary values.
    if (solver) {
        let scale = u.f_scale * u.slab.inv_eta;
        if (c == 2u) {
            let base = (slot * 2u + part) * n;
            for (var z = 0u; z < n; z++) {
                line[z] = pressure_at(base + z);
            }
            differentiate_line();
            for (var z = 0u; z < n; z++) {
                line[z] = scale * (line[z] - f[word(2u, z, k) + part]);
            }
        } else {
            let base = (slot * 2u + other) * n;
            let qc = q[c];
            for (var z = 0u; z < n; z++) {
                line[z] = scale * (sign * qc * pressure_at(base + z) - f[word(c, z, k) + part]);
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
    }
    // Every thread has read the pressure: its words take the velocity's coefficients.
    workgroupBarrier();
    if (solver) {
        // The values at the ends (the transform's first and last rows are 1 and +-1, so
        // these are its sums) and, at k = 0 under a bottom wall, the slope at the top
        // (sum_m m^2 c_m 2 / H).
        var top = 0.0;
        var bottom = 0.0;
        var slope = 0.0;
        for (var m = 0u; m < n; m++) {
            let v = coef[m];
            top += v;
            bottom += select(v, -v, m % 2u == 1u);
            slope += f32(m * m) * v;
        }
        for (var m4 = 0u; m4 < Q; m4++) {
            var v = vec4<f32>(0.0);
            for (var i = 0u; i < 4u; i++) {
                let m = m4 * 4u + i;
                if (m < n) {
                    v[i] = coef[m];
                }
            }
            lines[m4 * LINES + lid] = v;
        }
        let e = (slot * 6u + c * 2u + part) * 2u;
        velocity_ends[e] = top;
        velocity_ends[e + 1u] = bottom;
        slopes[slot * 6u + c * 2u + part] = -u.dz_scale * slope;
    }
    workgroupBarrier();

    // The walls' C and D (slab_walls) per (slot, component): threads lid < 3 KS.
    if (walls != 0u && lid < 3u * KS) {
        let ws = lid % KS;
        let wc = lid / KS;
        let wk = k0 + ws;
        var big_c = vec2<f32>(0.0);
        var big_d = vec2<f32>(0.0);
        if (wk < nk) {
            big_c = -velocity_end(ws, wc, 1u);
            if (walls == 2u && length(slab_wave(u.slab, wk, false)) != 0.0) {
                var x = vec2<f32>(0.0);
                var y = vec2<f32>(0.0);
                for (var i = 0u; i < 6u; i++) {
                    let w = -velocity_end(ws, i % 3u, select(1u, 0u, i >= 3u));
                    x += cmul(minv(wc, i, wk), w);
                    y += cmul(minv(3u + wc, i, wk), w);
                }
                big_c = x;
                big_d = y;
            }
        }
        wall_cd[ws * 6u + wc * 2u] = big_c;
        wall_cd[ws * 6u + wc * 2u + 1u] = big_d;
    }
    workgroupBarrier();
    if (walls != 0u && lid < KS) {
        let wk = k0 + lid;
        let wkk = slab_wave(u.slab, wk, false);
        let wabs = length(wkk);
        var a = vec2<f32>(0.0);
        var b = vec2<f32>(0.0);
        if (wk < nk && wabs != 0.0) {
            let cd = lid * 6u;
            a = wall_cd[cd + 4u] - times_i(wkk.x * wall_cd[cd] + wkk.y * wall_cd[cd + 2u]) / wabs;
            b = -wall_cd[cd + 5u] - times_i(wkk.x * wall_cd[cd + 1u] + wkk.y * wall_cd[cd + 3u]) / wabs;
        }
        wall_ab[lid * 2u] = a;
        wall_ab[lid * 2u + 1u] = b;
    }
    workgroupBarrier();

    // The values along z (the dense inverse transform, j = 0 the top) and the walls, one
    // output (c, j, slot, part) at a time.
    let zeta_at = n * Q * 4u;
    for (var o = lid; o < LINES * n; o += WG) {
        let op = o % 2u;
        let os = (o / 2u) % KS;
        let cj = o / (2u * KS);
        let oc = cj / n;
        let j = cj % n;
        let ok = k0 + os;
        if (ok >= nk) {
            continue;
        }
        let l = (oc * KS + os) * 2u + op;
        var acc = 0.0;
        for (var m4 = 0u; m4 < Q; m4++) {
            let t = points[j * Q + m4];
            let v = lines[m4 * LINES + l];
            acc += t.x * v.x;
            acc += t.y * v.y;
            acc += t.z * v.z;
            acc += t.w * v.w;
        }
        let okk = slab_wave(u.slab, ok, false);
        let oabs = length(okk);
        let zeta = point_word(zeta_at + j);
        var x = acc;
        if (oabs == 0.0) {
            x = 0.0;
            if (oc < 2u) {
                let e = (os * 6u + oc * 2u + op) * 2u;
                let top = velocity_ends[e];
                let bottom = velocity_ends[e + 1u];
                if (walls == 1u) {
                    x = acc - bottom + zeta * slopes[os * 6u + oc * 2u + op];
                } else if (walls == 2u) {
                    let h = zeta / u.slab.height;
                    x = acc - bottom * (1.0 - h) - top * h;
                }
            }
        } else if (walls != 0u) {
            let a = wall_ab[os * 2u];
            let b = wall_ab[os * 2u + 1u];
            let cc = wall_cd[os * 6u + oc * 2u];
            let dd = wall_cd[os * 6u + oc * 2u + 1u];
            let decay = exp(-oabs * zeta);
            let grow = exp(oabs * (zeta - u.slab.height));
            let az = a * zeta;
            let bz = b * zeta;
            var corr: vec2<f32>;
            if (oc == 2u) {
                corr = (oabs * az + cc) * decay + (oabs * bz + dd) * grow;
            } else {
                let kc = okk[oc];
                corr = (times_i(-kc * az) + cc) * decay + (times_i(kc * bz) + dd) * grow;
            }
            x = acc + corr[op];
        }
        out[word(oc, j, ok) + op] = x;
    }
}
