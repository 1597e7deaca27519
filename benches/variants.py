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
The lanes_lean variant is a candidate, right to the last word (it passes tests/it/stokes_slab.rs
with MESOFLOW_SHADER_DIR): the lanes kernel with its table rows read where used instead of
held in private arrays, and the derivative's factors (1, 2 z) computed in place, so fewer
registers a thread and more resident warps (at 10^5 the kernel's 3850 warps fit one wave
only at 64 registers or fewer). lanes_lean2, also right: lanes_lean with the walls' per-part
constants built after the inverse transform's sums, and those sums one part (re, im) at a
time, so fewer values are live during them.
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
        (*line)[i] = own[i] * (*line)[i] + below[i] * alpha + above[i] * beta + g0[i] + kappa2 * g1[i] + s_inv.x;
    }
}

""" + src[end:]
    if "diff" in steps:
        start = src.index("fn differentiate(line: ptr<function, Line>) {")
        end = src.index("// chebyshev_bvp's solve")
        src = src[:start] + """fn differentiate(line: ptr<function, Line>) {
    for (var i = 0u; i < PER; i++) {
        (*line)[i] = u.dz_scale * (unit[i] + twice_z[i]) * (*line)[i];
    }
}

""" + src[end:]
    if "transform" in steps:
        start = src.index("    for (var src = 0u; src < SEG; src++) {")
        end = src.index("    if (!valid) {")
        src = src[:start] + """    for (var h = 0u; h < HALF; h++) {
        even_re[h] = re[h % PER] + points[h];
        odd_re[h] = re[(h + 1u) % PER];
        even_im[h] = im[h % PER];
        odd_im[h] = im[(h + 1u) % PER];
    }
""" + src[end:]
    if "walls" in steps:
        src = src.replace("let walls = u.slab.walls;", "let walls = 0u;")
    return src


def lanes_lean(src):
    """slab_lanes.wgsl with its table rows read where used (lanes_lean in the docstring)."""
    def cut(start, end, new):
        i, j = src.index(start), src.index(end)
        return src[:i] + new + src[j:]
    src = cut("// This lane's rows of chebyshev_bvp's tables", "// Per k: the Schur complement's", """\
// This wave number (the segment's k); its table rows are read where used (0 past the line).
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

// The downward recurrences' factors: the back substitution's (above, own) or the
// derivative's (1 on the element two above, 2 z on the element itself).
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

""")
    src = cut("    for (var i = 0u; i < PER; i++) {\n        let z = z_of(i);\n        let live = z < n;",
              "    s_inv = vec4", "    wave = k;\n")
    swaps = [
        ("below[i + 1u]", "below(i + 1u)"), ("below[i]", "below(i)"),
        ("""fn scan_downwards(line: ptr<function, Line>, mul: ptr<private, array<f32, PER>>,
                  scale: ptr<private, array<f32, PER>>) {""",
         "fn scan_downwards(line: ptr<function, Line>, derivative: bool) {"),
        ("(*mul)[i + 1u]", "down_mul(derivative, i + 1u)"), ("(*mul)[i]", "down_mul(derivative, i)"),
        ("(*scale)[i + 1u]", "down_scale(derivative, i + 1u)"), ("(*scale)[i]", "down_scale(derivative, i)"),
        ("scan_downwards(&t, &unit, &twice_z);", "scan_downwards(&t, true);"),
        ("scan_downwards(line, &above, &own);", "scan_downwards(line, false);"),
        ("r0 += g0[i] * (*line)[i];", "r0 += boundary_row(3u, i) * (*line)[i];"),
        ("r1 += g1[i] * (*line)[i];", "r1 += boundary_row(4u, i) * (*line)[i];"),
    ]
    for old, new in swaps:
        assert old in src, f"slab_lanes.wgsl changed: update benches/variants.py ({old!r})"
        src = src.replace(old, new)
    return src


def lanes_lean2(src):
    """lanes_lean, its walls' per-part constants built after the inverse transform's sums
    and those sums one part at a time (fewer values live at once; lanes_lean2 in the
    docstring)."""
    src = lanes_lean(src)
    tb = src.index("    // The velocity at the top and the bottom, columns x, y, z of (re, im).")
    walls = src.index("    // The walls (slab_walls) and the k = 0 mode, per part.")
    transform = src.index("    // The inverse transform by parity")
    decl = "    var w_re = PartWalls(L(1.0), L(0.0), L(0.0), L(0.0), L(0.0));\n    var w_im = w_re;\n"
    block = src[walls:transform]
    split = block.index("    if (kabs == 0.0) {")
    slope, constants = block[:split], block[split:]
    assert decl in slope, "slab_lanes.wgsl changed: update benches/variants.py (walls)"
    slope = slope.replace(decl, "").replace("    // The walls (slab_walls) and the k = 0 mode, per part.\n", "")
    constants = "    // The walls (slab_walls) and the k = 0 mode, per part.\n" + decl + constants
    ends = src[tb:walls]
    src = src[:tb] + slope + src[transform:]
    at = src.index("    if (!valid) {")
    src = src[:at] + ends + constants + src[at:]
    both = """            let c_re = subgroupShuffle(re[i], first_lane + src);
            let c_im = subgroupShuffle(im[i], first_lane + src);
            let m = PER * src + i;
            if (m < n) {
                for (var h = 0u; h < HALF; h++) {
                    let j = min(HALF * lane + h, upper - 1u);
                    let t = points[j * n + m];
                    if (i % 2u == 0u) {
                        even_re[h] += t * c_re;
                        even_im[h] += t * c_im;
                    } else {
                        odd_re[h] += t * c_re;
                        odd_im[h] += t * c_im;
                    }
                }
            }
        }
    }
"""
    assert both in src, "slab_lanes.wgsl changed: update benches/variants.py (transform)"
    def one(part):
        return f"""            let c_{part} = subgroupShuffle({part}[i], first_lane + src);
            let m = PER * src + i;
            if (m < n) {{
                for (var h = 0u; h < HALF; h++) {{
                    let t = points[min(HALF * lane + h, upper - 1u) * n + m];
                    if (i % 2u == 0u) {{
                        even_{part}[h] += t * c_{part};
                    }} else {{
                        odd_{part}[h] += t * c_{part};
                    }}
                }}
            }}
        }}
    }}
"""
    return src.replace(both, one("re") + """    for (var src = 0u; src < SEG; src++) {
        for (var i = 0u; i < PER; i++) {
""" + one("im"))


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
    variants["lanes_lean"] = ("chebyshev/slab_lanes.wgsl", lanes_lean(lanes))
    variants["lanes_lean2"] = ("chebyshev/slab_lanes.wgsl", lanes_lean2(lanes))
    for name, (file, text) in variants.items():
        f = out / name / file
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_text(text)
        print(f)


main()
