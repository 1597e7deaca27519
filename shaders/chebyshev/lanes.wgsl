// template: imported by spread_lanes.wgsl and interpolate_lanes.wgsl after grid.wgsl
// (nodes/chebyshev_spread.rs, kernel `lanes`); the node puts `const SEG: u32` (lanes per
// particle: a power of two, at most the adapter's smallest subgroup) and `const
// LANES_WG: u32` (the workgroup size) before the source.
//
// A segment of SEG consecutive subgroup lanes per particle, LANES_WG / SEG consecutive
// particles per workgroup, no workgroup memory and no barrier. The support's (x, y) columns are packed
// densely over the lanes (the cells past the window's end at the far end of either axis
// dropped: a support of 5.1 cells, 7 cells per axis in the workgroup kernels, is 5 or 6
// cells, 25 to 30 columns, one block of 32 lanes, 36 in 1 % of places), x fastest: the
// lanes of one row are consecutive grid words); each lane evaluates its own column's
// x and y factors, and lane t the z factor of the t-th point of the particle's z range,
// which the segment reads by shuffle as it walks the points. Every branch around a
// shuffle depends on the particle alone, so a segment's lanes take it together, and a
// shuffle reads lanes of its own segment only. Assumes full subgroups of consecutive
// invocations (lane = invocation index mod subgroup size), as the FCM lane kernels do.

struct LaneSupport {
    u: vec2<f32>,       // position in cell-centre units along x, y
    qz: f32,
    first: vec2<i32>,   // first cell of the support along x, y
    zr: vec2<u32>,      // the range of z points (z_range)
    cols: vec2<u32>,    // columns along x, y (0 for a segment past the particles)
    zl: f32,            // this lane's z factor: of point zr.x + k, or 0 past the range
}

// Particle p's support as lane k of its segment sees it; `live`: p is a particle.
fn lane_support(p: u32, k: u32, live: bool, weighted: bool) -> LaneSupport {
    let u = vec2<f32>(centre_units(pos[3u * p], 0u), centre_units(pos[3u * p + 1u], 1u));
    let qz = pos[3u * p + 2u];
    let first = vec2<i32>(ceil(u - geo.radius.xz));
    let zr = z_range(qz);
    let side = geo.shape.x + 1u;
    var cols = vec2<u32>(0u);
    if (live) {
        // Up to the last cell of each axis within the window's end (phi_x and phi_y's
        // test): support + 1 cells hold the 2 radius + 1 cells that may be in it, so the
        // last one or two are past it (a support of 5.1 cells: 5 or 6 of the 7).
        cols = vec2<u32>(side);
        while (cols.x > 0u && abs(f32(first.x + i32(cols.x) - 1) - u.x) > geo.radius.x) {
            cols.x -= 1u;
        }
        while (cols.y > 0u && abs(f32(first.y + i32(cols.y) - 1) - u.y) > geo.radius.z) {
            cols.y -= 1u;
        }
    }
    var zl = 0.0;
    if (k <= zr.y - zr.x) {
        zl = z_factor(zr.x + k, qz, weighted);
    }
    return LaneSupport(u, qz, first, zr, cols, zl);
}

// A segment's particle as lane k of it sees it: the segment's first lane, the particle p
// (pp: p, or the last particle for a segment past them, so that reads stay in range),
// whether it is one, its support, and the z points and packed columns to walk (none
// past the particles).
struct LaneParticle {
    k: u32,
    base: u32,
    p: u32,
    pp: u32,
    live: bool,
    sp: LaneSupport,
    count: u32,
    columns: u32,
}

// The particle of workgroup `group`'s invocation `lid`, subgroup lane `lane`.
fn lane_particle(group: u32, lid: u32, lane: u32, weighted: bool) -> LaneParticle {
    let k = lane % SEG;
    let p = group * (LANES_WG / SEG) + lid / SEG;
    let live = p < geo.n.w;
    let pp = min(p, max(geo.n.w, 1u) - 1u);
    let sp = lane_support(pp, k, live, weighted);
    let count = select(0u, sp.zr.y - sp.zr.x + 1u, live);
    return LaneParticle(k, lane - k, p, pp, live, sp, count, sp.cols.x * sp.cols.y);
}

// The packed column c's (x, y) weight and its cell in a z plane; weight 0 past the columns.
struct LaneColumn {
    w: f32,
    cell: u32,
}

fn lane_column(sp: LaneSupport, c: u32) -> LaneColumn {
    if (c >= sp.cols.x * sp.cols.y) {
        return LaneColumn(0.0, 0u);
    }
    // c / cols.x in floats (exact: the quotient's fraction is at least 1 / (2 cols.x)
    // from a whole number, far above the rounding), cheaper than an integer division.
    let cy = u32((f32(c) + 0.5) / f32(sp.cols.x));
    let cx = c - cy * sp.cols.x;
    let ix = sp.first.x + i32(cx);
    let iy = sp.first.y + i32(cy);
    let w = phi_x(f32(ix) - sp.u.x) * phi_y(f32(iy) - sp.u.y);
    let cell = wrap_near(ix, geo.n.x) + geo.n.x * wrap_near(iy, geo.n.y);
    return LaneColumn(w, cell);
}

// wrap_cell for i in [-n, 2 n), as a support's cells are (it is narrower than the grid,
// its first cell within its half-width of a cell centre in the box): no integer modulo.
fn wrap_near(i: i32, n: u32) -> u32 {
    var j = i;
    if (j < 0) {
        j += i32(n);
    }
    if (j >= i32(n)) {
        j -= i32(n);
    }
    return u32(j);
}

// The z factor of the t-th point of the range, by shuffle from lane t of the segment at
// `base` (points past the segment's lanes computed here). Every lane of the segment calls
// it with the same t.
fn lane_z(sp: LaneSupport, t: u32, base: u32, weighted: bool) -> f32 {
    var w = subgroupShuffle(sp.zl, base + min(t, SEG - 1u));
    if (t >= SEG) {
        w = z_factor(sp.zr.x + t, sp.qz, weighted);
    }
    return w;
}
