// Flat thread index of a 1-D kernel whose workgroups are folded over (x, y), because one
// dispatch dimension holds at most 65535 workgroups (see CompileCtx::grid_1d).
fn flat_index(wid: vec3<u32>, nwg: vec3<u32>, lid: u32, wg: u32) -> u32 {
    return (wid.y * nwg.x + wid.x) * wg + lid;
}
