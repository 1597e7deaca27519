//! Spectral operations: functions of the wave vector applied to all components of a
//! spectrum at once. Placed between a forward and an inverse transform they are folded
//! into the forward transform's last pass (see `src/plan/fold.rs`), so a convolution
//! costs no pass over the grid of its own. A kind whose output has another component
//! count than its input (`poisson`: 1 in, 1, 3 or 4 out; `SpectralKind::out_comps`) is
//! not folded and runs as a pass of its own (`src/plan/fold.rs`).
//!
//! Wave vectors are in physical units of the periodic box (lengths Lx, Ly, Lz):
//! k = 2 pi (kx / Lx, ky / Ly, kz / Lz), with signed wave numbers (index i on an axis of n
//! points is i for i <= n/2, else i - n).

use std::f64::consts::PI;

use crate::gpu::DeviceCaps;
use crate::gpu::{CompileCtx, CompileError, Dispatch, NodeIo};
use crate::node::{
    F32_PARAM_MAX, F32_PARAM_MIN, GpuKernels, Lowering, Node, NodeKind, ParamKind, ParamSpec,
    Params, PortError, PortSpec, RefCtx, Registry, Signature, check_f32_coefficient,
};
use crate::transform::SpectralBody;
use crate::value::{PortType, RefArray, ValueType, half_dims};

/// The signed wave number of index `i` on an axis of `n` points (see the module doc).
pub fn wave_number(i: u32, n: u32) -> i64 {
    if i > n / 2 {
        i as i64 - n as i64
    } else {
        i as i64
    }
}

/// The in-plane wave vector (kx, ky) = 2 pi (x / Lx, y / Ly) of every k of a half
/// spectrum of `dims` (x fastest, y signed), and whether each axis is an unpaired Nyquist
/// index there.
pub fn plane_waves(dims: [u32; 3], lengths: [f64; 2]) -> Vec<([f64; 2], [bool; 2])> {
    let h = half_dims(dims);
    let mut out = Vec::with_capacity((h[0] * h[1]) as usize);
    for y in 0..h[1] {
        for x in 0..h[0] {
            let w = [wave_number(x, dims[0]), wave_number(y, dims[1])];
            let k = [0, 1].map(|a| 2.0 * std::f64::consts::PI * w[a] as f64 / lengths[a]);
            let nyq = [0, 1].map(|a| {
                let n = dims[a] as i64;
                n % 2 == 0 && n > 1 && w[a].abs() == n / 2
            });
            out.push((k, nyq));
        }
    }
    out
}

fn box_param() -> ParamSpec {
    ParamSpec {
        name: "box",
        kind: ParamKind::Numbers {
            len: Some(3),
            min: F32_PARAM_MIN,
            max: F32_PARAM_MAX,
        },
        default: Some(crate::expr::ParamValue::Numbers(vec![1.0, 1.0, 1.0])),
        doc: "periodic box lengths (Lx, Ly, Lz): k = 2 pi (kx/Lx, ky/Ly, kz/Lz)",
    }
}

/// One wave vector as the f64 references see it.
#[derive(Clone, Copy, Debug)]
pub struct Mode {
    /// The wave vector in physical units: 2 pi (kx/Lx, ky/Ly, kz/Lz).
    pub k: [f64; 3],
    /// Signed wave numbers (kx in 0..=nx/2 on a half spectrum).
    pub wave: [i64; 3],
    /// Real-space grid dims.
    pub dims: [u32; 3],
    /// Box lengths.
    pub lengths: [f64; 3],
    /// The time step.
    pub step: u64,
}

impl Mode {
    /// Whether the wave number on `axis` is an unpaired Nyquist index (n/2 of an even n),
    /// where odd operators (derivatives) have no consistent real value.
    pub fn nyquist(&self, axis: usize) -> bool {
        let n = self.dims[axis] as i64;
        n % 2 == 0 && self.wave[axis].abs() == n / 2 && n > 1
    }
}

/// The f64 operation at one wave vector on the components, with the kind's own params
/// (after the box lengths). `v` holds the input's components, padded with zeros to the
/// output's count where that is larger; the operation leaves the output's components in
/// its first places.
type Apply = fn(at: &Mode, p: &[f64], v: &mut [[f64; 2]]);

