// template: nodes/slab_solve.rs prepends the constants WG (threads a workgroup), SEG (lanes
// a wave number: a power of two, at most the adapter's smallest subgroup), PER (points a
// lane: even), HALF (upper-half points a lane takes in the inverse transform) and POINTS.
//
// slab_solve's `lanes` kernel: the solve of slab_solve.wgsl (the chain chebyshev_derivative,
// slab_pressure_source, chebyshev_bvp, chebyshev_derivative, slab_velocity_source,
// chebyshev_bvp, chebyshev (inverse), slab_walls) with a wave number's z line spread over a
// segment of SEG consecutive subgroup lanes, PER consecutive points a lane (lane s holds
// z = PER s + i), instead of whole lines in one thread. Every serial step along z is a
// first-order recurrence within a parity (PER is even, so a lane's element i has the
// parity of i): the banded elimination, its back substitution and the Chebyshev
// derivative. Each runs as a scan: a lane composes its own elements' affine maps, the
// segment scans the lanes' maps by shuffles (log2 SEG steps), and each lane applies the
// value that enters it. Sums over a line (the boundary rows, the end values) are shuffle
// reductions, and the inverse transform reads the coefficients of the other lanes by
// shuffle. So a wave number's serial chain is PER points long plus log2 SEG shuffles a
// step, not POINTS, and a grid with few wave numbers has SEG times the threads of the
// kernel of whole lines to hide each one's latency. No workgroup memory and no barrier:
// a lane's line of the real and of the imaginary parts (x, y, z as the lanes of a vec3)
// stays in registers. Neighbouring k sit in neighbouring segments, so a warp's load of
// one element reads, in each of SEG planes, the (re, im) pairs of 32 / SEG consecutive k.
// On an H100 (2026-12-08, BENCHMARKS.md) it took 0.043 ms at 10^5 spheres (bottom wall,
// 30 points) against the three-lines kernel's 0.053, 0.25 against 0.23 at 10^6, and
// loses past 32 points (6 points a lane, the line padded): opt-in, not `auto`'s choice.
// Every shuffle is outside any branch that depends on the lane: segments past the last k
// run on k = nk - 1 and write nothing. Assumes full subgroups of consecutive invocations,
// as the other lane kernels do (chebyshev/lanes.wgsl).
// f: (re, im) word pairs (c n + z) nk + k. out: word 2 ((c n + z) nk + k) + part.
// bvp: chebyshev_bvp's strided per-k tables. points: the inverse transform's matrix
// (n x n), then zeta_j. minv: the slit's 6 x 6 complex inverse per k.
#import stokes_slab/slab.wgsl
#import chebyshev/slab_bindings.wgsl
#import stokes_slab/wall_flow.wgsl

alias L = vec3<f32>;
alias Line = array<L, PER>;

@group(0) @binding(0) var<storage, read> f: array<vec2<f32>>;

// This lane's place in its segment (0 to SEG - 1) and the segment's first subgroup lane.
var<private> lane: u32;
var<private> first_lane: u32;

// This wave number (the segment's k). Its rows of chebyshev_bvp's tables are read where
// used, 0 past the line, not held in private arrays: `below`, the forward elimination's
// factor on the element two below (-l_z); `above` and `own`, the back substitution's on
// the element two above (-q_z u_z) and on the element itself (q_z); the boundary rows g0
// (row 3) and g1 (row 4). Held in arrays (and with the derivative's factors as arrays) the
// kernel ran the same at 30 points and 1.13x / 1.29x slower at 34 (10^5 / 10^6, H100,
// 2026-12-08; 155 registers a thread either way there, by the driver's statistics).
var<private> wave: u32;

fn below(i: u32) -> f32 {
    let z = z_of(i);
    return select(0.0, -entry(min(z, POINTS - 1u), wave), z < POINTS && z >= 2u);
}

fn above(i: u32) -> f32 {
    let z = z_of(i);
    let zc = min(z, POINTS - 1u);
    return select(0.0, -entry(POINTS + zc, wave) * entry(2u * POINTS + zc, wave), z + 2u < POINTS);
}

