// template: nodes/chebyshev.rs prepends the constants WG, POINTS, CHUNK, SHARED_MATRIX
// and MATRIX_WORDS.
//
// A dense product along z (nodes/chebyshev.rs: the Chebyshev transforms and the
// derivative): out[c][k][p] = sum_j M[k][j] x[c][j][p] for every component c, output
// level k and word p of a z level (words `plane` apart), x read from word x_offset on. One thread per line (c, p) and
// chunk of CHUNK outputs: it reads its line once into a private array (POINTS = n is
// fixed when the kernel is built, so the loops unroll and the line stays in registers)
// and writes the chunk's outputs; neighbouring threads take neighbouring words. With
// SHARED_MATRIX (n^2 words fit 16 KiB) the workgroup first copies M into workgroup
// memory, else every thread reads it from the buffer. Chunks give small grids more
// threads, and keep a thread under lavapipe's 65535 loop iterations. nodes/chebyshev.rs
// prepends WG, POINTS, CHUNK, SHARED_MATRIX and MATRIX_WORDS (n^2, or 1 without it).
#import common/index.wgsl

struct Shape { comps: u32, n: u32, plane: u32, scale: f32, x_offset: u32, pad0: u32, pad1: u32, pad2: u32 }

@group(0) @binding(0) var<storage, read> x: array<f32>;
@group(0) @binding(1) var<storage, read_write> out: array<f32>;
@group(0) @binding(2) var<storage, read> matrix: array<f32>;
@group(0) @binding(3) var<uniform> shape: Shape;

var<workgroup> shared_matrix: array<f32, MATRIX_WORDS>;

fn m_entry(i: u32) -> f32 {
    if (SHARED_MATRIX) {
        return shared_matrix[i];
    }
    return matrix[i];
}

@compute @workgroup_size(WG)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let t = flat_index(wid, nwg, lid, WG);
    let lines = shape.comps * shape.plane;
    if (SHARED_MATRIX) {
        for (var i = lid; i < MATRIX_WORDS; i += WG) {
            shared_matrix[i] = matrix[i];
        }
        workgroupBarrier();
    }
    if (t >= lines * ((POINTS + CHUNK - 1u) / CHUNK)) {
        return;
    }
    let line_index = t % lines;
    let first = (t / lines) * CHUNK;
    let p = line_index % shape.plane;
    let base = (line_index - p) * POINTS + p;
    var v: array<f32, POINTS>;
    for (var j = 0u; j < POINTS; j++) {
        v[j] = x[shape.x_offset + base + j * shape.plane];
    }
    for (var k = first; k < min(first + CHUNK, POINTS); k++) {
        var acc = 0.0;
        for (var j = 0u; j < POINTS; j++) {
            acc += m_entry(k * POINTS + j) * v[j];
        }
        out[base + k * shape.plane] = acc;
    }
}