struct SpectralKind {
    name: &'static str,
    doc: &'static str,
    params: fn() -> Vec<ParamSpec>,
    /// Components the operation needs (`None`: any count).
    comps: Option<u32>,
    /// Components of the output for the values and the input's count ([`same_comps`]
    /// for an operation on the components in place). A count other than the input's
    /// keeps the node out of the transforms' passes (`src/plan/fold.rs`).
    out_comps: fn(&[f64], u32) -> u32,
    /// f64 params of the reference: the box lengths, then the kind's own.
    values: fn(&Params) -> Vec<f64>,
    /// The WGSL body with its f32 params (computed in f64 from `values`, rounded once).
    gpu: fn(&[f64]) -> SpectralBody,
    /// Checks the coefficients the body forms from the values for f32
    /// ([`check_f32_coefficient`]), when the node is built.
    coefficients: fn(&[f64]) -> Result<(), String>,
    /// Checks the input spectrum against the values (a noisy Green function needs a half
    /// spectrum, whose Hermitian pairs it knows).
    check: fn(&[f64], &ValueType) -> Result<(), String>,
    apply: Apply,
}

/// The output has the input's components.
fn same_comps(_: &[f64], input: u32) -> u32 {
    input
}

fn any_spectrum(_: &[f64], _: &ValueType) -> Result<(), String> {
    Ok(())
}

/// For bodies whose f32 params are the values themselves (each in its param's range).
fn no_coefficients(_: &[f64]) -> Result<(), String> {
    Ok(())
}

/// The coefficients `stokes_body` forms, within f32's meaningful range: the mobility
/// 1/(4 pi^2 eta q^2) at the smallest wave number (q = 1/L of the longest side, where it
/// is largest), the noise amplitude, and with a split the screening's exponents.
fn stokes_coefficients(v: &[f64]) -> Result<(), String> {
    let eta = v[stokes::VISCOSITY];
    let longest = v[..3].iter().cloned().fold(0.0, f64::max);
    check_f32_coefficient(
        "the mobility at the longest wavelength, `box`^2 / (4 pi^2 `viscosity`)",
        longest * longest / (4.0 * PI * PI * eta),
    )?;
    let volume = v[0] * v[1] * v[2];
    check_f32_coefficient(
        "the noise amplitude `noise` / (2 pi sqrt(`viscosity` `box` volume))",
        v[stokes::NOISE] / (2.0 * PI * (eta * volume).sqrt()),
    )?;
    let split = v[stokes::SPLIT];
    if split != 0.0 {
        let (a, sigma) = (v[stokes::RADIUS], v[stokes::WIDTH]);
        check_f32_coefficient("2 pi `radius`", 2.0 * PI * a)?;
        check_f32_coefficient("pi^2 / `split`^2", PI * PI / (split * split))?;
        check_f32_coefficient(
            "4 pi^2 `width`^2 - pi^2 / `split`^2",
            4.0 * PI * PI * sigma * sigma - PI * PI / (split * split),
        )?;
    }
    Ok(())
}

fn inverse_lengths(v: &[f64]) -> Vec<f32> {
    v[..3].iter().map(|l| (1.0 / l) as f32).collect()
}

fn body(text: &str, params: Vec<f32>) -> SpectralBody {
    SpectralBody {
        body: text.to_string(),
        params,
        ..Default::default()
    }
}

/// Index of the `stokes` values: box (3), viscosity, noise, seed, stream, with_forces,
/// and the Positively Split Ewald screening: radius, split (0: none), width.
mod stokes {
    pub const VISCOSITY: usize = 3;
    pub const NOISE: usize = 4;
    pub const SEED: usize = 5;
    pub const STREAM: usize = 6;
    pub const FORCES: usize = 7;
    pub const RADIUS: usize = 8;
    pub const SPLIT: usize = 9;
    pub const WIDTH: usize = 10;
}

/// The PSE far-field factor on the Stokes operator at |k|^2 = k2 (UAMMD thesis eq. 20.17,
/// digest section 4.2): sinc^2(k a) (1 + k^2 / (4 xi^2)) exp((sigma^2 - 1 / (4 xi^2)) k^2).
/// The last exponential holds Hasimoto's exp(-k^2 / (4 xi^2)) and undoes the two
/// convolutions with the spreading Gaussian of standard deviation sigma; 1 without a split.
pub fn pse_screening(k2: f64, radius: f64, split: f64, width: f64) -> f64 {
    if split == 0.0 {
        return 1.0;
    }
    let ka = k2.sqrt() * radius;
    let sinc = if ka < 1e-8 { 1.0 } else { ka.sin() / ka };
    let q = k2 / (4.0 * split * split);
    sinc * sinc * (1.0 + q) * ((width * width * k2) - q).exp()
}