fn own(i: u32) -> f32 {
    let z = z_of(i);
    return select(0.0, entry(POINTS + min(z, POINTS - 1u), wave), z < POINTS);
}

fn boundary_row(row: u32, i: u32) -> f32 {
    let z = z_of(i);
    return select(0.0, entry(row * POINTS + min(z, POINTS - 1u), wave), z < POINTS);
}

// The downward recurrences' factors: the back substitution's (above, own) or the Chebyshev
// derivative's (`differentiate`: 1 on the element two above, 2 z on the element itself).
fn down_mul(derivative: bool, i: u32) -> f32 {
    if (derivative) {
        return 1.0;
    }
    return above(i);
}

fn down_scale(derivative: bool, i: u32) -> f32 {
    if (derivative) {
        return 2.0 * f32(z_of(i));
    }
    return own(i);
}

// Per k: the Schur complement's 2 x 2 inverse (rows y0, p0) and kappa^2.
var<private> s_inv: vec4<f32>;
var<private> kappa2: f32;

fn entry(row: u32, k: u32) -> f32 {
    return bvp[row * u.slab.nk + k];
}

// The z index of this lane's element i.
fn z_of(i: u32) -> u32 {
    return PER * lane + i;
}

// Component c's coefficient z of k, complex (0 past the line).
fn forcing(c: u32, z: u32, k: u32) -> vec2<f32> {
    if (z >= POINTS) {
        return vec2<f32>(0.0);
    }
    return f[(c * POINTS + z) * u.slab.nk + k];
}

// The sum of v over the segment, in every lane.
fn segment_sum(v: L) -> L {
    var x = v;
    for (var d = 1u; d < SEG; d *= 2u) {
        x += subgroupShuffleXor(x, d);
    }
    return x;
}

// The line's sums over the segment: every element (the value at z = 1, the top) and
// every element times (-1)^z (at z = -1, the bottom).
fn line_ends(line: ptr<function, Line>) -> array<L, 2> {
    var even = L(0.0);
    var odd = L(0.0);
    for (var i = 0u; i < PER; i += 2u) {
        even += (*line)[i];
        odd += (*line)[i + 1u];
    }
    even = segment_sum(even);
    odd = segment_sum(odd);
    return array<L, 2>(even + odd, even - odd);
}

// The recurrence x_z = m_z x_(z-2) + x_z upwards along each parity (m: `below`, 0 where
// the recurrence starts): a scan of the affine maps over the segment.
fn eliminate_upwards(line: ptr<function, Line>) {
    // This lane's maps per parity (x, y): x -> a x + b.
    var a = vec2<f32>(1.0);
    var b0 = L(0.0);
    var b1 = L(0.0);
    for (var i = 0u; i < PER; i += 2u) {
        let m = vec2<f32>(below(i), below(i + 1u));
        b0 = m.x * b0 + (*line)[i];
        b1 = m.y * b1 + (*line)[i + 1u];
        a *= m;
    }
    // Inclusive scan: each lane's map after those of the lanes before it.
    for (var d = 1u; d < SEG; d *= 2u) {
        let ap = subgroupShuffleUp(a, d);
        let bp0 = subgroupShuffleUp(b0, d);
        let bp1 = subgroupShuffleUp(b1, d);
        if (lane >= d) {
            b0 = a.x * bp0 + b0;
            b1 = a.y * bp1 + b1;
            a *= ap;
        }
    }
    // The value entering this lane: the last of the lanes before (each chain starts with
    // m = 0, so the composed map's b is that value).
    var x0 = subgroupShuffleUp(b0, 1u);
    var x1 = subgroupShuffleUp(b1, 1u);
    if (lane == 0u) {
        x0 = L(0.0);
        x1 = L(0.0);
    }
    for (var i = 0u; i < PER; i += 2u) {
        x0 = below(i) * x0 + (*line)[i];
        (*line)[i] = x0;
        x1 = below(i + 1u) * x1 + (*line)[i + 1u];
        (*line)[i + 1u] = x1;
    }
}

