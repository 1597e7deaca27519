// template: imported by spread.wgsl and interpolate.wgsl (nodes/chebyshev_spread.rs): the
// grid regular in x, y (cells centred at -L/2 + (i + 1/2) h) and Chebyshev in z, the
// window per axis (window_phi, from shaders/window/), the walls' images.
struct Geometry {
    n: vec4<u32>,        // nx, ny, z points, particles
    shape: vec4<u32>,    // support (cells), components, walls (0 none, 1 bottom, 2 slit), -
    h: vec4<f32>,        // hx, hy, 1 / hx, 1 / hy
    box_len: vec4<f32>,  // Lx, Ly, 1 / Lx, 1 / Ly
    z: vec4<f32>,        // zmin, zmax, zmid, H / 2
    win_x: vec4<f32>,    // window params for hx (z uses them too, with hx)
    win_y: vec4<f32>,    // window params for hy
    radius: vec4<f32>,   // where the window ends: x (cells), z (length), y (cells), -
}

// table: z of each point (top first), then the quadrature weights h_x h_y (H/2) w_j.
fn z_point(j: u32) -> f32 {
    return table[j];
}

fn z_weight(j: u32) -> f32 {
    return table[geo.n.z + j];
}

// Position along x (a = 0) or y (1) in cell-centre units (cell i's centre at i), folded
// into the box.
fn centre_units(x: f32, a: u32) -> f32 {
    let l = geo.box_len[a];
    let folded = x - l * floor(x * geo.box_len[a + 2u] + 0.5);
    return (folded + 0.5 * l) * geo.h[a + 2u] - 0.5;
}

fn wrap_cell(i: i32, n: u32) -> u32 {
    let m = i32(n);
    return u32(((i % m) + m) % m);
}

// phi per unit length at r cells along x or y, zero beyond the support.
fn phi_x(r: f32) -> f32 {
    return select(window_phi(r, geo.win_x) * geo.h.z, 0.0, abs(r) > geo.radius.x);
}

fn phi_y(r: f32) -> f32 {
    return select(window_phi(r, geo.win_y) * geo.h.w, 0.0, abs(r) > geo.radius.z);
}

// phi per unit length at distance d along z (in x cells), zero beyond the support.
fn phi_z(d: f32) -> f32 {
    return select(window_phi(d * geo.h.z, geo.win_x) * geo.h.z, 0.0, abs(d) > geo.radius.y);
}

// The z factor with the walls' images subtracted.
fn z_kernel(z: f32, qz: f32) -> f32 {
    var w = phi_z(z - qz);
    if (geo.shape.z >= 1u) {
        w -= phi_z(z - (2.0 * geo.z.x - qz));
    }
    if (geo.shape.z == 2u) {
        w -= phi_z(z - (2.0 * geo.z.y - qz));
    }
    return w;
}

// The z points within the support of a particle at qz (its images' lie inside it too):
// j from acos, widened by one point each way (each point is tested exactly after).
fn z_range(qz: f32) -> vec2<u32> {
    let last = f32(geo.n.z - 1u);
    let top = clamp((qz + geo.radius.y - geo.z.z) / geo.z.w, -1.0, 1.0);
    let bottom = clamp((qz - geo.radius.y - geo.z.z) / geo.z.w, -1.0, 1.0);
    let lo = max(floor(last * acos(top) / 3.141592653589793) - 1.0, 0.0);
    let hi = min(ceil(last * acos(bottom) / 3.141592653589793) + 1.0, last);
    return vec2<u32>(u32(lo), u32(hi));
}

// The per-particle factors, computed once by the workgroup: phi_x and phi_y of the
// (support + 1) cells of each axis (support at most 32), and the z factor (images
// subtracted) of the first Z_CACHE z points in the support; points past those (a support
// spanning more than Z_CACHE Chebyshev points) are computed where they are used.
const Z_CACHE: u32 = 256u;
var<workgroup> factor_x: array<f32, 33>;
var<workgroup> factor_y: array<f32, 33>;
var<workgroup> factor_z: array<f32, Z_CACHE>;

// Fills the factors of a particle at (ux, uy) in cell units and qz, its first cells
// x0, y0 and z range zr; every thread of the 64 calls it (it ends on a barrier).
fn fill_factors(lid: u32, ux: f32, uy: f32, qz: f32, x0: i32, y0: i32, zr: vec2<u32>, weighted: bool) {
    let side = geo.shape.x + 1u;
    if (lid < side) {
        factor_x[lid] = phi_x(f32(x0 + i32(lid)) - ux);
        factor_y[lid] = phi_y(f32(y0 + i32(lid)) - uy);
    }
    let count = min(zr.y - zr.x + 1u, Z_CACHE);
    for (var t = lid; t < count; t += 64u) {
        factor_z[t] = z_factor(zr.x + t, qz, weighted);
    }
    workgroupBarrier();
}

// The z factor of point j (times its quadrature weight when `weighted`).
fn z_factor(j: u32, qz: f32, weighted: bool) -> f32 {
    let w = z_kernel(z_point(j), qz);
    return select(w, w * z_weight(j), weighted);
}

// The z factor of the t-th point of the range, from the cache where it is there.
fn cached_z(t: u32, zr: vec2<u32>, qz: f32, weighted: bool) -> f32 {
    if (t < Z_CACHE) {
        return factor_z[t];
    }
    return z_factor(zr.x + t, qz, weighted);
}

// A particle's place on the grid: its z, the first cells of its support and its range of
// z points.
struct Support {
    qz: f32,
    first: vec2<i32>,
    zr: vec2<u32>,
}

// Particle p's support, with its factors filled in workgroup memory (every thread of the
// workgroup calls it: it ends on a barrier). `pos` is the kernel's positions binding.
fn particle_support(p: u32, lid: u32, weighted: bool) -> Support {
    let u = vec2<f32>(centre_units(pos[3u * p], 0u), centre_units(pos[3u * p + 1u], 1u));
    let qz = pos[3u * p + 2u];
    let first = vec2<i32>(ceil(u - geo.radius.xz));
    let zr = z_range(qz);
    fill_factors(lid, u.x, u.y, qz, first.x, first.y, zr, weighted);
    return Support(qz, first, zr);
}

// Column c (x fastest) of the support: its x, y window weight and its cell in a level.
fn column_weight(c: u32) -> f32 {
    let side = geo.shape.x + 1u;
    return factor_x[c % side] * factor_y[c / side];
}

fn column_cell(c: u32, sp: Support) -> u32 {
    let side = geo.shape.x + 1u;
    return wrap_cell(sp.first.x + i32(c % side), geo.n.x) + geo.n.x * wrap_cell(sp.first.y + i32(c / side), geo.n.y);
}

// The offsets [first, end) into a particle's z range of the points whose factor is not zero:
// the range from z_range is widened by a point each way, and a point on a wall has a zero
// factor (its image cancels it); trimming the ends here keeps the column loops free of
// tests.
fn nonzero_z(sp: Support, weighted: bool) -> vec2<u32> {
    var first = 0u;
    var end = sp.zr.y - sp.zr.x + 1u;
    while (first < end && cached_z(first, sp.zr, sp.qz, weighted) == 0.0) {
        first++;
    }
    while (end > first && cached_z(end - 1u, sp.zr, sp.qz, weighted) == 0.0) {
        end--;
    }
    return vec2<u32>(first, end);
}
