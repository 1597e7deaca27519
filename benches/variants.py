"""Writes the shader variants benches/gpu_variants.sh times, each a folder that
MESOFLOW_SHADER_DIR can name, derived from the shipped files under shaders/ so they
follow them:
  interp_noload   the workgroup-table interpolation without grid loads
  interp_l1       its grid loads folded into 4 KiB (L1 hits)
  interp_setup    no column sums at all (tables, barrier, reduction, store)
  interp_unroll8  the column sums' z loop written out for support 8 in 3D
(BENCHMARKS.md, issue 5, fifth version: what they showed). DP Stokes variants
(VARIANT_BENCH=dpstokes in benches/gpu_variants.sh) go under shaders/chebyshev/ the
same way; none is kept now (cheb_interp_pairs, threads over (column, z point) pairs,
timed 2026-12-06 on an H100: 0.24 -> 0.47 ms at 10^5, slower; removed). The lanes_*
variants each take a step out of slab_solve's lanes kernel (shaders/chebyshev/slab_lanes.wgsl;
time them with VARIANT_SLAB=lanes), so their numbers are wrong and only their times
count; every table entry and forcing word is still read and every output word written:
  lanes_nosolve     the three banded solves (each element instead mixes its table rows)
  lanes_nodiff      the two Chebyshev derivatives (each element scaled)
  lanes_notransform the inverse transform's shuffles and sums (coefficients as values)
  lanes_nowalls     the walls' constants, factors and exponentials
  lanes_skeleton    all four: loads, the pressure's sources, stores
Usage:
  python3 benches/variants.py OUT_DIR"""
import pathlib
import sys

LOAD = "r[c] = r[c] + w * dv * grid[(geo.comp_offset + c) * cells + cell];"


def unroll8(src):
    start = src.index("// This thread's share")
    end = src.index("// Writes particle")
    loads = "\n".join(f"            let o{k} = oxy + stencil_o[tz + {k}u];" for k in range(8))

    def comp(c):
        terms = " + ".join(f"stencil_w[tz + {k}u] * grid[b{c} + o{k}]" for k in range(8))
        return f"            acc[{c}] = acc[{c}] + wxy * geo.dv * ({terms});"

    extra = "".join(
        f"            if (COMPS > {c}u) {{\n                let b{c} = b0 + {c}u * cells;\n{comp(c)}\n            }}\n"
        for c in range(1, 4)
    )
    body = f"""// This thread's share of its particle's sum (zero for threads without a particle).
// Variant: support 8 in 3D written out (all eight z loads of a column issued together).
fn column_sums(lid: u32, seg: u32, ppw: u32) -> vec4<f32> {{
    let s = lid / seg;
    var acc = vec4<f32>(0.0);
    if (s < ppw && stencil_p[s] < geo.count) {{
        let tw = s * DIMS * NS;
        let cells = geo.n.w;
        for (var pair = lid % seg; pair < NS * NS; pair = pair + seg) {{
            let ix = pair % NS;
            let iy = pair / NS;
            let wxy = stencil_w[tw + ix] * stencil_w[tw + NS + iy];
            let oxy = stencil_o[tw + ix] + stencil_o[tw + NS + iy];
            let tz = tw + 2u * NS;
{loads}
            let b0 = geo.comp_offset * cells;
{comp(0)}
{extra}        }}
    }}
    return acc;
}}

"""
    return src[:start] + body + src[end:]


def lanes_without(src, steps):
    """slab_lanes.wgsl without the named steps (see the docstring), for timing only."""
    if "solve" in steps:
        start = src.index("fn solve(line: ptr<function, Line>, alpha: L, beta: L) {")
        end = src.index("// The walls' flow of one part")
        src = src[:start] + """fn solve(line: ptr<function, Line>, alpha: L, beta: L) {
    for (var i = 0u; i < PER; i++) {
        (*line)[i] = own(i) * (*line)[i] + below(i) * alpha + above(i) * beta + boundary_row(3u, i) + kappa2 * boundary_row(4u, i) + s_inv.x;
    }
}

""" + src[end:]
    if "diff" in steps:
        start = src.index("fn differentiate(line: ptr<function, Line>) {")
        end = src.index("// chebyshev_bvp's solve")
        src = src[:start] + """fn differentiate(line: ptr<function, Line>) {
    for (var i = 0u; i < PER; i++) {
        (*line)[i] = u.dz_scale * (1.0 + 2.0 * f32(z_of(i))) * (*line)[i];
    }
}

""" + src[end:]
    if "transform" in steps:
        start = src.index("fn parity_sums(line: ptr<function, Line>) -> array<Half, 2> {")
        end = src.index("@compute @workgroup_size(WG)")
        src = src[:start] + """fn parity_sums(line: ptr<function, Line>) -> array<Half, 2> {
    var even: Half;
    var odd: Half;
    for (var h = 0u; h < HALF; h++) {
        even[h] = (*line)[h % PER] + points[h];
        odd[h] = (*line)[(h + 1u) % PER];
    }
    return array<Half, 2>(even, odd);
}

""" + src[end:]
    if "walls" in steps:
        src = src.replace("let walls = u.slab.walls;", "let walls = 0u;")
    return src


def main():
    out = pathlib.Path(sys.argv[1])
    common = pathlib.Path("shaders/spread/interpolate_common.wgsl").read_text()
    subgroup = pathlib.Path("shaders/spread/interpolate_subgroup.wgsl").read_text()
    assert LOAD in common, "interpolate_common.wgsl changed: update benches/variants.py"
    variants = {
        "interp_noload": ("interpolate_common.wgsl", common.replace(LOAD, "r[c] = r[c] + w * dv * f32(cell & 7u);")),
        "interp_l1": ("interpolate_common.wgsl", common.replace(LOAD, LOAD.replace("+ cell]", "+ (cell & 1023u)]"))),
        "interp_setup": ("interpolate_subgroup.wgsl", subgroup.replace(
            "    var v = column_sums(lid, seg, ppw);", "    var v = vec4<f32>(stencil_w[lid % 384u]);")),
        "interp_unroll8": ("interpolate_common.wgsl", unroll8(common)),
    }
    variants = {name: ("spread/" + file, text) for name, (file, text) in variants.items()}
    lanes = pathlib.Path("shaders/chebyshev/slab_lanes.wgsl").read_text()
    for name, steps in [("nosolve", ["solve"]), ("nodiff", ["diff"]), ("notransform", ["transform"]),
                        ("nowalls", ["walls"]), ("skeleton", ["solve", "diff", "transform", "walls"])]:
        variants["lanes_" + name] = ("chebyshev/slab_lanes.wgsl", lanes_without(lanes, steps))
    for name, (file, text) in variants.items():
        f = out / name / file
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_text(text)
        print(f)


main()