// The recurrence x_z = mul_z x_(z+2) + scale_z x_z downwards along each parity (0 past
// the line): a scan over the segment from its last lane, whose chain starts past the line.
fn scan_downwards(line: ptr<function, Line>, derivative: bool) {
    var a = vec2<f32>(1.0);
    var b0 = L(0.0);
    var b1 = L(0.0);
    for (var j = 0u; j < PER; j += 2u) {
        let i = PER - 2u - j;
        let m = vec2<f32>(down_mul(derivative, i), down_mul(derivative, i + 1u));
        b0 = m.x * b0 + down_scale(derivative, i) * (*line)[i];
        b1 = m.y * b1 + down_scale(derivative, i + 1u) * (*line)[i + 1u];
        a *= m;
    }
    for (var d = 1u; d < SEG; d *= 2u) {
        let ap = subgroupShuffleDown(a, d);
        let bp0 = subgroupShuffleDown(b0, d);
        let bp1 = subgroupShuffleDown(b1, d);
        if (lane + d < SEG) {
            b0 = a.x * bp0 + b0;
            b1 = a.y * bp1 + b1;
            a *= ap;
        }
    }
    var x0 = subgroupShuffleDown(b0, 1u);
    var x1 = subgroupShuffleDown(b1, 1u);
    if (lane == SEG - 1u) {
        x0 = L(0.0);
        x1 = L(0.0);
    }
    for (var j = 0u; j < PER; j += 2u) {
        let i = PER - 2u - j;
        x0 = down_mul(derivative, i) * x0 + down_scale(derivative, i) * (*line)[i];
        (*line)[i] = x0;
        x1 = down_mul(derivative, i + 1u) * x1 + down_scale(derivative, i + 1u) * (*line)[i + 1u];
        (*line)[i + 1u] = x1;
    }
}

// The element after this lane's last (the next lane's first; 0 past the segment).
fn next_lane_first(line: ptr<function, Line>) -> L {
    let x = subgroupShuffleDown((*line)[0], 1u);
    return select(x, L(0.0), lane == SEG - 1u);
}

// The element before this lane's first (the previous lane's last; 0 before the segment).
fn previous_lane_last(line: ptr<function, Line>) -> L {
    let x = subgroupShuffleUp((*line)[PER - 1u], 1u);
    return select(x, L(0.0), lane == 0u);
}

// The Chebyshev derivative's coefficients in place, times 2 / H: d_m = sum over j > m,
// j - m odd, of 2 j c_j (chebyshev_derivative's recurrence d_(m-1) = d_(m+1) + 2 m c_m),
// d_0 halved. The suffix sums per parity t_z = sum over j >= z, j - z even, of 2 j c_j,
// then d_m = t_(m+1).
fn differentiate(line: ptr<function, Line>) {
    var t = *line;
    scan_downwards(&t, true);
    let after = next_lane_first(&t);
    for (var i = 0u; i < PER; i++) {
        var d: L;
        if (i + 1u < PER) {
            d = t[i + 1u];
        } else {
            d = after;
        }
        if (z_of(i) == 0u) {
            d = 0.5 * d;
        }
        (*line)[i] = u.dz_scale * d;
    }
}