/// The Stokes solution operator with Fourier-space fluctuations: values are the box,
/// viscosity, noise scale, seed, stream, whether the deterministic part is applied, and
/// the PSE screening. f32 params: 1/L (3), 1/(4 pi^2 eta), noise / (2 pi sqrt(eta V)),
/// seed bits (2), stream bits; with q = k / (2 pi) the mobility is p3 / q^2 and the
/// noise amplitude p4 N / |q| (N cells, V the box volume). With a split, also 2 pi a,
/// pi^2 / xi^2 and 4 pi^2 sigma^2 - pi^2 / xi^2, and the mobility is times
/// [`pse_screening`], the noise times its square root.
fn stokes_body(v: &[f64]) -> SpectralBody {
    let eta = v[stokes::VISCOSITY];
    let noise = v[stokes::NOISE];
    let volume = v[0] * v[1] * v[2];
    let seed = v[stokes::SEED] as u64;
    let mut params = inverse_lengths(v);
    params.push((1.0 / (4.0 * PI * PI * eta)) as f32);
    params.push((noise / (2.0 * PI * (eta * volume).sqrt())) as f32);
    params.push(f32::from_bits(seed as u32));
    params.push(f32::from_bits((seed >> 32) as u32));
    params.push(f32::from_bits(v[stokes::STREAM] as u32));
    let split = v[stokes::SPLIT];
    if split != 0.0 {
        let (a, sigma) = (v[stokes::RADIUS], v[stokes::WIDTH]);
        params.push((2.0 * PI * a) as f32);
        params.push((PI * PI / (split * split)) as f32);
        params.push((4.0 * PI * PI * sigma * sigma - PI * PI / (split * split)) as f32);
    }
    // The projection leaves out unpaired Nyquist wave numbers (n/2 of an even n): a mode
    // there and its conjugate partner, both stored with +n/2, then get the same
    // operator, so the result stays the half spectrum of a real field.
    let mut text = String::from(
        "let q = vec3<f32>(k) * vec3<f32>(spectral_params[0], spectral_params[1], spectral_params[2]);
    let q2 = dot(q, q);
    var u: array<vec2<f32>, 3>;
    if (q2 == 0.0) {
        return u;
    }
    let inv = 1.0 / q2;
    let even = (n % vec3<u32>(2u)) == vec3<u32>(0u);
    let nyquist = (even & (vec3<u32>(abs(k)) == n / vec3<u32>(2u))) & (n > vec3<u32>(1u));
    let p = select(q, vec3<f32>(0.0), nyquist);
    let p2 = dot(p, p);
    let pinv = select(0.0, 1.0 / p2, p2 > 0.0);
",
    );
    if split != 0.0 {
        text.push_str(
            "    let ka = spectral_params[8] * sqrt(q2);
    let sinc = sin(ka) / ka;
    let screen = sinc * sinc * (1.0 + spectral_params[9] * q2) * exp(spectral_params[10] * q2);
",
        );
    } else {
        text.push_str("    let screen = 1.0;\n");
    }
    if v[stokes::FORCES] != 0.0 {
        text.push_str(
            "    let d = (p.x * v[0] + p.y * v[1] + p.z * v[2]) * pinv;
    let b = spectral_params[3] * inv * screen;
    u[0] = b * (v[0] - p.x * d);
    u[1] = b * (v[1] - p.y * d);
    u[2] = b * (v[2] - p.z * d);
",
        );
    }
    let noisy = noise != 0.0;
    if noisy {
        text.push_str(
            "    let z = fourier_normal(k, n, step, bitcast<u32>(spectral_params[5]), bitcast<u32>(spectral_params[6]), bitcast<u32>(spectral_params[7]));
    let dz = (p.x * z[0] + p.y * z[1] + p.z * z[2]) * pinv;
    let c = spectral_params[4] * f32(n.x * n.y * n.z) * sqrt(inv * screen);
    u[0] += c * (z[0] - p.x * dz);
    u[1] += c * (z[1] - p.y * dz);
    u[2] += c * (z[2] - p.z * dz);
",
        );
    }
    text.push_str("    return u;");
    SpectralBody {
        body: text,
        params,
        imports: if noisy {
            vec!["random/fourier_normal.wgsl".into()]
        } else {
            Vec::new()
        },
        uses_step: noisy,
    }
}

fn stokes_apply(at: &Mode, p: &[f64], v: &mut [[f64; 2]]) {
    // p: viscosity, noise, seed, stream, with_forces (after the box).
    let (eta, noise, forces) = (p[0], p[1], p[4] != 0.0);
    let k = at.k;
    let k2 = k[0] * k[0] + k[1] * k[1] + k[2] * k[2];
    let screen = pse_screening(k2, p[5], p[6], p[7]);
    let mut u = [[0.0; 2]; 3];
    if k2 > 0.0 {
        // Unpaired Nyquist wave numbers are left out of the projection (see stokes_body).
        let kp = [0, 1, 2].map(|a| if at.nyquist(a) { 0.0 } else { k[a] });
        let kp2 = kp[0] * kp[0] + kp[1] * kp[1] + kp[2] * kp[2];
        let project = |x: &[[f64; 2]], scale: f64, u: &mut [[f64; 2]; 3]| {
            for part in 0..2 {
                let d = if kp2 > 0.0 {
                    (0..3).map(|i| kp[i] * x[i][part]).sum::<f64>() / kp2
                } else {
                    0.0
                };
                for i in 0..3 {
                    u[i][part] += scale * (x[i][part] - kp[i] * d);
                }
            }
        };
        if forces {
            project(v, screen / (eta * k2), &mut u);
        }
        if noise != 0.0 {
            let cells = at.dims.iter().map(|&d| d as f64).product::<f64>();
            let volume = at.lengths.iter().product::<f64>();
            let z = fourier_normal(at.wave, at.dims, at.step, p[2] as u64, p[3] as u32);
            project(
                &z,
                noise * cells * (screen / (volume * eta * k2)).sqrt(),
                &mut u,
            );
        }
    }
    v.copy_from_slice(&u);
}

