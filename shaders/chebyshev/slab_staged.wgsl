// template: nodes/slab_solve.rs prepends the constants WG, KS, POINTS, LS, ROWS, OUTS and
// FORWARD.
//
// slab_solve's `staged` kernel (nodes/slab_solve.rs): the same solve as slab_solve.wgsl,
// for grids with few wave numbers, where that kernel's one thread per line leaves every
// step a serial chain per thread. A workgroup takes KS wave numbers and stages them in
// workgroup memory: their 6 KS lines (component c, slot, part: line (c KS + slot) 2 +
// part, words LS apart, LS = POINTS rounded up to odd so that neighbouring lines fall in
// different banks) and their per-k tables, each read from global memory once by all WG
// threads in coalesced runs. With FORWARD the lines are the forcing's values along z (the
// x, y transformed grid) and the forward Chebyshev transform runs here first, so the
// product needs no `chebyshev` dispatch before it. The dense transforms (forward and
// inverse) spread their 6 KS n outputs over all the threads (OUTS each; neighbouring
// threads take neighbouring lines of one output row, so a row's matrix words are shared);
// the banded solves stay one thread per line (pressure: 2 KS threads, velocity: 6 KS), from
// and back to workgroup memory; the walls' constants per (slot, component) once; the
// values with the walls leave in the order of the output's words.
// f, out: word 2 ((c n + z) nk + k) + part. bvp: chebyshev_bvp's strided per-k tables
// (ROWS rows read). points: the inverse transform's matrix (n x n), zeta_j, the weights
// of dv/dz at the top, the forward transform's matrix (n x n). minv: the slit's 6 x 6
// complex inverse per k, word ((r 6 + c) 2 + part) nk + k.
#import common/index.wgsl
#import stokes_slab/slab.wgsl
#import chebyshev/slab_lines.wgsl
#import stokes_slab/wall_flow.wgsl
#import chebyshev/slab_bindings.wgsl

@group(0) @binding(0) var<storage, read> f: array<f32>;

const LINES: u32 = 6u * KS;

// A line a thread (chebyshev/slab_lines.wgsl).
alias Lane = f32;

// The lines: the forcing's values or coefficients, then the velocity's coefficients, then
// its values along z.
var<workgroup> lines: array<f32, LINES * LS>;
// Row r of slot s's table at r KS + s.
var<workgroup> tables: array<f32, ROWS * KS>;
// The pressure's coefficients per (slot, part), words LS apart; its values at the ends
// per (slot, part): top, bottom.
var<workgroup> pressure: array<f32, 2u * KS * LS>;
var<workgroup> pressure_ends: array<f32, KS * 4u>;
// The walls' constants per (slot, component): (C, D), complex.
var<workgroup> walls_cd: array<vec4<f32>, KS * 3u>;
// The k = 0 slope of each line at the top (bottom wall).
var<workgroup> slopes: array<f32, LINES>;

fn entry(row: u32, slot: u32) -> f32 {
    return tables[row * KS + slot];
}

fn line_of(c: u32, slot: u32, part: u32) -> u32 {
    return (c * KS + slot) * 2u + part;
}

// The velocity's value at end e (0 top, 1 bottom) of component c of slot `slot`.
fn velocity_end(slot: u32, c: u32, e: u32) -> vec2<f32> {
    let z = select(0u, POINTS - 1u, e == 1u);
    return vec2<f32>(lines[line_of(c, slot, 0u) * LS + z], lines[line_of(c, slot, 1u) * LS + z]);
}

