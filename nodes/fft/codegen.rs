//! WGSL for one FFT pass, generated from its [`Pass`] recipe: sizes, strides, radix
//! stages and twiddle offsets are literals, loops over a thread's butterflies are
//! unrolled, and registers are plain variables, so the driver compiles straight-line
//! code with every index known. The pipeline cache keys on the source, so equal passes of
//! different nodes share one pipeline.
//!
//! A stage of radix R after Ns points (mixed-radix Stockham, natural order in and out):
//! butterfly j < n/R reads points j + r n/R, multiplies point r by w^(k r), k = j mod Ns,
//! w = e^(-+2 pi i / (Ns R)), takes the R-point DFT and writes point r to
//! (j / Ns) Ns R + k + r Ns. The first stage reads from global memory (reads are
//! coalesced), the last writes to it (so are writes), and the stages in between exchange
//! through workgroup memory.

use std::f64::consts::PI;
use std::fmt::Write;

use super::plan::{Layout, Load, Pass, Store};
use crate::gpu::Binding;
use crate::transform::SpectralBody;

/// A spectral node folded into a forward transform's last pass.
pub struct Fold<'a> {
    pub body: &'a SpectralBody,
    /// Real-space dims (nx, ny, nz).
    pub dims: [u32; 3],
    /// Dims of the spectrum as stored (nx/2 + 1 along x for half spectra).
    pub stored: [u32; 3],
    /// The spectrum is a half spectrum (x wave numbers are 0..=nx/2).
    pub half: bool,
}

/// The bindings of a pass, in order: source (unless in place), destination, twiddles,
/// then the folded spectral node's params and, when its body reads the step, the engine
/// clock.
pub fn bindings(p: &Pass, fold: Option<&Fold>) -> Vec<Binding> {
    let mut b = Vec::new();
    if p.src != p.dst {
        b.push(Binding::StorageRead);
    }
    b.push(Binding::StorageReadWrite);
    b.push(Binding::StorageRead);
    if p.spectral {
        b.push(Binding::StorageRead);
        if fold.is_some_and(|f| f.body.uses_step) {
            b.push(Binding::StorageRead);
        }
    }
    b
}

/// An f32 literal of an f64 constant (rounded once).
fn lit(x: f64) -> String {
    let s = format!("{:?}", x as f32);
    if x < 0.0 { format!("({s})") } else { s }
}

/// `base + (pos) * inner` without the multiplication when it is 1.
fn at(base: &str, pos: &str, inner: u32) -> String {
    if inner == 1 {
        format!("{base} + {pos}")
    } else {
        format!("{base} + ({pos}) * {inner}u")
    }
}

/// Offset of line `ln` in an array of lines of `len` points `inner` apart.
fn line_base(ln: &str, len: u32, inner: u32) -> String {
    if inner == 1 {
        format!("{ln} * {len}u")
    } else {
        format!(
            "({ln} / {inner}u) * {}u + {ln} % {inner}u",
            inner as u64 * len as u64
        )
    }
}

/// `j + offset`, without a zero offset.
fn plus(j: &str, off: u32) -> String {
    if off == 0 {
        j.to_string()
    } else {
        format!("{j} + {off}u")
    }
}

/// Multiplication by `sign` i.
fn rot(sign: f64) -> &'static str {
    if sign > 0.0 { "mul_i" } else { "mul_ni" }
}