/// Complex standard normals for stored mode `wave` of a half spectrum of real grid
/// `dims`, three components: the f64 twin of `fourier_normal` in
/// shaders/random/fourier_normal.wgsl (see there for the pairing rules).
pub fn fourier_normal(
    wave: [i64; 3],
    dims: [u32; 3],
    step: u64,
    seed: u64,
    stream: u32,
) -> [[f64; 2]; 3] {
    let [nx, ny, nz] = dims.map(|d| d as u64);
    let sx = nx / 2 + 1;
    let ix = wave[0] as u64;
    let iy = wave[1].rem_euclid(ny as i64) as u64;
    let iz = wave[2].rem_euclid(nz as i64) as u64;
    let mut m = ix + sx * (iy + ny * iz);
    let (mut conj, mut real) = (false, false);
    if ix == 0 || (nx % 2 == 0 && ix == nx / 2) {
        let pm = ix + sx * ((ny - iy) % ny + ny * ((nz - iz) % nz));
        real = pm == m;
        conj = pm < m;
        m = m.min(pm);
    }
    [0, 1, 2].map(|c| {
        let re = crate::nodes::random::normal(8 * m + 2 * c, step, seed, stream);
        let im = crate::nodes::random::normal(8 * m + 2 * c + 1, step, seed, stream);
        if real {
            [re, 0.0]
        } else {
            let h = std::f64::consts::FRAC_1_SQRT_2;
            [h * re, if conj { -h * im } else { h * im }]
        }
    })
}

fn curl_body(v: &[f64]) -> SpectralBody {
    let params: Vec<f32> = v[..3]
        .iter()
        .map(|l| (2.0 * PI * v[3] / l) as f32)
        .collect();
    body(
        "// Unpaired Nyquist wave numbers carry no derivative.
    let even = (n % vec3<u32>(2u)) == vec3<u32>(0u);
    let ny = (even & (vec3<u32>(abs(k)) == n / vec3<u32>(2u))) & (n > vec3<u32>(1u));
    let q = select(vec3<f32>(k), vec3<f32>(0.0), ny) * vec3<f32>(spectral_params[0], spectral_params[1], spectral_params[2]);
    let w0 = q.y * v[2] - q.z * v[1];
    let w1 = q.z * v[0] - q.x * v[2];
    let w2 = q.x * v[1] - q.y * v[0];
    var u = v;
    u[0] = vec2<f32>(-w0.y, w0.x);
    u[1] = vec2<f32>(-w1.y, w1.x);
    u[2] = vec2<f32>(-w2.y, w2.x);
    return u;",
        params,
    )
}

fn curl_apply(at: &Mode, p: &[f64], v: &mut [[f64; 2]]) {
    let q = [0, 1, 2].map(|a| if at.nyquist(a) { 0.0 } else { p[0] * at.k[a] });
    let x = [v[0], v[1], v[2]];
    for (a, out) in v.iter_mut().enumerate() {
        let (b, c) = ((a + 1) % 3, (a + 2) % 3);
        // (q x v)_a = q_b v_c - q_c v_b, then times i.
        let w = [0, 1].map(|part| q[b] * x[c][part] - q[c] * x[b][part]);
        *out = [-w[1], w[0]];
    }
}

fn stokes_params(noise_default: f64) -> Vec<ParamSpec> {
    vec![
        box_param(),
        ParamSpec::f32_positive("viscosity", None, "solvent viscosity eta"),
        ParamSpec::f32_nonnegative(
            "noise",
            Some(noise_default),
            "factor on the fluctuating velocity M^(1/2) W (0: none, and no random numbers are drawn)",
        ),
        crate::nodes::random::seed_param(),
        crate::nodes::random::stream_param(),
        ParamSpec::f32_nonnegative(
            "split",
            Some(0.0),
            "Positively Split Ewald: the splitting parameter xi of the far field (0: plain Stokes); then the operator is times sinc^2(k a) (1 + k^2/(4 xi^2)) exp((width^2 - 1/(4 xi^2)) k^2)",
        ),
        ParamSpec::f32_positive(
            "radius",
            Some(1.0),
            "with a split: the hydrodynamic radius a of the RPY sinc^2(k a)",
        ),
        ParamSpec::f32_nonnegative(
            "width",
            Some(0.0),
            "with a split: standard deviation sigma of the spreading Gaussian, whose two convolutions the operator undoes",
        ),
    ]
}