// chebyshev_bvp's solve (shaders/chebyshev/bvp.wgsl) of the line (f, scaled by (H/2)^2;
// alpha, beta scaled), leaving y's coefficients in it: the boundary rows' sums, the
// Schur complement's Y0 and P0, the elimination, and y from the a's.
fn solve(line: ptr<function, Line>, alpha: L, beta: L) {
    var r0 = L(0.0);
    var r1 = L(0.0);
    for (var i = 0u; i < PER; i++) {
        r0 += boundary_row(3u, i) * (*line)[i];
        r1 += boundary_row(4u, i) * (*line)[i];
    }
    r0 = segment_sum(r0) - alpha;
    r1 = segment_sum(r1) - beta;
    let y0 = s_inv.x * r0 + s_inv.y * r1;
    let p0 = s_inv.z * r0 + s_inv.w * r1;
    // A a = f - B (Y0, P0): B is -kappa^2 at (0, Y0) and (1, P0).
    if (lane == 0u) {
        (*line)[0] += kappa2 * y0;
        (*line)[1] += kappa2 * p0;
    }
    eliminate_upwards(line);
    // The back substitution x_z = above_z x_(z+2) + own_z x_z.
    scan_downwards(line, false);
    // y'_0 = P0, y'_1 = a_0 - a_2 / 2, y'_m = (a_(m-1) - a_(m+1)) / 2m (0 from n on).
    var slope: Line;
    let a_before = previous_lane_last(line);
    let a_after = next_lane_first(line);
    for (var i = 0u; i < PER; i++) {
        let z = z_of(i);
        var lo = a_before;
        if (i > 0u) {
            lo = (*line)[i - 1u];
        }
        var hi = a_after;
        if (i + 1u < PER) {
            hi = (*line)[i + 1u];
        }
        var v = (lo - hi) / (2.0 * f32(max(z, 1u)));
        if (z == 0u) {
            v = p0;
        } else if (z == 1u) {
            v = lo - 0.5 * hi;
        } else if (z >= POINTS) {
            v = L(0.0);
        }
        slope[i] = v;
    }
    // y_0 = Y0, y_1 = P0 - y'_2 / 2, y_m = (y'_(m-1) - y'_(m+1)) / 2m.
    let s_before = previous_lane_last(&slope);
    let s_after = next_lane_first(&slope);
    for (var i = 0u; i < PER; i++) {
        let z = z_of(i);
        var lo = s_before;
        if (i > 0u) {
            lo = slope[i - 1u];
        }
        var hi = s_after;
        if (i + 1u < PER) {
            hi = slope[i + 1u];
        }
        var v = (lo - hi) / (2.0 * f32(max(z, 1u)));
        if (z == 0u) {
            v = y0;
        } else if (z == 1u) {
            v = p0 - 0.5 * hi;
        } else if (z >= POINTS) {
            v = L(0.0);
        }
        (*line)[i] = v;
    }
}

// The walls' flow of one part: values at zeta get keep v + (a1 zeta + b1) exp(-|k| zeta) +
// (a2 zeta + b2) exp(|k| (zeta - H)).
struct PartWalls {
    keep: L,
    a1: L,
    b1: L,
    a2: L,
    b2: L,
}

fn at_height(w: PartWalls, v: L, zeta: f32, decay: f32, grow: f32) -> L {
    return w.keep * v + (w.a1 * zeta + w.b1) * decay + (w.a2 * zeta + w.b2) * grow;
}

// Part `part` (0 re, 1 im) of the columns (x, y, z) of a matrix of complex columns.
fn part_of(m: mat3x2<f32>, part: u32) -> L {
    return L(m[0][part], m[1][part], m[2][part]);
}

alias Half = array<L, HALF>;