/// The R-point DFT in place on the registers `v` (direction `sign`).
fn butterfly(w: &mut String, v: &[String], sign: f64, ind: &str) {
    let r = v.len();
    let rot = rot(sign);
    match r {
        1 => {}
        2 => {
            writeln!(
                w,
                "{ind}{{ let a = {0}; {0} = a + {1}; {1} = a - {1}; }}",
                v[0], v[1]
            )
            .unwrap();
        }
        4 => {
            writeln!(
                w,
                "{ind}{{ let t0 = {0} + {2}; let t1 = {0} - {2}; let t2 = {1} + {3}; let t3 = {rot}({1} - {3});\n{ind}  {0} = t0 + t2; {2} = t0 - t2; {1} = t1 + t3; {3} = t1 - t3; }}",
                v[0], v[1], v[2], v[3]
            )
            .unwrap();
        }
        8 => {
            let c = lit(0.5f64.sqrt());
            let s = sign;
            // Two 4-point DFTs (even and odd points), the odd one turned by w^k,
            // w = e^(sign 2 pi i / 8), then 2-point DFTs.
            writeln!(
                w,
                "{ind}{{ let e0 = {0} + {4}; let e1 = {0} - {4}; let e2 = {2} + {6}; let e3 = {rot}({2} - {6});\n\
                 {ind}  let a0 = e0 + e2; let a2 = e0 - e2; let a1 = e1 + e3; let a3 = e1 - e3;\n\
                 {ind}  let o0 = {1} + {5}; let o1 = {1} - {5}; let o2 = {3} + {7}; let o3 = {rot}({3} - {7});\n\
                 {ind}  let b0 = o0 + o2; let b2 = {rot}(o0 - o2); let c1 = o1 + o3; let c3 = o1 - o3;\n\
                 {ind}  let b1 = {c} * vec2<f32>(c1.x {m} c1.y, c1.y {p} c1.x);\n\
                 {ind}  let b3 = {c} * vec2<f32>(-c3.x {m} c3.y, {sx}c3.x - c3.y);\n\
                 {ind}  {0} = a0 + b0; {4} = a0 - b0; {1} = a1 + b1; {5} = a1 - b1;\n\
                 {ind}  {2} = a2 + b2; {6} = a2 - b2; {3} = a3 + b3; {7} = a3 - b3; }}",
                v[0],
                v[1],
                v[2],
                v[3],
                v[4],
                v[5],
                v[6],
                v[7],
                // w^1 = c (1 + s i): (x + iy)(1 + s i) = (x - s y) + i (y + s x).
                m = if s > 0.0 { "-" } else { "+" },
                p = if s > 0.0 { "+" } else { "-" },
                // w^3 = c (-1 + s i): (x + iy)(-1 + s i) = (-x - s y) + i (s x - y).
                sx = if s > 0.0 { "" } else { "-" },
            )
            .unwrap();
        }
        _ => {
            // Odd radix: pairs j, R-j give y_k = a0 + sum_j cos(2 pi jk/R) (a_j + a_{R-j})
            // + sign i sum_j sin(2 pi jk/R) (a_j - a_{R-j}).
            let h = (r - 1) / 2;
            write!(w, "{ind}{{ let a0 = {};", v[0]).unwrap();
            for j in 1..=h {
                write!(
                    w,
                    " let s{j} = {0} + {1}; let d{j} = {0} - {1};",
                    v[j],
                    v[r - j]
                )
                .unwrap();
            }
            writeln!(w).unwrap();
            let sum: Vec<String> = (1..=h).map(|j| format!("s{j}")).collect();
            writeln!(w, "{ind}  {} = a0 + {};", v[0], sum.join(" + ")).unwrap();
            for k in 1..=h {
                let angle = |j: usize| 2.0 * PI * (j * k) as f64 / r as f64;
                let a: Vec<String> = (1..=h)
                    .map(|j| format!("{} * s{j}", lit(angle(j).cos())))
                    .collect();
                let b: Vec<String> = (1..=h)
                    .map(|j| format!("{} * d{j}", lit(angle(j).sin())))
                    .collect();
                writeln!(
                    w,
                    "{ind}  {{ let a = a0 + {}; let b = {rot}({}); {} = a + b; {} = a - b; }}",
                    a.join(" + "),
                    b.join(" + "),
                    v[k],
                    v[r - k]
                )
                .unwrap();
            }
            writeln!(w, "{ind}}}").unwrap();
        }
    }
}