fn stokes_values(p: &Params, forces: bool) -> Vec<f64> {
    let b = p.numbers("box");
    vec![
        b[0],
        b[1],
        b[2],
        p.number("viscosity"),
        p.number("noise"),
        p.number("seed"),
        p.number("stream"),
        if forces { 1.0 } else { 0.0 },
        p.number("radius"),
        p.number("split"),
        p.number("width"),
    ]
}

/// Index of the `poisson` values: box (3), permittivity, screening, outputs (0 potential,
/// 1 field, 2 both).
mod poisson {
    pub const PERMITTIVITY: usize = 3;
    pub const SCREENING: usize = 4;
    pub const OUTPUTS: usize = 5;
    pub const CHOICES: &[&str] = &["potential", "field", "both"];
}

/// Components `poisson` writes: phi; Ex, Ey, Ez; or phi, Ex, Ey, Ez.
fn poisson_out_comps(v: &[f64], _: u32) -> u32 {
    [1, 3, 4][v[poisson::OUTPUTS] as usize]
}

/// The coefficients `poisson_body` forms, within f32's meaningful range: the potential's
/// factor at the longest wavelength, `box`^2 / (4 pi^2 eps), and with screening its
/// exponent's factor 2 pi^2 s^2 (on q^2 = (k / 2 pi)^2).
fn poisson_coefficients(v: &[f64]) -> Result<(), String> {
    let eps = v[poisson::PERMITTIVITY];
    let longest = v[..3].iter().cloned().fold(0.0, f64::max);
    check_f32_coefficient(
        "the potential at the longest wavelength, `box`^2 / (4 pi^2 `permittivity`)",
        longest * longest / (4.0 * PI * PI * eps),
    )?;
    let s = v[poisson::SCREENING];
    check_f32_coefficient("2 pi^2 `screening`^2", 2.0 * PI * PI * s * s)
}

/// f32 params: 1/L (3), 1/(4 pi^2 eps), 2 pi^2 s^2; with q = k / (2 pi) (k the physical
/// wave vector), phi = exp(-p4 q^2) p3 f / q^2 and E = -i 2 pi q phi.
fn poisson_body(v: &[f64]) -> SpectralBody {
    let eps = v[poisson::PERMITTIVITY];
    let s = v[poisson::SCREENING];
    let mut params = inverse_lengths(v);
    params.push((1.0 / (4.0 * PI * PI * eps)) as f32);
    params.push((2.0 * PI * PI * s * s) as f32);
    let outputs = v[poisson::OUTPUTS] as usize;
    let mut text = String::from(
        "let q = vec3<f32>(k) * vec3<f32>(spectral_params[0], spectral_params[1], spectral_params[2]);
    let q2 = dot(q, q);
    var u: array<vec2<f32>, SPECTRAL_OUT>;
    if (q2 == 0.0) {
        return u;
    }
    let phi = v[0] * (spectral_params[3] * exp(-spectral_params[4] * q2) / q2);
",
    );
    if outputs != 1 {
        text.push_str("    u[0] = phi;\n");
    }
    if outputs != 0 {
        let first = if outputs == 2 { 1 } else { 0 };
        // -i k phi = k (phi.y, -phi.x); unpaired Nyquist wave numbers carry no derivative.
        text.push_str(&format!(
            "    let even = (n % vec3<u32>(2u)) == vec3<u32>(0u);
    let nyquist = (even & (vec3<u32>(abs(k)) == n / vec3<u32>(2u))) & (n > vec3<u32>(1u));
    let d = select(q, vec3<f32>(0.0), nyquist) * 6.2831855;
    let mi = vec2<f32>(phi.y, -phi.x);
    u[{first}u] = d.x * mi;
    u[{}u] = d.y * mi;
    u[{}u] = d.z * mi;
",
            first + 1,
            first + 2
        ));
    }
    text.push_str("    return u;");
    body(&text, params)
}

/// The f64 twin of `poisson_body`, from the physical wave vector: phi = exp(-s^2 k^2 / 2)
/// f / (eps k^2), E = -i k phi.
fn poisson_apply(at: &Mode, p: &[f64], v: &mut [[f64; 2]]) {
    let (eps, s, outputs) = (p[0], p[1], p[2] as usize);
    let k = at.k;
    let k2 = k[0] * k[0] + k[1] * k[1] + k[2] * k[2];
    let f = v[0];
    v.fill([0.0; 2]);
    if k2 == 0.0 {
        return;
    }
    let g = (-0.5 * s * s * k2).exp() / (eps * k2);
    let phi = [g * f[0], g * f[1]];
    let mut out = Vec::new();
    if outputs != 1 {
        out.push(phi);
    }
    if outputs != 0 {
        for (a, &ka) in k.iter().enumerate() {
            let ka = if at.nyquist(a) { 0.0 } else { ka };
            // -i (x + i y) = y - i x.
            out.push([ka * phi[1], -ka * phi[0]]);
        }
    }
    v[..out.len()].copy_from_slice(&out);
}