// Every line through the n x n matrix at points[m_at]: output (line l, row j) is thread
// lid's output o where lid + o WG = j LINES + l. Called by all threads (it holds barriers).
fn dense(lid: u32, m_at: u32) {
    var acc: array<f32, OUTS>;
    for (var o = 0u; o < OUTS; o++) {
        let idx = lid + o * WG;
        var s = 0.0;
        if (idx < LINES * POINTS) {
            let l = idx % LINES;
            let row = m_at + (idx / LINES) * POINTS;
            for (var m = 0u; m < POINTS; m++) {
                s += points[row + m] * lines[l * LS + m];
            }
        }
        acc[o] = s;
    }
    workgroupBarrier();
    for (var o = 0u; o < OUTS; o++) {
        let idx = lid + o * WG;
        if (idx < LINES * POINTS) {
            lines[(idx % LINES) * LS + idx / LINES] = acc[o];
        }
    }
    workgroupBarrier();
}

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let n = POINTS;
    let nk = u.slab.nk;
    let k0 = (wid.y * nwg.x + wid.x) * KS;

    // Stage the lines (component c, level z: the KS wave numbers' 2 KS words are
    // contiguous in f) and the tables (row r: KS contiguous words).
    for (var i = lid; i < 3u * n * 2u * KS; i += WG) {
        let r = i % (2u * KS);
        let cz = i / (2u * KS);
        var v = 0.0;
        if (k0 + r / 2u < nk) {
            v = f[2u * (cz * nk + k0) + r];
        }
        lines[((cz / n) * 2u * KS + r) * LS + cz % n] = v;
    }
    for (var i = lid; i < ROWS * KS; i += WG) {
        let s = i % KS;
        var v = 0.0;
        if (k0 + s < nk) {
            v = bvp[(i / KS) * nk + k0 + s];
        }
        tables[i] = v;
    }
    workgroupBarrier();
    if (FORWARD) {
        dense(lid, n * n + 2u * n);
    }

    // The pressure: p'' - k^2 p = i k.f + df_z/dz, decaying conditions (a thread per
    // slot and part).
    if (lid < 2u * KS) {
        let slot = lid / 2u;
        let part = lid % 2u;
        let k = k0 + slot;
        if (k < nk) {
            let other = 1u - part;
            let sign = select(-1.0, 1.0, part == 1u);
            let q = slab_wave(u.slab, k, true);
            let fz = line_of(2u, slot, part) * LS;
            let fx = line_of(0u, slot, other) * LS;
            let fy = line_of(1u, slot, other) * LS;
            for (var z = 0u; z < n; z++) {
                line[z] = lines[fz + z];
            }
            differentiate_line();
            for (var z = 0u; z < n; z++) {
                let ikf = sign * (q.x * lines[fx + z] + q.y * lines[fy + z]);
                line[z] = u.f_scale * (ikf + line[z]);
            }
            solve(slot, 0.0, 0.0);
            var top = 0.0;
            var bottom = 0.0;
            let base = (slot * 2u + part) * LS;
            for (var z = 0u; z < n; z++) {
                let p = coef[z];
                pressure[base + z] = p;
                top += p;
                bottom += select(p, -p, z % 2u == 1u);
            }
            pressure_ends[(slot * 2u + part) * 2u] = top;
            pressure_ends[(slot * 2u + part) * 2u + 1u] = bottom;
        }
    }
    workgroupBarrier();

    // The velocity: eta (v'' - k^2 v) = (i k p, dp/dz) - f with the force-free
    // exterior's boundary values (a thread per line); its coefficients replace the line.
    if (lid < LINES) {
        let part = lid % 2u;
        let slot = (lid / 2u) % KS;
        let c = lid / (2u * KS);
        let k = k0 + slot;
        if (k < nk) {
            let other = 1u - part;
            let sign = select(-1.0, 1.0, part == 1u);
            let q = slab_wave(u.slab, k, true);
            let kabs = length(slab_wave(u.slab, k, false));
            let scale = u.f_scale * u.slab.inv_eta;
            let own = lid * LS;
            if (c == 2u) {
                let base = (slot * 2u + part) * LS;
                for (var z = 0u; z < n; z++) {
                    line[z] = pressure[base + z];
                }
                differentiate_line();
                for (var z = 0u; z < n; z++) {
                    line[z] = scale * (line[z] - lines[own + z]);
                }
            } else {
                let base = (slot * 2u + other) * LS;
                let qc = q[c];
                for (var z = 0u; z < n; z++) {
                    line[z] = scale * (sign * qc * pressure[base + z] - lines[own + z]);
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
            solve(slot, alpha, beta);
            for (var z = 0u; z < n; z++) {
                lines[own + z] = coef[z];
            }
        }
    }
    workgroupBarrier();

    // Values at the points (j = 0 the top): the inverse transform.
    dense(lid, 0u);

    // The walls' constants (slab_walls): per line its k = 0 slope (bottom wall), per
    // (slot, component) from the real part's thread the homogeneous flow's C and D.
    let walls = u.slab.walls;
    if (lid < LINES) {
        let part = lid % 2u;
        let slot = (lid / 2u) % KS;
        let c = lid / (2u * KS);
        let k = k0 + slot;
        if (k < nk) {
            let kabs = length(slab_wave(u.slab, k, false));
            var slope = 0.0;
            if (kabs == 0.0 && walls == 1u && c < 2u) {
                let row_at = n * n + n;
                for (var i = 0u; i < n; i++) {
                    slope -= points[row_at + i] * lines[lid * LS + i];
                }
            }
            slopes[lid] = slope;
            if (part == 0u && kabs != 0.0 && walls != 0u) {
                var cc = -velocity_end(slot, c, 1u);
                var dd = vec2<f32>(0.0);
                if (walls == 2u) {
                    var w: array<vec2<f32>, 6>;
                    for (var i = 0u; i < 3u; i++) {
                        w[i] = -velocity_end(slot, i, 1u);
                        w[3u + i] = -velocity_end(slot, i, 0u);
                    }
                    cc = slit_row(c, w, k);
                    dd = slit_row(3u + c, w, k);
                }
                walls_cd[slot * 3u + c] = vec4<f32>(cc, dd);
            }
        }
    }
    workgroupBarrier();

    // The values with the walls, in the order of the output's words.
    let zeta_at = n * n;
    for (var i = lid; i < 3u * n * 2u * KS; i += WG) {
        let r = i % (2u * KS);
        let cz = i / (2u * KS);
        let slot = r / 2u;
        let part = r % 2u;
        let k = k0 + slot;
        if (k >= nk) {
            continue;
        }
        let c = cz / n;
        let j = cz % n;
        let l = (c * 2u * KS + r) * LS;
        let v = lines[l + j];
        let kk = slab_wave(u.slab, k, false);
        let kabs = length(kk);
        let zeta = points[zeta_at + j];
        var x = v;
        if (kabs == 0.0) {
            x = 0.0;
            if (c < 2u) {
                let top = lines[l];
                let bottom = lines[l + n - 1u];
                if (walls == 1u) {
                    x = v - bottom + zeta * slopes[c * 2u * KS + r];
                } else if (walls == 2u) {
                    let h = zeta / u.slab.height;
                    x = v - bottom * (1.0 - h) - top * h;
                }
            }
        } else if (walls != 0u) {
            let w0 = walls_cd[slot * 3u];
            let w1 = walls_cd[slot * 3u + 1u];
            let w2 = walls_cd[slot * 3u + 2u];
            let cd = WallConstants(mat3x2<f32>(w0.xy, w1.xy, w2.xy), mat3x2<f32>(w0.zw, w1.zw, w2.zw));
            let ab = wall_factors(cd, kk, kabs);
            let a = ab[0];
            let b = ab[1];
            let wc = walls_cd[slot * 3u + c];
            let decay = exp(-kabs * zeta);
            let grow = exp(kabs * (zeta - u.slab.height));
            let az = a * zeta;
            let bz = b * zeta;
            var corr: vec2<f32>;
            if (c == 2u) {
                corr = (kabs * az + wc.xy) * decay + (kabs * bz + wc.zw) * grow;
            } else {
                let kc = kk[c];
                corr = (times_i(-kc * az) + wc.xy) * decay + (times_i(kc * bz) + wc.zw) * grow;
            }
            x = v + corr[part];
        }
        out[2u * (cz * nk + k0) + r] = x;
    }
}