/// The WGSL of one pass; `fold` when a spectral node is applied to its results.
pub fn source(p: &Pass, fold: Option<&Fold>) -> String {
    let mut w = String::new();
    let n = p.n;
    let t = p.threads_per_line;
    let bs = p.tile_lines;
    let b = p.tile_comps * bs;
    let threads = p.threads();
    let sign = if p.inverse { 1.0 } else { -1.0 };
    let in_place = p.src == p.dst;
    let src = if in_place { "dst" } else { "src" };
    let (offsets, post) = p.twiddle_offsets();
    let mut stages = p.stages();
    if stages.is_empty() {
        // A 1-point line: one stage that moves values without a butterfly.
        stages.push((1, 1));
    }
    let via_shared_out = p.store_via_shared();
    let via_shared_in = p.load == Load::HalfPacked;
    let scale = if p.scale == 1.0 {
        String::new()
    } else {
        format!(" * {}", lit(p.scale))
    };

    writeln!(
        w,
        "// mesoflow FFT pass (generated): {n}-point {} along axis {}, radices {:?}, {t} threads/line, {bs} lines x {} comps per workgroup.",
        if p.inverse { "inverse" } else { "forward" },
        p.axis,
        p.radices,
        p.tile_comps
    )
    .unwrap();
    writeln!(w, "#import fft/common.wgsl").unwrap();
    if fold.is_some() {
        writeln!(w, "#import common/wave.wgsl").unwrap();
    }
    let mut binding = 0;
    let mut bind = |w: &mut String, access: &str, name: &str, ty: &str| {
        writeln!(
            w,
            "@group(0) @binding({binding}) var<storage, {access}> {name}: array<{ty}>;"
        )
        .unwrap();
        binding += 1;
    };
    let src_ty = if p.load == Load::Real {
        "f32"
    } else {
        "vec2<f32>"
    };
    let dst_ty = if p.store == Store::Real {
        "f32"
    } else {
        "vec2<f32>"
    };
    if !in_place {
        bind(&mut w, "read", "src", src_ty);
    }
    bind(&mut w, "read_write", "dst", dst_ty);
    bind(&mut w, "read", "tw", "vec2<f32>");
    if p.spectral {
        bind(&mut w, "read", "spectral_params", "f32");
        if fold.is_some_and(|f| f.body.uses_step) {
            bind(&mut w, "read", "clock", "u32");
        }
    }
    if p.shared > 0 {
        writeln!(w, "var<workgroup> sh: array<vec2<f32>, {}>;", p.shared).unwrap();
        let sl = p.shared_line();
        match (p.layout, p.padded) {
            (Layout::Contiguous, true) => writeln!(
                w,
                "fn sidx(line: u32, p: u32) -> u32 {{ let f = line * {sl}u + p; return f + (f >> 4u); }}"
            ),
            (Layout::Contiguous, false) => writeln!(
                w,
                "fn sidx(line: u32, p: u32) -> u32 {{ return line * {sl}u + p; }}"
            ),
            (Layout::Strided, _) => writeln!(
                w,
                "fn sidx(line: u32, p: u32) -> u32 {{ return p * {b}u + line; }}"
            ),
        }
        .unwrap();
    }
    if let (Some(f), true) = (fold, p.spectral) {
        // Folded nodes keep the component count (`src/plan/fold.rs` folds no other).
        w.push_str(&f.body.function(p.comps_per_line(), p.comps_per_line()));
    }

    writeln!(
        w,
        "\n@compute @workgroup_size({threads})\nfn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,\n        @builtin(local_invocation_index) lid: u32) {{"
    )
    .unwrap();
    writeln!(w, "    let g = wid.y * nwg.x + wid.x;").unwrap();
    match p.layout {
        Layout::Contiguous => writeln!(w, "    let ll = lid / {t}u; let t = lid % {t}u;"),
        Layout::Strided => writeln!(w, "    let ll = lid % {b}u; let t = lid / {b}u;"),
    }
    .unwrap();
    if p.tile_comps > 1 {
        writeln!(
            w,
            "    let s = g * {bs}u + ll % {bs}u; let valid = s < {lines}u; let ln = (ll / {bs}u) * {lines}u + s;",
            lines = p.lines
        )
        .unwrap();
    } else {
        writeln!(
            w,
            "    let s = g * {b}u + ll; let valid = s < {}u; let ln = s;",
            p.lines
        )
        .unwrap();
    }
    writeln!(w, "    let ib = {};", line_base("ln", p.in_len, p.in_inner)).unwrap();
    if !via_shared_out && !p.spectral_in_registers() {
        writeln!(
            w,
            "    let ob = {};",
            line_base("ln", p.out_len, p.out_inner)
        )
        .unwrap();
    }
    let regs = stages
        .iter()
        .map(|&(r, _)| r * (n / r).div_ceil(t))
        .max()
        .unwrap_or(1);
    for i in 0..regs {
        writeln!(w, "    var r{i}: vec2<f32>;").unwrap();
    }

    if via_shared_in {
        // The half spectrum (n + 1 values) into workgroup memory: every point of the
        // packed spectrum needs two of them.
        for i in 0..(n + 1).div_ceil(t) {
            writeln!(
                w,
                "    {{ let q = {}; if (valid && q <= {n}u) {{ sh[sidx(ll, q)] = {src}[ib + q]; }} }}",
                plus("t", i * t)
            )
            .unwrap();
        }
        writeln!(w, "    workgroupBarrier();").unwrap();
    }

    if p.spectral_in_registers() {
        let fold = fold.expect("a spectral pass is generated with its fold");
        spectral_in_registers(&mut w, p, fold, &stages, &offsets, post, src);
    } else {
        let to = if via_shared_out {
            To::Shared
        } else {
            To::Global {
                ob: "ob".into(),
                scale: scale.clone(),
            }
        };
        let from = From::Global {
            src,
            ib: "ib".into(),
        };
        emit_stages(&mut w, p, &stages, &offsets, post, sign, false, &from, &to);
    }

    if via_shared_out {
        output_phase(&mut w, p, fold, &scale, post);
    }
    writeln!(w, "}}").unwrap();
    // A folded body's imports name embedded files (its node's tests compile it).
    crate::gpu::shaders::resolve(&w)
        .expect("fft/common.wgsl, common/wave.wgsl and the folded body's imports are embedded")
}

