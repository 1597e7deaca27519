// template: the uniform and the bindings but the forcing's of the slab solve kernels
// (slab_staged.wgsl; slab_solve.wgsl and slab_solve_line.wgsl through slab_fused.wgsl),
// imported by them, and the reader of the slit's per-k inverse. Binding 0, the forcing
// `f`, each kernel declares itself (as f32 words, or as (re, im) pairs).

struct Solve {
    slab: Slab,
    // (H/2)^2 on the sources, H/2 on the boundary values, 2 / H on a derivative.
    f_scale: f32,
    bc_scale: f32,
    dz_scale: f32,
    pad: u32,
}

@group(0) @binding(1) var<storage, read_write> out: array<f32>;
@group(0) @binding(2) var<storage, read> bvp: array<f32>;
@group(0) @binding(3) var<storage, read> points: array<f32>;
@group(0) @binding(4) var<storage, read> minv_table: array<f32>;
@group(0) @binding(5) var<uniform> u: Solve;

fn minv(r: u32, c: u32, k: u32) -> vec2<f32> {
    let w = ((r * 6u + c) * 2u) * u.slab.nk + k;
    return vec2<f32>(minv_table[w], minv_table[w + u.slab.nk]);
}