// The inverse transform by parity of one part's line: at this lane's upper-half points j =
// HALF lane + h the sums over the even and over the odd coefficients of every lane, read
// by shuffle (the values at j and at its mirror n - 1 - j are their sum and difference).
fn parity_sums(line: ptr<function, Line>) -> array<Half, 2> {
    let n = POINTS;
    let upper = (n + 1u) / 2u;
    var even: Half;
    var odd: Half;
    for (var h = 0u; h < HALF; h++) {
        even[h] = L(0.0);
        odd[h] = L(0.0);
    }
    for (var src = 0u; src < SEG; src++) {
        for (var i = 0u; i < PER; i++) {
            let c = subgroupShuffle((*line)[i], first_lane + src);
            let m = PER * src + i;
            if (m < n) {
                for (var h = 0u; h < HALF; h++) {
                    let t = points[min(HALF * lane + h, upper - 1u) * n + m];
                    if (i % 2u == 0u) {
                        even[h] += t * c;
                    } else {
                        odd[h] += t * c;
                    }
                }
            }
        }
    }
    return array<Half, 2>(even, odd);
}

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32,
        @builtin(subgroup_invocation_id) sub_lane: u32) {
    let nk = u.slab.nk;
    let n = POINTS;
    lane = sub_lane % SEG;
    first_lane = sub_lane - lane;
    let k_here = (wid.y * nwg.x + wid.x) * (WG / SEG) + lid / SEG;
    let valid = k_here < nk;
    let k = min(k_here, nk - 1u);
    wave = k;
    s_inv = vec4<f32>(entry(5u * n, k), entry(5u * n + 1u, k), entry(5u * n + 2u, k), entry(5u * n + 3u, k));
    kappa2 = entry(5u * n + 4u, k);
    let q = slab_wave(u.slab, k, true);
    let kk = slab_wave(u.slab, k, false);
    let kabs = length(kk);

    // The pressure (re, im in lanes x, y): p'' - k^2 p = i k.f + df_z/dz, decaying
    // conditions.
    var p: Line;
    for (var i = 0u; i < PER; i++) {
        p[i] = L(forcing(2u, z_of(i), k), 0.0);
    }
    differentiate(&p);
    for (var i = 0u; i < PER; i++) {
        let z = z_of(i);
        let ikf = times_i(q.x * forcing(0u, z, k) + q.y * forcing(1u, z, k));
        p[i] = u.f_scale * (L(ikf, 0.0) + p[i]);
    }
    solve(&p, L(0.0), L(0.0));
    let p_ends = line_ends(&p);

    // The velocity: eta (v'' - k^2 v) = (i k p, dp/dz) - f with the force-free exterior's
    // boundary values; a line of real parts (x, y, z) and one of imaginary parts.
    var dp = p;
    differentiate(&dp);
    let scale = u.f_scale * u.slab.inv_eta;
    var re: Line;
    var im: Line;
    for (var i = 0u; i < PER; i++) {
        let z = z_of(i);
        let fx = forcing(0u, z, k);
        let fy = forcing(1u, z, k);
        let fz = forcing(2u, z, k);
        let pz = p[i];
        re[i] = scale * L(-q.x * pz.y - fx.x, -q.y * pz.y - fy.x, dp[i].x - fz.x);
        im[i] = scale * L(q.x * pz.x - fx.y, q.y * pz.x - fy.y, dp[i].y - fz.y);
    }
    var alpha_re = L(0.0);
    var beta_re = L(0.0);
    var alpha_im = L(0.0);
    var beta_im = L(0.0);
    if (kabs != 0.0) {
        let h = 0.5 * u.slab.inv_eta * u.bc_scale;
        let g = q * h / kabs;
        let top = p_ends[0];
        let bottom = p_ends[1];
        alpha_re = L(g * top.y, h * top.x);
        beta_re = L(-g * bottom.y, h * bottom.x);
        alpha_im = L(-g * top.x, h * top.y);
        beta_im = L(g * bottom.x, h * bottom.y);
    }
    solve(&re, alpha_re, beta_re);
    solve(&im, alpha_im, beta_im);
    let re_ends = line_ends(&re);
    let im_ends = line_ends(&im);
    let walls = u.slab.walls;
    // dv/dz at the top from the coefficients, (2 / H) sum m^2 c_m (the bottom wall's k = 0).
    // Summed only with the bottom wall (uniform over the dispatch, so its shuffles stay
    // outside any branch that depends on the lane).
    var slope_re = L(0.0);
    var slope_im = L(0.0);
    if (walls == 1u) {
        for (var i = 0u; i < PER; i++) {
            let m2 = f32(z_of(i) * z_of(i));
            slope_re -= m2 * re[i];
            slope_im -= m2 * im[i];
        }
        slope_re = u.dz_scale * segment_sum(slope_re);
        slope_im = u.dz_scale * segment_sum(slope_im);
    }
    // The inverse transform's sums (`parity_sums`): one part's, then the other's, and the
    // walls' constants after both. Against both parts' sums in one loop after the
    // constants: 0.0466 -> 0.0426 ms at 10^5 (bottom wall, H100 2026-12-08), though the
    // driver gives this order 128 registers, not 96 (at 34 points 128 with 4.5 KiB of
    // workgroup memory, not 155), and each part reads the transform's matrix again.
    let sums_re = parity_sums(&re);
    let sums_im = parity_sums(&im);
    // The velocity at the top and the bottom, columns x, y, z of (re, im).
    let top = mat3x2<f32>(vec2<f32>(re_ends[0].x, im_ends[0].x), vec2<f32>(re_ends[0].y, im_ends[0].y),
                          vec2<f32>(re_ends[0].z, im_ends[0].z));
    let bottom = mat3x2<f32>(vec2<f32>(re_ends[1].x, im_ends[1].x), vec2<f32>(re_ends[1].y, im_ends[1].y),
                             vec2<f32>(re_ends[1].z, im_ends[1].z));

    // The walls (slab_walls) and the k = 0 mode, per part.
    var w_re = PartWalls(L(1.0), L(0.0), L(0.0), L(0.0), L(0.0));
    var w_im = w_re;
    if (kabs == 0.0) {
        // Zero but for the bottom wall's and the slit's shear flows (x, y).
        w_re.keep = L(0.0);
        w_im.keep = L(0.0);
        if (walls != 0u) {
            w_re.keep = L(1.0, 1.0, 0.0);
            w_im.keep = w_re.keep;
            w_re.b1 = L(-re_ends[1].xy, 0.0);
            w_im.b1 = L(-im_ends[1].xy, 0.0);
            if (walls == 1u) {
                w_re.a1 = L(slope_re.xy, 0.0);
                w_im.a1 = L(slope_im.xy, 0.0);
            } else {
                w_re.a1 = L((re_ends[1].xy - re_ends[0].xy) / u.slab.height, 0.0);
                w_im.a1 = L((im_ends[1].xy - im_ends[0].xy) / u.slab.height, 0.0);
            }
        }
    } else if (walls != 0u) {
        let cd = wall_constants(walls, bottom, top, k);
        let ab = wall_factors(cd, kk, kabs);
        let a1 = mat3x2<f32>(times_i(-kk.x * ab[0]), times_i(-kk.y * ab[0]), kabs * ab[0]);
        let a2 = mat3x2<f32>(times_i(kk.x * ab[1]), times_i(kk.y * ab[1]), kabs * ab[1]);
        w_re = PartWalls(L(1.0), part_of(a1, 0u), part_of(cd.c, 0u), part_of(a2, 0u), part_of(cd.d, 0u));
        w_im = PartWalls(L(1.0), part_of(a1, 1u), part_of(cd.c, 1u), part_of(a2, 1u), part_of(cd.d, 1u));
    }

    if (!valid) {
        return;
    }
    // Open z leaves k != 0 as the transform makes it.
    let walled = kabs == 0.0 || walls != 0u;
    let component = 2u * n * nk;
    let upper = (n + 1u) / 2u;
    for (var h = 0u; h < HALF; h++) {
        let j = HALF * lane + h;
        if (j >= upper) {
            break;
        }
        for (var side = 0u; side < 2u; side++) {
            var at = j;
            var sign = 1.0;
            if (side == 1u) {
                at = n - 1u - j;
                sign = -1.0;
                if (at == j) {
                    break;
                }
            }
            var v_re = sums_re[0][h] + sign * sums_re[1][h];
            var v_im = sums_im[0][h] + sign * sums_im[1][h];
            if (walled) {
                let zeta = points[n * n + at];
                let decay = exp(-kabs * zeta);
                let grow = exp(kabs * (zeta - u.slab.height));
                v_re = at_height(w_re, v_re, zeta, decay, grow);
                v_im = at_height(w_im, v_im, zeta, decay, grow);
            }
            let w = slab_word(0u, at, k, n, nk);
            out[w] = v_re.x;
            out[w + 1u] = v_im.x;
            out[w + component] = v_re.y;
            out[w + component + 1u] = v_im.y;
            out[w + 2u * component] = v_re.z;
            out[w + 2u * component + 1u] = v_im.z;
        }
    }
}