/// Results from workgroup memory to global memory, one (line, point) item per thread at a
/// time, consecutive threads on consecutive addresses: unfolding packed real spectra
/// and applying a folded spectral node to all components of a wave vector.
fn output_phase(w: &mut String, p: &Pass, fold: Option<&Fold>, scale: &str, post: u32) {
    let n = p.n;
    let bs = p.tile_lines;
    let threads = p.threads();
    let count = p.out_count();
    let items = bs * count;
    let comps = p.tile_comps;
    writeln!(w, "    // results").unwrap();
    for i in 0..items.div_ceil(threads) {
        writeln!(w, "    {{ let item = {};", plus("lid", i * threads)).unwrap();
        writeln!(w, "      if (item < {items}u) {{").unwrap();
        match p.layout {
            Layout::Contiguous => {
                writeln!(
                    w,
                    "        let ls = item / {count}u; let q = item % {count}u;"
                )
            }
            Layout::Strided => writeln!(w, "        let ls = item % {bs}u; let q = item / {bs}u;"),
        }
        .unwrap();
        writeln!(w, "        let s2 = g * {bs}u + ls;").unwrap();
        writeln!(w, "        if (s2 < {}u) {{", p.lines).unwrap();
        let array = if p.spectral {
            "SPECTRAL_IN".to_string()
        } else {
            format!("{comps}u")
        };
        writeln!(w, "          var v: array<vec2<f32>, {array}>;").unwrap();
        for c in 0..comps {
            let line = plus("ls", c * bs);
            if p.store == Store::HalfPacked {
                // X[q] = (Z[q] + Z*[n-q]) / 2 + w^q (Z[q] - Z*[n-q]) / 2i, w = e^(-i pi/n).
                writeln!(
                    w,
                    "          {{ let zq = sh[sidx({line}, q % {n}u)]; let zm = sh[sidx({line}, ({n}u - q) % {n}u)]; let zc = vec2<f32>(zm.x, -zm.y);\n            v[{c}] = 0.5 * (zq + zc) + cmul(tw[{post}u + q], 0.5 * mul_ni(zq - zc)); }}"
                )
                .unwrap();
            } else {
                writeln!(w, "          v[{c}] = sh[sidx({line}, q)];").unwrap();
            }
        }
        if let (Some(f), true) = (fold, p.spectral) {
            let cell = at(&line_base("s2", p.out_len, p.out_inner), "q", p.out_inner);
            apply_spectral(w, f, &cell, "          ");
        }
        for c in 0..comps {
            let ln = if comps > 1 {
                format!("{}u + s2", c * p.lines)
            } else {
                "s2".to_string()
            };
            writeln!(
                w,
                "          {{ let o = {}; dst[{}] = v[{c}]{scale}; }}",
                line_base(&format!("({ln})"), p.out_len, p.out_inner),
                at("o", "q", p.out_inner)
            )
            .unwrap();
        }
        writeln!(w, "        }}\n      }}\n    }}").unwrap();
    }
}