static KINDS: &[SpectralKind] = &[
    SpectralKind {
        name: "spectral_filter",
        doc: "Gaussian filter of a spectrum: every component times exp(-sigma^2 |k|^2 / 2), k in units of the box",
        params: || {
            vec![
                ParamSpec::f32_nonnegative("sigma", None, "filter width (a length)"),
                box_param(),
            ]
        },
        comps: None,
        out_comps: same_comps,
        values: |p| {
            let b = p.numbers("box");
            vec![b[0], b[1], b[2], p.number("sigma")]
        },
        // p0 = -sigma^2 (2 pi)^2 / 2, p1..3 = 1/L: exp(p0 |k/L|^2) with integer k.
        gpu: |v| {
            let mut params = vec![(-0.5 * v[3] * v[3] * 4.0 * PI * PI) as f32];
            params.extend(inverse_lengths(v));
            body(
                "let q = vec3<f32>(k) * vec3<f32>(spectral_params[1], spectral_params[2], spectral_params[3]);
    let g = exp(spectral_params[0] * dot(q, q));
    var u = v;
    for (var c = 0u; c < SPECTRAL_IN; c++) {
        u[c] = u[c] * g;
    }
    return u;",
                params,
            )
        },
        coefficients: no_coefficients,
        check: any_spectrum,
        apply: |at, p, v| {
            let k = at.k;
            let g = (-0.5 * p[0] * p[0] * (k[0] * k[0] + k[1] * k[1] + k[2] * k[2])).exp();
            for x in v.iter_mut() {
                x[0] *= g;
                x[1] *= g;
            }
        },
    },
    SpectralKind {
        name: "solenoidal_projection",
        doc: "projection of a 3-component spectrum onto divergence-free fields: (I - k k^T / |k|^2) f; the k = 0 mode is kept",
        params: || vec![box_param()],
        comps: Some(3),
        out_comps: same_comps,
        values: |p| p.numbers("box").to_vec(),
        // Only the direction of k matters: k/L without 2 pi.
        gpu: |v| {
            body(
                "let q = vec3<f32>(k) * vec3<f32>(spectral_params[0], spectral_params[1], spectral_params[2]);
    let q2 = dot(q, q);
    if (q2 == 0.0) {
        return v;
    }
    let h = q * inverseSqrt(q2);
    let d = h.x * v[0] + h.y * v[1] + h.z * v[2];
    var u = v;
    u[0] = v[0] - h.x * d;
    u[1] = v[1] - h.y * d;
    u[2] = v[2] - h.z * d;
    return u;",
                inverse_lengths(v),
            )
        },
        coefficients: no_coefficients,
        check: any_spectrum,
        apply: |at, _, v| {
            let k = at.k;
            let k2 = k[0] * k[0] + k[1] * k[1] + k[2] * k[2];
            if k2 == 0.0 {
                return;
            }
            // k is real: project the real and imaginary parts alike.
            let d = [0, 1].map(|part| (0..3).map(|i| k[i] * v[i][part]).sum::<f64>() / k2);
            for (ki, vi) in k.iter().zip(v.iter_mut()) {
                vi[0] -= ki * d[0];
                vi[1] -= ki * d[1];
            }
        },
    },
    SpectralKind {
        name: "curl",
        doc: "scale * i k x f of a 3-component spectrum (the curl of the field; unpaired Nyquist wave numbers carry no derivative)",
        params: || {
            vec![
                box_param(),
                ParamSpec::f32_factor("scale", Some(1.0), "factor on the curl"),
            ]
        },
        comps: Some(3),
        out_comps: same_comps,
        values: |p| {
            let b = p.numbers("box");
            vec![b[0], b[1], b[2], p.number("scale")]
        },
        gpu: curl_body,
        coefficients: no_coefficients,
        check: any_spectrum,
        apply: curl_apply,
    },
    SpectralKind {
        name: "stokes",
        doc: "periodic Stokes flow of a force density: u = (I - k k^T / k^2) f / (eta k^2), k = 0 mode zero (unpaired Nyquist components left out of the projection); plus noise * M^(1/2) W drawn in Fourier space (FCM's fluctuating stress) when noise > 0; with split > 0 the Positively Split Ewald far field of RPY (times sinc^2(ka) H(k, xi), undoing the spreading Gaussian)",
        params: || stokes_params(0.0),
        comps: Some(3),
        out_comps: same_comps,
        values: |p| stokes_values(p, true),
        gpu: stokes_body,
        coefficients: stokes_coefficients,
        check: |v, t| match t {
            ValueType::ComplexGrid { .. } if v[stokes::NOISE] != 0.0 => Err(format!(
                "noise needs the half spectrum of a real field (rfft), got {t}"
            )),
            _ => Ok(()),
        },
        apply: stokes_apply,
    },
    SpectralKind {
        name: "poisson",
        doc: "periodic Poisson equation of a charge density's spectrum (1 component): phi = exp(-s^2 k^2 / 2) f / (eps k^2) (s the `screening` width: the Gaussian screening of an Ewald split, a Gaussian of variance s^2 convolved once more; 0: none) and the field E = -grad phi = -i k phi, written as `outputs` says: potential (1 component: phi), field (3: Ex, Ey, Ez) or both (4: phi, Ex, Ey, Ez). The k = 0 mode is zero: a uniform neutralising background (a non-neutral density's mean is cancelled). Unpaired Nyquist wave numbers carry no derivative (no field along that axis). Never folded into the transforms' passes (its output has more components than its input): runs as a pass of its own",
        params: || {
            vec![
                box_param(),
                ParamSpec::f32_positive("permittivity", None, "permittivity eps of the medium"),
                ParamSpec::f32_nonnegative(
                    "screening",
                    Some(0.0),
                    "Gaussian screening width s (a length): the spectrum is times exp(-s^2 k^2 / 2)",
                ),
                ParamSpec::choice(
                    "outputs",
                    "both",
                    poisson::CHOICES,
                    "what the output holds: potential (phi), field (Ex, Ey, Ez) or both (phi, Ex, Ey, Ez)",
                ),
            ]
        },
        comps: Some(1),
        out_comps: poisson_out_comps,
        values: |p| {
            let b = p.numbers("box");
            let outputs = poisson::CHOICES
                .iter()
                .position(|c| *c == p.text("outputs"))
                .expect("checked against the choices");
            vec![
                b[0],
                b[1],
                b[2],
                p.number("permittivity"),
                p.number("screening"),
                outputs as f64,
            ]
        },
        gpu: poisson_body,
        coefficients: poisson_coefficients,
        check: any_spectrum,
        apply: poisson_apply,
    },
];

