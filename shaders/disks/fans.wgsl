// Each vertex's fan of the torus mesh (nodes/disks/mesh.rs layout) as a table the overlap
// correction reads in every round (nodes/disks/overlap.rs `vertex_fans`): the mesh stays
// fixed while those rounds repeat, so its fans are walked once. Column-major rows of n
// words: 0 the corners walked (the vertex's edges, at most MAX_FAN), 1 the first corner
// (the lowest: the walk, and so the correction's float sums, in a fixed order), 2 + j
// the far end of the j-th edge walked, for j below `width`. Entries:
// - `clear`: every first corner to 0xFFFFFFFF;
// - `corners`: every corner offers itself to its vertex by atomicMin;
// - `walk`: one thread per vertex, by twins around the vertex from its first corner.
#import common/index.wgsl

// The longest fan walked, as the correction's (shaders/disks/overlap.wgsl).
const MAX_FAN: u32 = 128u;

struct Params { n: u32, slots: u32, width: u32 }

@group(0) @binding(0) var<storage, read> mesh: array<u32>;
@group(0) @binding(1) var<storage, read_write> fans: array<atomic<u32>>;
@group(0) @binding(2) var<uniform> params: Params;

@compute @workgroup_size(256)
fn clear(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_index) lid: u32) {
    let i = flat_index(wid, nwg, lid, 256u);
    if (i < params.n) {
        atomicStore(&fans[params.n + i], 0xFFFFFFFFu);
    }
}

@compute @workgroup_size(256)
fn corners(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
           @builtin(local_invocation_index) lid: u32) {
    let c = flat_index(wid, nwg, lid, 256u);
    if (c >= params.slots) {
        return;
    }
    let v = mesh[6u * (c / 3u) + c % 3u];
    if (v < params.n) {
        atomicMin(&fans[params.n + v], c);
    }
}

@compute @workgroup_size(256)
fn walk(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let v = flat_index(wid, nwg, lid, 256u);
    if (v >= params.n) {
        return;
    }
    let start = atomicLoad(&fans[params.n + v]);
    var edges = 0u;
    var c = start;
    for (var step = 0u; step < MAX_FAN && c < params.slots; step = step + 1u) {
        let t = c / 3u;
        let k = c % 3u;
        // The edge v -> v_(k+1) of this corner; the next corner is across it.
        if (step < params.width) {
            atomicStore(&fans[(2u + step) * params.n + v], mesh[6u * t + (k + 1u) % 3u]);
        }
        edges = edges + 1u;
        let u = mesh[6u * t + 3u + (k + 2u) % 3u];
        c = 3u * (u / 3u) + (u % 3u + 2u) % 3u;
        if (c == start) {
            break;
        }
    }
    atomicStore(&fans[v], edges);
}