/// `v = spectral(k, n, v)` for the wave vector of spectrum cell `cell` (a WGSL
/// expression), as lines indented by `ind`.
fn apply_spectral(w: &mut String, f: &Fold, cell: &str, ind: &str) {
    let [sx, sy, _] = f.stored;
    let [nx, ny, nz] = f.dims;
    writeln!(w, "{ind}let cell = {cell};").unwrap();
    writeln!(
        w,
        "{ind}let ix = cell % {sx}u; let iy = (cell / {sx}u) % {sy}u; let iz = cell / {}u;",
        sx * sy
    )
    .unwrap();
    let kx = if f.half {
        "i32(ix)".to_string()
    } else {
        format!("wave_number(ix, {nx}u)")
    };
    writeln!(
        w,
        "{ind}v = spectral(vec3<i32>({kx}, wave_number(iy, {ny}u), wave_number(iz, {nz}u)), vec3<u32>({nx}u, {ny}u, {nz}u), v);"
    )
    .unwrap();
}

/// Where a pass's first stage reads its lines.
enum From<'a> {
    /// Global memory through the pass's [`Load`]: binding `src`, line base `ib`.
    Global { src: &'a str, ib: String },
    /// Workgroup memory, as every later stage reads.
    Shared,
    /// Registers `{prefix}{i}` loaded before (see [`prefetch`]), i = m R + r for point
    /// j + r n/R of the thread's m-th butterfly j.
    Registers(String),
}

/// Where a pass's last stage writes its results.
enum To {
    /// Global memory through the pass's [`Store`] at line base `ob`, times `scale`.
    Global { ob: String, scale: String },
    /// Workgroup memory.
    Shared,
    /// Registers `{prefix}{i}`, i = m R + r for point r of the thread's m-th butterfly:
    /// point j + r Ns of the line, j = t + m T (T threads per line).
    Registers(String),
}