/// The node kind of a table row.
fn spectral_kind(row: &'static SpectralKind) -> NodeKind {
    NodeKind::declare(row.name, row.doc)
        .input(PortSpec::new(
            "x",
            PortType::Spectrum,
            "a spectrum (half spectrum of rfft, or full spectrum of fft)",
        ))
        .output(PortSpec::new(
            "out",
            PortType::Spectrum,
            "the result, on the input's wave vectors (components: the input's, or as the kind's doc says)",
        ))
        .params((row.params)())
        .build(move |params| {
            let values = (row.values)(params);
            if values[..3].iter().any(|&l| l <= 0.0) {
                return Err(format!(
                    "box lengths must be positive, got {:?}",
                    &values[..3]
                ));
            }
            (row.coefficients)(&values)?;
            Ok(Box::new(SpectralNode {
                kind: row,
                body: (row.gpu)(&values),
                values,
            }))
        })
}

struct SpectralNode {
    kind: &'static SpectralKind,
    values: Vec<f64>,
    body: SpectralBody,
}

impl Node for SpectralNode {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let t = inputs
            .first()
            .copied()
            .flatten()
            .ok_or_else(|| PortError::new("x", "a spectral node needs a spectrum"))?;
        let comps = match t {
            ValueType::ComplexGrid { comps, .. } | ValueType::HalfComplexGrid { comps, .. } => {
                comps
            }
            other => return Err(PortError::new("x", format!("{other} is not a spectrum"))),
        };
        if let Some(c) = self.kind.comps
            && c != comps
        {
            return Err(PortError::new(
                "x",
                format!("{} needs {c} components, got {t}", self.kind.name),
            ));
        }
        (self.kind.check)(&self.values, &t).map_err(|e| PortError::new("x", e))?;
        let out_comps = (self.kind.out_comps)(&self.values, comps);
        let out = match t {
            ValueType::ComplexGrid { dims, .. } => ValueType::ComplexGrid {
                dims,
                comps: out_comps,
            },
            ValueType::HalfComplexGrid { dims, .. } => ValueType::HalfComplexGrid {
                dims,
                comps: out_comps,
            },
            other => other,
        };
        Ok(Signature::outputs(vec![out]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Spectral(self.body.clone())
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], cx: RefCtx) {
        let Some(x) = &inputs[0] else { return };
        apply_reference(
            &self.values,
            self.kind.apply,
            Some(x),
            &mut outputs[0],
            cx.step,
        );
    }
}

