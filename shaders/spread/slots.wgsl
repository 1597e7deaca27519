// template: imported by the per-particle spreading and interpolation kernels, which
// define geo (spread/geometry.wgsl).
//
// Particles are taken in a decorrelated order: slot g serves particle
// (g % CHUNKS) * chunk + g / CHUNKS, so workgroups running at the same time work far apart
// even when the particles are sorted in space (sorted input otherwise piles every
// concurrent access onto the same few cache lines). CHUNKS must exceed the slots a GPU
// runs at once (about 17k on an H100); it comes from the host, which sizes the dispatch.
override CHUNKS: u32 = 65536u;

// Particle served by global slot g, or geo.count when the slot is empty. The map is one
// to one on g < CHUNKS * chunk; the dispatch may round up past that (folded grids), and
// those slots must stay empty.
fn slot_particle(g: u32) -> u32 {
    let chunk = (geo.count + CHUNKS - 1u) / CHUNKS;
    if (g >= CHUNKS * chunk) {
        return geo.count;
    }
    let p = (g % CHUNKS) * chunk + g / CHUNKS;
    return select(geo.count, p, p < geo.count);
}