/// The radix stages of one line transform of direction `sign`; `conj`: the twiddle
/// table holds the other direction's twiddles (conjugated on use).
#[allow(clippy::too_many_arguments)]
fn emit_stages(
    w: &mut String,
    p: &Pass,
    stages: &[(u32, u32)],
    offsets: &[u32],
    post: u32,
    sign: f64,
    conj: bool,
    from: &From,
    to: &To,
) {
    let n = p.n;
    let t = p.threads_per_line;
    let last = stages.len() - 1;
    for (si, &(r, ns)) in stages.iter().enumerate() {
        let nb = n / r;
        let per = nb.div_ceil(t);
        let global_src = match from {
            From::Global { src, ib } if si == 0 => Some((*src, ib.as_str())),
            _ => None,
        };
        let registers = match from {
            From::Registers(prefix) if si == 0 => Some(prefix.as_str()),
            _ => None,
        };
        // The packed inverse reads its half spectrum from workgroup memory (put there
        // before the stages).
        let read_shared = global_src.is_none() && registers.is_none() || p.load == Load::HalfPacked;
        let write_shared = si < last || matches!(to, To::Shared);
        let global_dst = match to {
            To::Global { ob, scale } if si == last => Some((ob.as_str(), scale.as_str())),
            _ => None,
        };
        writeln!(w, "    // stage {si}: radix {r} after {ns} points").unwrap();
        let guard = |m: u32, global: bool| -> String {
            let mut c = Vec::new();
            if global {
                c.push("valid".to_string());
            }
            if (m + 1) * t > nb {
                c.push(format!("j < {nb}u"));
            }
            c.join(" && ")
        };
        let open = |w: &mut String, m: u32, cond: &str| {
            write!(w, "    {{ let j = {};", plus("t", m * t)).unwrap();
            if cond.is_empty() {
                writeln!(w).unwrap();
            } else {
                writeln!(w, " if ({cond}) {{").unwrap();
            }
        };
        let close = |w: &mut String, cond: &str| {
            if cond.is_empty() {
                writeln!(w, "    }}").unwrap();
            } else {
                writeln!(w, "    }} }}").unwrap();
            }
        };
        // Reads.
        for m in 0..per {
            let cond = guard(m, !read_shared);
            open(w, m, &cond);
            for rr in 0..r {
                let reg = format!("r{}", m * r + rr);
                let pos = plus("j", rr * nb);
                let load = match (global_src, registers) {
                    (None, Some(prefix)) => format!("{reg} = {prefix}{};", m * r + rr),
                    (None, None) => format!("{reg} = sh[sidx(ll, {pos})];"),
                    (Some((src, ib)), _) => match p.load {
                        Load::Complex => {
                            format!("{reg} = {src}[{}];", at(ib, &pos, p.in_inner))
                        }
                        Load::Real => format!("{reg} = vec2<f32>({src}[{ib} + {pos}], 0.0);"),
                        Load::HalfMirror => format!(
                            "{{ let p = {pos}; let mirror = p > {h}u; let x = {src}[{ib} + select(p, {n}u - p, mirror)]; {reg} = select(x, vec2<f32>(x.x, -x.y), mirror); }}",
                            h = n / 2
                        ),
                        // Z[p] = (X[p] + X*[n-p]) + i w^p (X[p] - X*[n-p]), w = e^(i pi/n):
                        // the spectrum of x[2m] + i x[2m+1] (times 2). The imaginary
                        // parts of X[0] and X[n] are dropped, as numpy's irfft does.
                        Load::HalfPacked => format!(
                            "{{ let p = {pos}; let x0 = sh[sidx(ll, p)]; let y0 = sh[sidx(ll, {n}u - p)];\n          let a = select(x0, vec2<f32>(x0.x, 0.0), p == 0u); let c = select(vec2<f32>(y0.x, -y0.y), vec2<f32>(y0.x, 0.0), p == 0u);\n          {reg} = a + c + mul_i(cmul(tw[{post}u + p], a - c)); }}"
                        ),
                    },
                };
                writeln!(w, "        {load}").unwrap();
            }
            close(w, &cond);
        }
        if read_shared && write_shared {
            writeln!(w, "    workgroupBarrier();").unwrap();
        }
        // Twiddles, butterflies, writes.
        for m in 0..per {
            let cond = guard(m, global_dst.is_some());
            open(w, m, &cond);
            let v: Vec<String> = (0..r).map(|rr| format!("r{}", m * r + rr)).collect();
            if ns > 1 {
                writeln!(
                    w,
                    "        let k = j % {ns}u; let tb = {}u + k * {}u;",
                    offsets[si],
                    r - 1
                )
                .unwrap();
                for (rr, reg) in v.iter().enumerate().skip(1) {
                    let tw = format!("tw[{}]", plus("tb", rr as u32 - 1));
                    if conj {
                        writeln!(
                            w,
                            "        {{ let q = {tw}; {reg} = cmul({reg}, vec2<f32>(q.x, -q.y)); }}"
                        )
                    } else {
                        writeln!(w, "        {reg} = cmul({reg}, {tw});")
                    }
                    .unwrap();
                }
            }
            butterfly(w, &v, sign, "        ");
            let dest = if si == last {
                // Ns R = n: the output index is j + r Ns.
                "j".to_string()
            } else if ns == 1 {
                format!("j * {r}u")
            } else {
                format!("(j / {ns}u) * {}u + k", ns * r)
            };
            for (rr, reg) in v.iter().enumerate() {
                let pos = plus(&dest, rr as u32 * ns);
                let store = match (global_dst, to) {
                    _ if write_shared => format!("sh[sidx(ll, {pos})] = {reg};"),
                    (Some((ob, scale)), _) => match p.store {
                        Store::Complex => {
                            format!("dst[{}] = {reg}{scale};", at(ob, &pos, p.out_inner))
                        }
                        Store::Half => format!(
                            "{{ let p = {pos}; if (p <= {}u) {{ dst[{ob} + p] = {reg}; }} }}",
                            n / 2
                        ),
                        Store::Real => format!("dst[{ob} + {pos}] = {reg}.x{scale};"),
                        Store::HalfPacked => {
                            unreachable!("packed stores go through workgroup memory")
                        }
                    },
                    (None, To::Registers(prefix)) => {
                        format!("{prefix}{} = {reg};", m * r + rr as u32)
                    }
                    (None, _) => unreachable!("the last stage writes to its destination"),
                };
                writeln!(w, "        {store}").unwrap();
            }
            close(w, &cond);
        }
        if write_shared {
            writeln!(w, "    workgroupBarrier();").unwrap();
        }
    }
}