/// Applies `apply` in f64 to every stored wave vector of the spectrum `input` (zeros of
/// `out`'s count without one, as a generator), writing `out` (the same wave vectors, its
/// own component count); `values` starts with the box lengths.
fn apply_reference(
    values: &[f64],
    apply: Apply,
    input: Option<&RefArray>,
    out: &mut RefArray,
    step: u64,
) {
    let (dims, comps, half) = match out.ty {
        ValueType::ComplexGrid { dims, comps } => (dims, comps as usize, false),
        ValueType::HalfComplexGrid { dims, comps } => (dims, comps as usize, true),
        _ => return,
    };
    let s = if half { half_dims(dims) } else { dims };
    let cells = (s[0] * s[1] * s[2]) as usize;
    let lengths = [values[0], values[1], values[2]];
    let in_comps = match input.map(|x| x.ty) {
        Some(ValueType::ComplexGrid { comps, .. } | ValueType::HalfComplexGrid { comps, .. }) => {
            comps as usize
        }
        _ => comps,
    };
    let mut v = vec![[0.0; 2]; comps.max(in_comps)];
    for cell in 0..cells {
        let c32 = cell as u32;
        let (ix, iy, iz) = (c32 % s[0], (c32 / s[0]) % s[1], c32 / (s[0] * s[1]));
        let kx = if half {
            ix as i64
        } else {
            wave_number(ix, dims[0])
        };
        let wave = [kx, wave_number(iy, dims[1]), wave_number(iz, dims[2])];
        let at = Mode {
            k: [0, 1, 2].map(|a| 2.0 * PI * wave[a] as f64 / lengths[a]),
            wave,
            dims,
            lengths,
            step,
        };
        v.fill([0.0; 2]);
        if let Some(x) = input {
            for (c, vc) in v[..in_comps].iter_mut().enumerate() {
                let i = 2 * (c * cells + cell);
                *vc = [x.data[i], x.data[i + 1]];
            }
        }
        apply(&at, &values[3..], &mut v);
        for (c, vc) in v[..comps].iter().enumerate() {
            let i = 2 * (c * cells + cell);
            out.data[i] = vc[0];
            out.data[i + 1] = vc[1];
        }
    }
}

/// `stokes_noise`: the fluctuating part of `stokes` alone, as a half spectrum generated
/// from nothing (its inverse transform, interpolated, is M^(1/2) W). It draws the same
/// numbers as a `stokes` node with the same seed, stream and step.
fn stokes_noise_kind() -> NodeKind {
    let mut params = stokes_params(1.0);
    params.insert(
        1,
        ParamSpec {
            name: "grid",
            kind: ParamKind::Numbers {
                len: Some(3),
                min: 1.0,
                max: 65536.0,
            },
            default: None,
            doc: "cells per axis of the real-space grid",
        },
    );
    NodeKind::declare(
        "stokes_noise",
        "the half spectrum of noise * M^(1/2) W for periodic Stokes flow (the fluctuating part of `stokes`, with the same draws): its inverse rfft, interpolated, has covariance noise^2 M",
    )
    .output(PortSpec::new(
        "out",
        PortType::HalfComplexGrid,
        "half spectrum of the fluctuating velocity, 3 components",
    ))
    .params(params)
    .build(|params| {
        let values = stokes_values(params, false);
        stokes_coefficients(&values)?;
        let grid = params.numbers("grid");
        if grid.iter().any(|g| g.fract() != 0.0) {
            return Err(format!(
                "`grid` must be whole numbers of cells, got {grid:?}"
            ));
        }
        Ok(Box::new(StokesNoiseNode {
            dims: [grid[0] as u32, grid[1] as u32, grid[2] as u32],
            body: stokes_body(&values),
            values,
        }))
    })
}

struct StokesNoiseNode {
    dims: [u32; 3],
    values: Vec<f64>,
    body: SpectralBody,
}

impl StokesNoiseNode {
    fn ty(&self) -> ValueType {
        ValueType::HalfComplexGrid {
            dims: self.dims,
            comps: 3,
        }
    }
}

impl Node for StokesNoiseNode {
    fn infer(&self, _: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        Ok(Signature::outputs(vec![self.ty()]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn cpu_reference(&self, _: &[Option<RefArray>], outputs: &mut [RefArray], cx: RefCtx) {
        apply_reference(&self.values, stokes_apply, None, &mut outputs[0], cx.step);
    }
}

impl GpuKernels for StokesNoiseNode {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let out = io.outputs[0];
        Ok(vec![crate::transform::standalone_dispatch(
            cx,
            "stokes_noise",
            &self.body,
            None,
            out,
        )?])
    }
}

pub fn register(r: &mut Registry) {
    for row in KINDS {
        r.add(spectral_kind(row));
    }
    r.add(stokes_noise_kind());
}
