// The Chebyshev transform along z (nodes/chebyshev.rs): out[c][k][p] = sum_j T[k][j] x[c][j][p]
// for every component c, output level k and word p of a z level (words `plane` apart).
// One thread per line (c, p) and chunk of CHUNK outputs: it reads its line once into
// workgroup memory (n words, WG apart) and writes the chunk's outputs; neighbouring threads
// take neighbouring words, and all threads of a workgroup read the same matrix entry at
// once. Long lines take several chunks, because lavapipe stops a thread after 65535 loop
// iterations. nodes/chebyshev.rs prepends WG, POINTS (n) and CHUNK, chosen so the lines
// fit and a thread loops at most 32768 times.
#import common/index.wgsl

struct Shape { comps: u32, n: u32, plane: u32, scale: f32 }

@group(0) @binding(0) var<storage, read> x: array<f32>;
@group(0) @binding(1) var<storage, read_write> out: array<f32>;
@group(0) @binding(2) var<storage, read> matrix: array<f32>;
@group(0) @binding(3) var<uniform> shape: Shape;

var<workgroup> line: array<f32, WG * POINTS>;

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let t = flat_index(wid, nwg, lid, WG);
    let lines = shape.comps * shape.plane;
    // No barriers: each thread touches only its own line, so threads past the end leave.
    if (t >= lines * ((shape.n + CHUNK - 1u) / CHUNK)) {
        return;
    }
    let line_index = t % lines;
    let first = (t / lines) * CHUNK;
    let p = line_index % shape.plane;
    let base = (line_index - p) * shape.n + p;
    let n = shape.n;
    for (var j = 0u; j < n; j++) {
        line[j * WG + lid] = x[base + j * shape.plane];
    }
    for (var k = first; k < min(first + CHUNK, n); k++) {
        var acc = 0.0;
        for (var j = 0u; j < n; j++) {
            acc += matrix[k * n + j] * line[j * WG + lid];
        }
        out[base + k * shape.plane] = acc;
    }
}