/// A folded spectral node on a pass along y or z: each component's lines in turn
/// through workgroup memory, their results left in registers where the last butterflies
/// put them (a thread then holds every component of its points), the spectral node
/// applied there, and the results written, or with `inverse_after` transformed back
/// first, component by component (the inverse transform's first pass).
fn spectral_in_registers(
    w: &mut String,
    p: &Pass,
    fold: &Fold,
    stages: &[(u32, u32)],
    offsets: &[u32],
    post: u32,
    src: &str,
) {
    let comps = p.seq_comps;
    let t = p.threads_per_line;
    let &(r, ns) = stages.last().expect("at least one stage");
    let nb = p.n / r;
    let per = nb.div_ceil(t);
    for c in 0..comps {
        let ln = format!("({}u + s)", c * p.lines);
        writeln!(
            w,
            "    let ib{c} = {};",
            line_base(&ln, p.in_len, p.in_inner)
        )
        .unwrap();
        writeln!(
            w,
            "    let ob{c} = {};",
            line_base(&ln, p.out_len, p.out_inner)
        )
        .unwrap();
        for i in 0..per * r {
            writeln!(w, "    var o{c}_{i}: vec2<f32>;").unwrap();
        }
    }
    // The later components' first loads are issued now, with the first's: a
    // workgroup works through the components in turn, and without them in flight it
    // would keep a third of the bytes of a plain pass in flight.
    for c in 1..comps {
        prefetch(w, p, stages[0], src, &format!("ib{c}"), &format!("p{c}_"));
    }
    for c in 0..comps {
        writeln!(w, "    // component {c}").unwrap();
        if c > 0 && p.shared > 0 {
            // The previous component's last stage has read workgroup memory.
            writeln!(w, "    workgroupBarrier();").unwrap();
        }
        let from = if c == 0 {
            From::Global {
                src,
                ib: format!("ib{c}"),
            }
        } else {
            From::Registers(format!("p{c}_"))
        };
        let to = To::Registers(format!("o{c}_"));
        emit_stages(w, p, stages, offsets, post, -1.0, false, &from, &to);
    }
    // This thread's points: j + r Ns for its butterflies j.
    let points = |w: &mut String, body: &dyn Fn(&mut String, u32, &str)| {
        for m in 0..per {
            let partial = (m + 1) * t > nb;
            writeln!(
                w,
                "    {{ let j = {};{}",
                plus("t", m * t),
                if partial {
                    format!(" if (j < {nb}u) {{")
                } else {
                    String::new()
                }
            )
            .unwrap();
            for rr in 0..r {
                body(w, m * r + rr, &plus("j", rr * ns));
            }
            writeln!(w, "    }}{}", if partial { " }" } else { "" }).unwrap();
        }
    };
    writeln!(w, "    // the folded spectral node at this thread's points").unwrap();
    points(w, &|w, i, pos| {
        writeln!(w, "      {{ let q = {pos};").unwrap();
        writeln!(w, "        var v: array<vec2<f32>, SPECTRAL_IN>;").unwrap();
        for c in 0..comps {
            writeln!(w, "        v[{c}] = o{c}_{i};").unwrap();
        }
        let cell = at(&line_base("s", p.out_len, p.out_inner), "q", p.out_inner);
        apply_spectral(w, fold, &cell, "        ");
        for c in 0..comps {
            if p.inverse_after {
                writeln!(w, "        o{c}_{i} = v[{c}];").unwrap();
            } else {
                writeln!(
                    w,
                    "        if (valid) {{ dst[{}] = v[{c}]; }}",
                    at(&format!("ob{c}"), "q", p.out_inner)
                )
                .unwrap();
            }
        }
        writeln!(w, "      }}").unwrap();
    });
    if !p.inverse_after {
        return;
    }
    for c in 0..comps {
        writeln!(w, "    // component {c} back").unwrap();
        // The forward stages (or the previous component's inverse) have read workgroup
        // memory before this component's points go in.
        writeln!(w, "    workgroupBarrier();").unwrap();
        points(w, &|w, i, pos| {
            writeln!(w, "      sh[sidx(ll, {pos})] = o{c}_{i};").unwrap();
        });
        writeln!(w, "    workgroupBarrier();").unwrap();
        let to = To::Global {
            ob: format!("ob{c}"),
            scale: String::new(),
        };
        emit_stages(w, p, stages, offsets, post, 1.0, true, &From::Shared, &to);
    }
}

/// The first stage's loads of one component of a complex pass into registers
/// `{prefix}{i}` ([`From::Registers`]).
fn prefetch(w: &mut String, p: &Pass, (r, _): (u32, u32), src: &str, ib: &str, prefix: &str) {
    assert_eq!(p.load, Load::Complex, "only complex lines are prefetched");
    let t = p.threads_per_line;
    let nb = p.n / r;
    for m in 0..nb.div_ceil(t) {
        for rr in 0..r {
            writeln!(w, "    var {prefix}{}: vec2<f32>;", m * r + rr).unwrap();
        }
        let guard = if (m + 1) * t > nb {
            format!("valid && j < {nb}u")
        } else {
            "valid".into()
        };
        writeln!(w, "    {{ let j = {}; if ({guard}) {{", plus("t", m * t)).unwrap();
        for rr in 0..r {
            writeln!(
                w,
                "        {prefix}{} = {src}[{}];",
                m * r + rr,
                at(ib, &plus("j", rr * nb), p.in_inner)
            )
            .unwrap();
        }
        writeln!(w, "    }} }}").unwrap();
    }
}
