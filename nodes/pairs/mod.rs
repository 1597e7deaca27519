//! Pairwise sums: `neighbour_sum` (pairs within a cutoff found through a cell list) and
//! `all_pairs` (every pair, tiled in workgroup memory, for open boundaries and small N).
//! Both apply one pair kernel from [`PairKernel`] and sum per particle:
//!
//! out_i = self(v_i) + sum over j != i with |r_ij| <= cutoff of pair(r_ij, v_j),
//! r_ij = x_i - x_j (the minimum image on periodic axes).
//!
//! A pair kernel is one WGSL file in `shaders/pairs/` defining `pair_term(r, r2, vj)` and
//! `self_term(vi)` (values and results as 4-vectors: a kernel reads the first
//! `value_comps` words of each particle's value row and its result row is the components
//! `out_first ..` of its own (`out_comps` of them; `shaders/pairs/values.wgsl`);
//! `pair_params` and `pair_table` are its f32 words and table), plus its arm in
//! [`PairKernel`] here with the f64 twin: swapping the kernel is changing the `kernel`
//! param. Mobility kernels act on values (forces, 3 in and 3 out): a sum is then a
//! matrix-vector product M v, and can be a Lanczos loop body; the Poisson near field takes
//! charges (1) and gives the potential (1), the field (3) or both (4).
//!
//! The cell list is made of primitives (see `graphs/lib/cell_list.json`): cell_hash in
//! linear order, bin_sort (the order, the count and the first slot of each cell) and a
//! gather of the rows. The sum runs in the sorted order it is given.

pub mod blake;
pub mod poisson;
pub mod rpy;

use std::f64::consts::PI;

use crate::expr::ParamValue;
use crate::gpu::{
    Binding, Choice, CompileCtx, CompileError, DeviceCaps, Dispatch, KernelSpec, NodeIo, WG_1D,
};
use crate::node::{
    GpuKernels, Lowering, Node, NodeKind, ParamKind, ParamSpec, Params, PortError, PortSpec,
    RefCtx, Registry, RowError, Signature, check_f32_coefficient,
};
use crate::value::{HostArray, HostData, PortType, RefArray, ValueType};
use rpy::NearTable;

/// The pair kernels, by name in the `kernel` param.
pub const KERNELS: &[&str] = &[
    "rpy",
    "rpy_near",
    "lj",
    "poisson_near",
    "rpy_wall",
    "nonreciprocal",
];

/// What `poisson_near` and `lj` write: the potential (the energy, for lj), the field (the
/// force, for lj) or both (potential first: phi, Ex, Ey, Ez).
pub const PAIR_OUTPUTS: &[&str] = &["potential", "field", "both"];

/// Index of `field` in [`PAIR_OUTPUTS`].
const FIELD: usize = 1;

/// One pair kernel with its parameters, as built from node params.
#[derive(Clone, Debug, PartialEq)]
pub enum PairKernel {
    /// Free-space Rotne-Prager-Yamakawa mobility (overlap form below 2a): out = M v; with
    /// `rotation` the grand mobility, values (force, torque) and results (velocity, angular
    /// velocity) as 6 columns.
    Rpy {
        radius: f64,
        viscosity: f64,
        rotation: bool,
    },
    /// Rotne-Prager-Blake: RPY above a no-slip wall at z = `wall_height` (see `blake.rs`),
    /// translation only or (`rotation`) the grand mobility.
    RpyWall {
        radius: f64,
        viscosity: f64,
        wall_height: f64,
        rotation: bool,
    },
    /// The near field of RPY under the Positively Split Ewald split with parameter xi,
    /// tabulated in f64 on the host (see `rpy.rs`), linear interpolation on the GPU.
    RpyNear {
        radius: f64,
        viscosity: f64,
        split: f64,
        table: std::sync::Arc<NearTable>,
    },
    /// Lennard-Jones force 24 eps (2 (s/r)^12 - (s/r)^6) r / r^2 (values unused); with
    /// cutoff 2^(1/6) sigma it is the WCA force. Its potential is half of each pair's
    /// energy 4 eps ((s/r)^12 - (s/r)^6) - `shift` (the energy at the cutoff, so it is
    /// continuous there; 0 for an infinite cutoff), so that the particles' potentials add
    /// up to the total energy. `outputs` as for PoissonNear.
    Lj {
        epsilon: f64,
        sigma: f64,
        shift: f64,
        outputs: usize,
    },
    /// The near field of Ewald-split Gaussian charges (see `poisson.rs`): values are
    /// charges; the potential, the field or both (`outputs`, an index into
    /// [`PAIR_OUTPUTS`]). `table` holds (G, G'/r) at equally spaced distances from 0 to
    /// `cutoff`, in f64.
    PoissonNear {
        width: f64,
        permittivity: f64,
        split: f64,
        outputs: usize,
        cutoff: f64,
        table: std::sync::Arc<Vec<[f64; 2]>>,
    },
    /// The non-reciprocal 2-D pair force of S1 eq. 2 (nodes/disks/forces.rs): on i from j,
    /// mu_i alpha_j r / |r|^3 (long range) or r / |r|^7 (`short`), values (alpha, mu) per
    /// particle, the force out (2 columns); positions N x 2.
    Nonreciprocal { short: bool },
}

/// The `outputs` param as an index into [`PAIR_OUTPUTS`].
fn outputs_index(p: &Params) -> usize {
    PAIR_OUTPUTS
        .iter()
        .position(|o| *o == p.text("outputs"))
        .expect("choice checked")
}

impl PairKernel {
    fn from_params(p: &Params, cutoff: f64) -> Result<PairKernel, String> {
        let radius = p.number("radius");
        let viscosity = p.number("viscosity");
        if matches!(p.text("kernel"), "rpy" | "rpy_near" | "rpy_wall") {
            // The coefficients the RPY kernels multiply values by (`words`, the near
            // table's scale), each within f32's meaningful range, so that M v neither
            // overflows nor vanishes.
            check_f32_coefficient(
                "1/(6 pi `viscosity` `radius`)",
                1.0 / (6.0 * PI * viscosity * radius),
            )?;
            check_f32_coefficient("1/(8 pi `viscosity`)", 1.0 / (8.0 * PI * viscosity))?;
            if p.flag("rotation") {
                check_f32_coefficient(
                    "1/(8 pi `viscosity` `radius`^3)",
                    1.0 / (8.0 * PI * viscosity * radius.powi(3)),
                )?;
            }
        }
        Ok(match p.text("kernel") {
            "rpy" => PairKernel::Rpy {
                radius,
                viscosity,
                rotation: p.flag("rotation"),
            },
            "rpy_wall" => PairKernel::RpyWall {
                radius,
                viscosity,
                wall_height: p.number("wall_height"),
                rotation: p.flag("rotation"),
            },
            "rpy_near" => {
                let split = p.number("split");
                if split <= 0.0 {
                    return Err("kernel rpy_near needs `split` (the Ewald parameter xi) > 0".into());
                }
                if !cutoff.is_finite() || cutoff <= 0.0 {
                    return Err(format!(
                        "kernel rpy_near needs a positive finite `cutoff` (its table ends there), got {cutoff}"
                    ));
                }
                let points = p.number("table_points") as usize;
                PairKernel::RpyNear {
                    radius,
                    viscosity,
                    split,
                    table: NearTable::shared(radius, viscosity, split, cutoff, points)?,
                }
            }
            "lj" => {
                let (epsilon, sigma) = (p.number("epsilon"), p.number("sigma"));
                check_f32_coefficient("`sigma`^2", sigma * sigma)?;
                check_f32_coefficient("24 `epsilon`", 24.0 * epsilon)?;
                let shift = if cutoff.is_finite() && cutoff > 0.0 {
                    let s6 = (sigma / cutoff).powi(6);
                    4.0 * epsilon * (s6 * s6 - s6)
                } else {
                    0.0
                };
                PairKernel::Lj {
                    epsilon,
                    sigma,
                    shift,
                    outputs: outputs_index(p),
                }
            }
            "poisson_near" => {
                let (width, split, permittivity) = (
                    p.number("width"),
                    p.number("split"),
                    p.number("permittivity"),
                );
                if split <= 0.0 {
                    return Err(
                        "kernel poisson_near needs `split` (the Ewald parameter xi) > 0".into(),
                    );
                }
                if !cutoff.is_finite() || cutoff <= 0.0 {
                    return Err(format!(
                        "kernel poisson_near needs a positive finite `cutoff` (its table ends there), got {cutoff}"
                    ));
                }
                check_f32_coefficient(
                    "the self potential (1/`width` - 1/g_t) / (4 pi^(3/2) `permittivity`)",
                    poisson::self_potential(width, split, permittivity),
                )?;
                let points = (p.number("table_points") as usize).max(2);
                let step = cutoff / (points - 1) as f64;
                let table = (0..points)
                    .map(|i| {
                        let (g, _, slope_over_r) =
                            poisson::near_terms(i as f64 * step, width, split, permittivity);
                        [g, slope_over_r]
                    })
                    .collect();
                PairKernel::PoissonNear {
                    width,
                    permittivity,
                    split,
                    outputs: outputs_index(p),
                    cutoff,
                    table: std::sync::Arc::new(table),
                }
            }
            "nonreciprocal" => PairKernel::Nonreciprocal {
                short: p.text("law") == "short",
            },
            other => unreachable!("choice checked: {other}"),
        })
    }

    /// Columns of the positions the kernel takes: 2 for the plane's nonreciprocal law,
    /// 3 for the others.
    pub fn dims(&self) -> u32 {
        match self {
            PairKernel::Nonreciprocal { .. } => 2,
            _ => 3,
        }
    }

    /// Words of each particle's value row the kernel reads.
    pub fn value_comps(&self) -> u32 {
        match self {
            PairKernel::PoissonNear { .. } => 1,
            PairKernel::Nonreciprocal { .. } => 2,
            PairKernel::Rpy { rotation: true, .. } | PairKernel::RpyWall { rotation: true, .. } => {
                6
            }
            _ => 3,
        }
    }

    /// The first component of the kernel's 4-vector result that the row holds.
    pub fn out_first(&self) -> u32 {
        match self {
            PairKernel::PoissonNear { outputs, .. } | PairKernel::Lj { outputs, .. } => {
                u32::from(*outputs == FIELD)
            }
            _ => 0,
        }
    }

    /// Components of each particle's result row.
    pub fn out_comps(&self) -> u32 {
        match self {
            PairKernel::PoissonNear { outputs, .. } | PairKernel::Lj { outputs, .. } => {
                [1, 3, 4][*outputs]
            }
            PairKernel::Nonreciprocal { .. } => 2,
            PairKernel::Rpy { rotation: true, .. } | PairKernel::RpyWall { rotation: true, .. } => {
                6
            }
            _ => 3,
        }
    }

    pub fn name(&self) -> &'static str {
        match self {
            PairKernel::Rpy { .. } => "rpy",
            PairKernel::RpyWall { .. } => "rpy_wall",
            PairKernel::RpyNear { .. } => "rpy_near",
            PairKernel::Lj { .. } => "lj",
            PairKernel::PoissonNear { .. } => "poisson_near",
            PairKernel::Nonreciprocal { .. } => "nonreciprocal",
        }
    }

    /// The kernel's WGSL with the row shapes the traversals read (`values.wgsl`).
    fn source(&self, cx: &CompileCtx<'_>) -> Result<String, CompileError> {
        Ok(format!(
            "const VALUE_COMPS: u32 = {}u;\nconst OUT_FIRST: u32 = {}u;\nconst OUT_COMPS: u32 = {}u;\n{}",
            self.value_comps(),
            self.out_first(),
            self.out_comps(),
            cx.shader(&format!("pairs/{}.wgsl", self.name()))?
        ))
    }

    /// Whether the kernel reads the values (a product M v) or only positions (forces).
    pub fn uses_values(&self) -> bool {
        !matches!(self, PairKernel::Lj { .. })
    }

    /// The `pair_params` words, computed in f64 and rounded once.
    fn words(&self) -> Vec<f32> {
        match self {
            PairKernel::Rpy {
                radius, viscosity, ..
            } => vec![
                *radius as f32,
                (1.0 / (6.0 * PI * viscosity * radius)) as f32,
                (1.0 / (8.0 * PI * viscosity)) as f32,
                (1.0 / (8.0 * PI * viscosity * radius.powi(3))) as f32,
            ],
            PairKernel::RpyWall {
                radius,
                viscosity,
                wall_height,
                ..
            } => vec![
                *radius as f32,
                (1.0 / (6.0 * PI * viscosity * radius)) as f32,
                (1.0 / (8.0 * PI * viscosity)) as f32,
                (1.0 / (8.0 * PI * viscosity * radius.powi(3))) as f32,
                (1.0 / (8.0 * PI * viscosity * radius * radius)) as f32,
                *wall_height as f32,
            ],
            PairKernel::RpyNear { table, .. } => {
                let last = (table.f.len() - 1) as f64;
                vec![(last / table.cutoff) as f32, last as f32]
            }
            PairKernel::Lj {
                epsilon,
                sigma,
                shift,
                ..
            } => {
                vec![
                    (24.0 * epsilon) as f32,
                    (sigma * sigma) as f32,
                    (2.0 * epsilon) as f32,
                    (0.5 * shift) as f32,
                ]
            }
            PairKernel::PoissonNear { table, cutoff, .. } => {
                let last = (table.len() - 1) as f64;
                vec![(last / cutoff) as f32, last as f32]
            }
            PairKernel::Nonreciprocal { short } => vec![f32::from(u8::from(*short))],
        }
    }

    /// The `pair_table` words: (f, g) interleaved for the tabulated near field.
    fn table(&self) -> Vec<f32> {
        match self {
            PairKernel::RpyNear { table, .. } => table
                .f
                .iter()
                .zip(&table.g)
                .flat_map(|(f, g)| [*f as f32, *g as f32])
                .collect(),
            PairKernel::PoissonNear { table, .. } => table
                .iter()
                .flat_map(|[g, s]| [*g as f32, *s as f32])
                .collect(),
            _ => vec![0.0],
        }
    }

    /// The f64 twin of `pair_term`: the contribution of j (at xj, value vj) to i (at xi,
    /// value vi) at r = x_i - x_j (the minimum image), as the kernel's 8 words (the row is
    /// `out_first ..`).
    pub fn pair(&self, xi: [f64; 3], xj: [f64; 3], r: [f64; 3], vi: Row, vj: Row) -> Row {
        let cross = |a: [f64; 3], b: [f64; 3]| {
            [
                a[1] * b[2] - a[2] * b[1],
                a[2] * b[0] - a[0] * b[2],
                a[0] * b[1] - a[1] * b[0],
            ]
        };
        let v3 = |v: [f64; 3]| [v[0], v[1], v[2], 0.0, 0.0, 0.0, 0.0, 0.0];
        let vj4 = vj;
        let vj = [vj[0], vj[1], vj[2]];
        let r2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
        let d = r2.sqrt();
        let tensor = |f: f64, g: f64| {
            // f v + g (r^ . v) r^, with r^ r^ taken as 0 for coincident particles (g
            // vanishes there for the mobilities).
            let rv = if r2 > 0.0 {
                (r[0] * vj[0] + r[1] * vj[1] + r[2] * vj[2]) / r2
            } else {
                0.0
            };
            [0, 1, 2].map(|c| f * vj[c] + g * rv * r[c])
        };
        match self {
            PairKernel::Rpy {
                radius,
                viscosity,
                rotation,
            } => {
                let (f, g) = rpy::rpy(d, *radius, *viscosity);
                let u = tensor(f, g);
                if !rotation {
                    return v3(u);
                }
                let t = torque(&vj4, true);
                let (fr, gr) = rpy::rpy_rotation(d, *radius, *viscosity);
                let rt = if r2 > 0.0 {
                    (r[0] * t[0] + r[1] * t[1] + r[2] * t[2]) / r2
                } else {
                    0.0
                };
                let c = rpy::rpy_coupling(d, *radius, *viscosity);
                let (tr, fr_) = (cross(t, r), cross(vj, r));
                [
                    u[0] + c * tr[0],
                    u[1] + c * tr[1],
                    u[2] + c * tr[2],
                    fr * t[0] + gr * rt * r[0] + c * fr_[0],
                    fr * t[1] + gr * rt * r[1] + c * fr_[1],
                    fr * t[2] + gr * rt * r[2] + c * fr_[2],
                    0.0,
                    0.0,
                ]
            }
            PairKernel::RpyWall {
                radius,
                viscosity,
                wall_height,
                rotation,
            } => {
                let t = torque(&vj4, *rotation);
                let (u, w) = blake::blake(xi, xj, vj, t, *radius, *viscosity, *wall_height, false);
                [u[0], u[1], u[2], w[0], w[1], w[2], 0.0, 0.0]
            }
            PairKernel::RpyNear { table, .. } => {
                let (f, g) = table.at(d);
                v3(tensor(f, g))
            }
            PairKernel::Lj {
                epsilon,
                sigma,
                shift,
                ..
            } => {
                let s6 = (sigma * sigma / r2).powi(3);
                let c = 24.0 * epsilon * (2.0 * s6 * s6 - s6) / r2;
                let half = 2.0 * epsilon * (s6 * s6 - s6) - 0.5 * shift;
                [half, c * r[0], c * r[1], c * r[2], 0.0, 0.0, 0.0, 0.0]
            }
            PairKernel::PoissonNear {
                width,
                permittivity,
                split,
                ..
            } => {
                // The exact near field, not the table: the tests bound the table's error.
                let (g, _, slope_over_r) = poisson::near_terms(d, *width, *split, *permittivity);
                let q = vj4[0];
                [
                    q * g,
                    -q * slope_over_r * r[0],
                    -q * slope_over_r * r[1],
                    -q * slope_over_r * r[2],
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                ]
            }
            PairKernel::Nonreciprocal { short } => {
                let w = if r2 == 0.0 {
                    0.0
                } else if *short {
                    r2.powf(-3.5)
                } else {
                    r2.powf(-1.5)
                };
                let c = vi[1] * vj4[0] * w;
                [c * r[0], c * r[1], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
            }
        }
    }

    /// The f64 twin of `self_term`, for particle i at xi with value vi.
    pub fn self_term(&self, xi: [f64; 3], vi: Row) -> Row {
        match self {
            PairKernel::Rpy {
                radius,
                viscosity,
                rotation,
            } => {
                let mut row = vi.map(|v| v / (6.0 * PI * viscosity * radius));
                if *rotation {
                    for c in 3..6 {
                        row[c] = vi[c] / (8.0 * PI * viscosity * radius.powi(3));
                    }
                }
                row
            }
            PairKernel::RpyWall {
                radius,
                viscosity,
                wall_height,
                rotation,
            } => {
                let f = [vi[0], vi[1], vi[2]];
                let t = torque(&vi, *rotation);
                let (u, w) = blake::blake(xi, xi, f, t, *radius, *viscosity, *wall_height, true);
                [u[0], u[1], u[2], w[0], w[1], w[2], 0.0, 0.0]
            }
            PairKernel::RpyNear { table, .. } => vi.map(|v| table.f[0] * v),
            PairKernel::Lj { .. } | PairKernel::Nonreciprocal { .. } => [0.0; 8],
            PairKernel::PoissonNear {
                width,
                permittivity,
                split,
                ..
            } => {
                let mut row = [0.0; 8];
                row[0] = vi[0] * poisson::self_potential(*width, *split, *permittivity);
                row
            }
        }
    }

    fn describe(&self) -> String {
        match self {
            PairKernel::Rpy {
                radius,
                viscosity,
                rotation,
            } => format!(
                "RPY mobility{}, radius {radius}, viscosity {viscosity}",
                if *rotation {
                    " (forces and torques)"
                } else {
                    ""
                }
            ),
            PairKernel::RpyWall {
                radius,
                viscosity,
                wall_height,
                rotation,
            } => format!(
                "Rotne-Prager-Blake mobility{} above the wall z = {wall_height}, radius {radius}, viscosity {viscosity}",
                if *rotation {
                    " (forces and torques)"
                } else {
                    ""
                }
            ),
            PairKernel::RpyNear {
                radius,
                viscosity,
                split,
                table,
            } => format!(
                "PSE near-field RPY, radius {radius}, viscosity {viscosity}, split {split}: table of {} points to r = {:.6} (self term {:.6e})",
                table.f.len(),
                table.cutoff,
                table.f[0]
            ),
            PairKernel::Lj {
                epsilon,
                sigma,
                shift,
                outputs,
            } => format!(
                "Lennard-Jones ({}: energy and force), epsilon {epsilon}, sigma {sigma}, energy shifted by {shift:e}",
                PAIR_OUTPUTS[*outputs]
            ),
            PairKernel::PoissonNear {
                width,
                permittivity,
                split,
                outputs,
                cutoff,
                table,
            } => format!(
                "Poisson near field of Gaussian charges ({}), width {width}, permittivity {permittivity}, split {split}: table of {} points to r = {cutoff:.6} (self potential {:.6e})",
                PAIR_OUTPUTS[*outputs],
                table.len(),
                table[0][0]
            ),
            PairKernel::Nonreciprocal { short } => format!(
                "non-reciprocal 2-D force mu_i alpha_j r/|r|^{} (S1 eq. 2)",
                if *short { 7 } else { 3 }
            ),
        }
    }
}

fn kernel_params() -> Vec<ParamSpec> {
    vec![
        ParamSpec::choice(
            "kernel",
            "rpy",
            KERNELS,
            "the pair kernel: rpy (free-space RPY mobility times values; with `rotation` forces and torques, N x 6), rpy_wall (RPY above a no-slip wall at `wall_height`, Rotne-Prager-Blake with Swan and Brady's corrections; open boundaries, all_pairs only), rpy_near (PSE near field of RPY), lj (Lennard-Jones force; WCA with cutoff 2^(1/6) sigma), poisson_near (near field of Ewald-split Gaussian charges: charges in (N x 1), potential, field or both out), nonreciprocal (S1's 2-D force mu_i alpha_j r/|r|^3 or r/|r|^7, `law`: positions N x 2, values (alpha, mu) N x 2, forces N x 2 out)",
        ),
        ParamSpec::f32_positive("radius", Some(1.0), "rpy, rpy_near: hydrodynamic radius a"),
        ParamSpec::f32_positive("viscosity", Some(1.0), "rpy, rpy_near: viscosity eta"),
        ParamSpec::flag(
            "rotation",
            false,
            "rpy, rpy_wall: the grand mobility: values are forces and torques, results velocities and angular velocities (N x 6 each)",
        ),
        ParamSpec::f32_factor(
            "wall_height",
            Some(0.0),
            "rpy_wall: the height of the no-slip wall (the plane z = wall_height); particle centres must lie above it",
        ),
        ParamSpec::f32_nonnegative(
            "split",
            Some(0.0),
            "rpy_near, poisson_near: Ewald splitting parameter xi (> 0)",
        ),
        ParamSpec::f32_positive(
            "width",
            Some(1.0),
            "poisson_near: the charges' Gaussian standard deviation a",
        ),
        ParamSpec::f32_positive(
            "permittivity",
            Some(1.0),
            "poisson_near: permittivity eps of the medium",
        ),
        ParamSpec::choice(
            "outputs",
            "field",
            PAIR_OUTPUTS,
            "poisson_near, lj: what each row holds: potential (phi; lj: the energy, half of each pair's truncated and shifted energy), field (Ex, Ey, Ez; lj: the force) or both (the potential, then the field)",
        ),
        ParamSpec::integer(
            "table_points",
            Some(4096.0),
            16.0,
            (1u64 << 22) as f64,
            "rpy_near, poisson_near: points of the f64-computed table from 0 to the cutoff",
        ),
        ParamSpec::f32_nonnegative("epsilon", Some(1.0), "lj: energy scale"),
        ParamSpec::f32_positive("sigma", Some(1.0), "lj: length scale"),
        ParamSpec::choice(
            "law",
            "short",
            &["long", "short"],
            "nonreciprocal: long r/|r|^3 or short r/|r|^7",
        ),
    ]
}

fn value_inputs() -> Vec<PortSpec> {
    vec![
        PortSpec::new(
            "positions",
            PortType::Particles(None),
            "positions (N x 3; N x 2 for the plane's kernel nonreciprocal)",
        ),
        PortSpec::new(
            "values",
            PortType::Particles(None),
            "the row each particle carries (forces, N x 3, for a mobility product; charges, N x 1, for poisson_near); unused by force kernels",
        )
        .optional(),
    ]
}

fn out_port() -> Vec<PortSpec> {
    vec![PortSpec::new(
        "out",
        PortType::Particles(None),
        "per particle: self(v_i) + sum over neighbours j of pair(x_i - x_j, v_j) (3 columns; poisson_near 1, 3 or 4)",
    )]
}

/// Checks positions and values, returning N.
fn check_rows(kernel: &PairKernel, inputs: &[Option<ValueType>]) -> Result<u32, PortError> {
    let Some(ValueType::Particles { n, k: dims }) = inputs[0] else {
        unreachable!("port type checked")
    };
    if dims != kernel.dims() {
        return Err(PortError::new(
            "positions",
            format!(
                "has {dims} columns; kernel {} takes positions of {} (N x {})",
                kernel.name(),
                kernel.dims(),
                kernel.dims()
            ),
        ));
    }
    match inputs[1] {
        Some(ValueType::Particles { n: m, .. }) if m != n => Err(PortError::new(
            "values",
            format!("has {m} rows but positions has {n}"),
        )),
        Some(ValueType::Particles { k, .. })
            if kernel.uses_values() && k != kernel.value_comps() =>
        {
            let hint = match kernel {
                PairKernel::Rpy { .. } | PairKernel::RpyWall { .. } => {
                    " (3: forces; 6: forces and torques, with `rotation`)"
                }
                _ => "",
            };
            Err(PortError::new(
                "values",
                format!(
                    "has {k} columns; kernel {} reads {} per particle{hint}",
                    kernel.name(),
                    kernel.value_comps()
                ),
            ))
        }
        None if kernel.uses_values() => Err(PortError::new(
            "values",
            format!("kernel {} multiplies values: connect them", kernel.name()),
        )),
        _ => Ok(n),
    }
}

/// Row i of `dims` (2 or 3) columns as a 3-vector (z = 0 in the plane).
fn row(data: &[f64], dims: usize, i: usize) -> [f64; 3] {
    let mut x = [0.0; 3];
    x[..dims].copy_from_slice(&data[dims * i..dims * (i + 1)]);
    x
}

/// A kernel's value or result row: 8 words (`shaders/pairs/values.wgsl` `Row`).
pub type Row = [f64; 8];

/// The torque of a (force, torque) row, zero without `rotation`.
fn torque(row: &Row, rotation: bool) -> [f64; 3] {
    if rotation {
        [row[3], row[4], row[5]]
    } else {
        [0.0; 3]
    }
}

/// Row i of `comps` columns as a kernel's 8 words (zeros after the row).
fn row8(data: &[f64], comps: usize, i: usize) -> Row {
    let mut v = [0.0; 8];
    v[..comps].copy_from_slice(&data[comps * i..comps * (i + 1)]);
    v
}

/// The f64 O(N^2) reference shared by both nodes: every pair, minimum image on the
/// periodic axes of `lengths` (empty: open boundaries).
fn reference_sum(
    kernel: &PairKernel,
    lengths: &[f64],
    periodic: &[bool],
    cutoff: f64,
    inputs: &[Option<RefArray>],
    out: &mut [f64],
) {
    let pos = &inputs[0].as_ref().expect("required").data;
    let dims = kernel.dims() as usize;
    let n = pos.len() / dims;
    let (vc, first, oc) = (
        kernel.value_comps() as usize,
        kernel.out_first() as usize,
        kernel.out_comps() as usize,
    );
    let zero = vec![0.0; n * vc];
    let vals = inputs[1].as_ref().map(|v| &v.data).unwrap_or(&zero);
    // The cutoff is compared as the GPU does, squared in f32.
    let cut2 = (cutoff as f32 * cutoff as f32) as f64;
    for i in 0..n {
        let xi = row(pos, dims, i);
        let vi = row8(vals, vc, i);
        let mut acc = kernel.self_term(xi, vi);
        for j in 0..n {
            if j == i {
                continue;
            }
            let xj = row(pos, dims, j);
            let mut r = [0.0; 3];
            for a in 0..3 {
                r[a] = xi[a] - xj[a];
                if a < lengths.len() && periodic[a] {
                    r[a] -= lengths[a] * (r[a] / lengths[a]).round();
                }
            }
            let r2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
            if r2 <= cut2 {
                let t = kernel.pair(xi, xj, r, vi, row8(vals, vc, j));
                for a in 0..8 {
                    acc[a] += t[a];
                }
            }
        }
        out[oc * i..oc * (i + 1)].copy_from_slice(&acc[first..first + oc]);
    }
}

fn pair_buffers(cx: &CompileCtx<'_>, kernel: &PairKernel) -> (wgpu::Buffer, wgpu::Buffer) {
    let words = kernel.words();
    let table = kernel.table();
    (
        cx.table("pair params", bytemuck::cast_slice(&words)),
        cx.table("pair table", bytemuck::cast_slice(&table)),
    )
}

fn box_spec(doc: &'static str, required: bool) -> ParamSpec {
    ParamSpec {
        name: "box",
        kind: ParamKind::Numbers {
            len: None,
            min: f64::MIN_POSITIVE,
            max: f64::MAX,
        },
        default: if required {
            None
        } else {
            Some(ParamValue::Numbers(vec![1.0, 1.0, 1.0]))
        },
        doc,
    }
}

fn neighbour_sum_kind() -> NodeKind {
    let mut inputs = value_inputs();
    inputs[0].doc = "positions, sorted by cell (the cell list's order)";
    NodeKind::declare(
        "neighbour_sum",
        "per particle, self term plus the pair kernel summed over neighbours within the cutoff, found through a cell list (27 cells; periodic minimum image)",
    )
    .inputs(inputs)
    .input(PortSpec::new(
        "cells",
        PortType::Indices,
        "linear cell index of each (sorted) particle: cell_hash keys after the sort (a key past the cells counts as the last cell)",
    ))
    .input(PortSpec::new(
        "cell_start",
        PortType::Indices,
        "first particle of each cell (exclusive scan of the counts; clamped to N)",
    ))
    .input(PortSpec::new(
        "cell_count",
        PortType::Indices,
        "particles in each cell (clamped to N - first: no slot past the particles)",
    ))
    .input(
        PortSpec::new(
            "list",
            PortType::Indices,
            "neighbour list from neighbour_list (same positions and cutoff): read instead of the cells for particles it holds whole (an entry past the particles counts as the last particle)",
        )
        .optional(),
    )
    .input(
        PortSpec::new(
            "list_count",
            PortType::Indices,
            "neighbours of each particle, from neighbour_list",
        )
        .optional(),
    )
    .outputs(out_port())
    .param(box_spec(
        "box lengths (Lx, Ly, Lz), centred at the origin; (Lx, Ly) for positions in a plane (N x 2)",
        true,
    ))
    .param(ParamSpec {
        name: "cells",
        kind: ParamKind::Numbers {
            len: None,
            min: 1.0,
            max: 1024.0,
        },
        default: None,
        doc: "cells per axis of the cell list (cell size >= cutoff), as many as box lengths",
    })
    .param(ParamSpec {
        name: "periodic",
        kind: ParamKind::Numbers {
            len: None,
            min: 0.0,
            max: 1.0,
        },
        default: Some(ParamValue::Numbers(vec![1.0, 1.0, 1.0])),
        doc: "1 for a periodic axis (minimum image), 0 for an open one, as many as box lengths (the default, 3 periodic axes, suits a 3-D box only)",
    })
    .param(ParamSpec::number(
        "cutoff",
        None,
        0.0,
        f64::MAX,
        "pairs with |r| <= cutoff are summed",
    ))
    .param(ParamSpec::integer(
        "lanes",
        Some(0.0),
        0.0,
        32.0,
        "subgroup lanes per particle walking its candidates together: 0 (auto): 8 where the adapter's subgroups hold at least 8 lanes, else 1; 1: one thread per particle; 2, 4, 8, 16 or 32: that many, refused where subgroups are narrower",
    ))
    .params(kernel_params())
    .build(|p| {
        let lanes = match p.number("lanes") as u32 {
            0 => Lanes::Auto,
            1 => Lanes::Off,
            n if n.is_power_of_two() => Lanes::Fixed(n),
            n => {
                return Err(format!(
                    "`lanes` must be 0 (auto), 1 or a power of two up to 32, got {n}"
                ));
            }
        };
        let lengths = p.numbers("box").to_vec();
        let cells: Vec<u32> = p.numbers("cells").iter().map(|&c| c as u32).collect();
        if p.numbers("cells").iter().any(|c| c.fract() != 0.0) {
            return Err(format!(
                "`cells` must be whole numbers, got {:?}",
                p.numbers("cells")
            ));
        }
        let periodic: Vec<bool> = p.numbers("periodic").iter().map(|&x| x == 1.0).collect();
        let cutoff = p.number("cutoff");
        check_geometry(&lengths, &cells, &periodic, cutoff)?;
        if p.text("kernel") == "rpy_wall" {
            return Err("kernel rpy_wall sums every pair above a wall in open space: use it in all_pairs".into());
        }
        Ok(Box::new(NeighbourSum {
            kernel: PairKernel::from_params(p, cutoff)?,
            lengths,
            cells,
            periodic,
            cutoff,
            lanes,
        }))
    })
}

/// The cell list must find every pair within the cutoff among 3 cells per axis, and the
/// minimum image must be unique.
fn check_geometry(
    lengths: &[f64],
    cells: &[u32],
    periodic: &[bool],
    cutoff: f64,
) -> Result<(), String> {
    let dims = lengths.len();
    if !(2..=3).contains(&dims) || cells.len() != dims || periodic.len() != dims {
        return Err(format!(
            "`box`, `cells` and `periodic` must have one entry per axis, 2 (a plane) or 3, got {dims}, {} and {}",
            cells.len(),
            periodic.len()
        ));
    }
    if cells.contains(&0) {
        return Err(format!(
            "`cells` must be at least 1 per axis, got {cells:?}"
        ));
    }
    let mut problems = Vec::new();
    for a in 0..dims {
        let size = lengths[a] / cells[a] as f64;
        if size < cutoff {
            problems.push(format!(
                "cells along axis {a} are {size} wide, less than the cutoff {cutoff}: use at most {} cells",
                (lengths[a] / cutoff).floor().max(1.0)
            ));
        }
        if periodic[a] && 2.0 * cutoff > lengths[a] {
            problems.push(format!(
                "the cutoff {cutoff} exceeds half the periodic box along axis {a} ({}): the minimum image would miss pairs",
                lengths[a]
            ));
        }
    }
    if problems.is_empty() {
        Ok(())
    } else {
        Err(problems.join("; "))
    }
}

/// The positions have a column per axis of the box.
fn check_dims(positions: Option<ValueType>, axes: usize) -> Result<(), PortError> {
    match positions {
        Some(ValueType::Particles { k, .. }) if k as usize != axes => Err(PortError::new(
            "positions",
            format!("has {k} columns but the box has {axes} axes"),
        )),
        _ => Ok(()),
    }
}

/// How `neighbour_sum` walks a particle's candidates on an adapter: a segment of `lanes`
/// subgroup lanes together, or one thread (`None`). Decided once, in `infer`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Traversal {
    lanes: Option<u32>,
}

impl std::fmt::Display for Traversal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.lanes {
            Some(seg) => write!(f, "strategy: {seg} subgroup lanes a particle"),
            None => f.write_str("strategy: one thread a particle"),
        }
    }
}

/// How many subgroup lanes walk one particle's candidates (the `lanes` param).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Lanes {
    Auto,
    Off,
    Fixed(u32),
}

pub struct NeighbourSum {
    pub kernel: PairKernel,
    lengths: Vec<f64>,
    cells: Vec<u32>,
    periodic: Vec<bool>,
    cutoff: f64,
    lanes: Lanes,
}

impl NeighbourSum {
    fn cell_count(&self) -> u32 {
        self.cells.iter().product()
    }

    /// Lanes per particle on this device (None: one thread per particle). Segments must
    /// lie inside one subgroup, so at most its smallest size.
    fn segment(&self, caps: &DeviceCaps) -> Result<Traversal, String> {
        let min = caps
            .subgroups
            .map(|(min, _)| min)
            .filter(|m| m.is_power_of_two());
        let lanes = match (self.lanes, min) {
            (Lanes::Off, _) => None,
            (Lanes::Auto, Some(min)) if min >= 8 => Some(8),
            (Lanes::Auto, _) => None,
            (Lanes::Fixed(seg), Some(min)) if seg <= min => Some(seg),
            (Lanes::Fixed(seg), _) => {
                return Err(format!(
                    "lanes = {seg} needs subgroups of at least {seg} lanes; this adapter has {}",
                    match caps.subgroups {
                        Some((a, b)) => format!("{a} to {b}"),
                        None => "no subgroup operations".into(),
                    }
                ));
            }
        };
        Ok(Traversal { lanes })
    }
}

impl Node for NeighbourSum {
    fn infer(
        &self,
        inputs: &[Option<ValueType>],
        caps: &DeviceCaps,
    ) -> Result<Signature, PortError> {
        let n = check_rows(&self.kernel, inputs)?;
        check_dims(inputs[0], self.lengths.len())?;
        let Some(ValueType::Indices { n: keys }) = inputs[2] else {
            unreachable!("port type checked")
        };
        if keys != n {
            return Err(PortError::new(
                "cells",
                format!("has {keys} entries but positions has {n} rows"),
            ));
        }
        for (port, i) in [("cell_start", 3), ("cell_count", 4)] {
            let Some(ValueType::Indices { n: c }) = inputs[i] else {
                unreachable!("port type checked")
            };
            if c != self.cell_count() {
                return Err(PortError::new(
                    port,
                    format!(
                        "has {c} entries but the cell list has {:?} = {} cells",
                        self.cells,
                        self.cell_count()
                    ),
                ));
            }
        }
        match (inputs[5], inputs[6]) {
            (None, None) => {}
            (Some(ValueType::Indices { n: l }), Some(ValueType::Indices { n: c })) => {
                if c != n {
                    return Err(PortError::new(
                        "list_count",
                        format!("has {c} entries but positions has {n} rows"),
                    ));
                }
                if n > 0 && l % n != 0 {
                    return Err(PortError::new(
                        "list",
                        format!("has {l} entries, not a whole number per particle ({n})"),
                    ));
                }
            }
            (Some(_), None) => {
                return Err(PortError::new(
                    "list_count",
                    "a neighbour list needs its counts: connect list_count too",
                ));
            }
            (None, Some(_)) => {
                return Err(PortError::new(
                    "list",
                    "list_count without the list: connect list too",
                ));
            }
            _ => unreachable!("port types checked"),
        }
        Ok(Signature::outputs(vec![ValueType::Particles {
            n,
            k: self.kernel.out_comps(),
        }])
        .with_plan(Choice(self.segment(caps))))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn notes(&self, _: &[Option<ValueType>]) -> Vec<String> {
        let size: Vec<String> = (0..self.lengths.len())
            .map(|a| format!("{:.4}", self.lengths[a] / self.cells[a] as f64))
            .collect();
        vec![
            self.kernel.describe(),
            format!(
                "cutoff {}, {:?} cells of size ({})",
                self.cutoff,
                self.cells,
                size.join(", ")
            ),
        ]
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        reference_sum(
            &self.kernel,
            &self.lengths,
            &self.periodic,
            self.cutoff,
            inputs,
            &mut outputs[0].data,
        );
    }
}

/// Layout of the `Geometry` uniform of shaders/pairs/cells.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct NeighbourGeometry {
    lengths: [f32; 4],
    cells: [u32; 4],
    periodic: [u32; 4],
    n: u32,
    cutoff2: f32,
    pad: [u32; 2],
}

impl NeighbourGeometry {
    fn new(lengths: &[f64], cells: &[u32], periodic: &[bool], n: u32, cutoff: f64) -> Self {
        let mut g = NeighbourGeometry {
            lengths: [1.0; 4],
            cells: [1; 4],
            periodic: [0; 4],
            n,
            cutoff2: (cutoff as f32) * (cutoff as f32),
            pad: [0; 2],
        };
        // A plane's z axis: one open cell of length 1 (the walk visits offset 0 only).
        for a in 0..lengths.len() {
            g.lengths[a] = lengths[a] as f32;
            g.cells[a] = cells[a];
            g.periodic[a] = u32::from(periodic[a]);
        }
        g
    }
}

impl GpuKernels for NeighbourSum {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let pos = io.inputs[0].expect("required");
        let ValueType::Particles { n, .. } = pos.ty else {
            unreachable!()
        };
        let values = io.inputs[1].map(|v| v.buffer);
        let seg = io.plan::<Choice<Traversal>>().get()?.lanes;
        let source = format!(
            "{}{}",
            self.kernel.source(cx)?,
            cx.shader(if seg.is_some() {
                "pairs/neighbour_sum_lanes.wgsl"
            } else {
                "pairs/neighbour_sum.wgsl"
            })?
        );
        let mut b = vec![Binding::StorageRead; 5];
        b.extend([
            Binding::StorageReadWrite,
            Binding::Uniform,
            Binding::StorageRead,
            Binding::StorageRead,
        ]);
        b.extend([Binding::StorageRead, Binding::StorageRead]);
        let list = io.inputs[5];
        let width = match list {
            Some(l) if n > 0 => (l.ty.words() / n as u64) as u32,
            _ => 0,
        };
        let mut spec = KernelSpec::new(
            format!(
                "neighbour_sum ({}{}{})",
                self.kernel.name(),
                if list.is_some() { ", list" } else { "" },
                seg.map(|s| format!(", {s} lanes")).unwrap_or_default()
            ),
            source,
            &b,
        )
        .constant("HAS_VALUES", f64::from(u8::from(values.is_some())))
        .constant("LIST_WIDTH", width as f64)
        .constant("DIM", self.lengths.len() as f64);
        if let Some(s) = seg {
            spec = spec.constant("SEG", s as f64);
        }
        let kernel = cx.kernel(&spec)?;
        let g = NeighbourGeometry::new(&self.lengths, &self.cells, &self.periodic, n, self.cutoff);
        let geo = cx.uniform("neighbour geometry", bytemuck::bytes_of(&g));
        let (params, table) = pair_buffers(cx, &self.kernel);
        let buffers = [
            pos.buffer,
            values.unwrap_or(pos.buffer),
            io.inputs[2].expect("required").buffer,
            io.inputs[3].expect("required").buffer,
            io.inputs[4].expect("required").buffer,
            io.outputs[0].buffer,
            &geo,
            &params,
            &table,
            list.map(|l| l.buffer).unwrap_or(pos.buffer),
            io.inputs[6].map(|l| l.buffer).unwrap_or(pos.buffer),
        ];
        let threads = n as u64 * seg.unwrap_or(1) as u64;
        Ok(vec![cx.dispatch(
            &kernel,
            &buffers,
            cx.grid_1d(threads, WG_1D),
        )])
    }
}

fn neighbour_list_kind() -> NodeKind {
    // The cell list and its geometry are neighbour_sum's.
    let sum = neighbour_sum_kind();
    let inputs = sum
        .inputs()
        .iter()
        .filter(|p| !matches!(p.name, "values" | "list" | "list_count"))
        .cloned();
    let geometry = sum
        .params()
        .iter()
        .filter(|p| matches!(p.name, "box" | "cells" | "periodic" | "cutoff"))
        .cloned();
    NodeKind::declare(
        "neighbour_list",
        "the neighbours within the cutoff of each particle, found through a cell list, as a list neighbour_sum reads instead of the cells (worth it when one list serves many sums: a Lanczos loop)",
    )
    .inputs(inputs)
    .output(PortSpec::new(
        "list",
        PortType::Indices,
        "max_neighbours entries per particle, neighbour k of particle i at k * N + i",
    ))
    .output(PortSpec::new(
        "count",
        PortType::Indices,
        "neighbours of each particle (past max_neighbours the list holds the first ones, and neighbour_sum walks the cells for that particle)",
    ))
    .params(geometry)
    .param(ParamSpec::integer(
        "max_neighbours",
        None,
        1.0,
        4096.0,
        "list entries per particle (a particle with more is summed from the cells: correct, slower)",
    ))
    .build(|p| {
        if p.numbers("cells").iter().any(|c| c.fract() != 0.0) {
            return Err(format!(
                "`cells` must be whole numbers, got {:?}",
                p.numbers("cells")
            ));
        }
        let list = NeighbourList {
            lengths: p.numbers("box").to_vec(),
            cells: p.numbers("cells").iter().map(|&c| c as u32).collect(),
            periodic: p.numbers("periodic").iter().map(|&x| x == 1.0).collect(),
            cutoff: p.number("cutoff"),
            width: p.number("max_neighbours") as u32,
        };
        check_geometry(&list.lengths, &list.cells, &list.periodic, list.cutoff)?;
        Ok(Box::new(list))
    })
}

pub struct NeighbourList {
    lengths: Vec<f64>,
    cells: Vec<u32>,
    periodic: Vec<bool>,
    cutoff: f64,
    width: u32,
}

impl Node for NeighbourList {
    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let Some(ValueType::Particles { n, .. }) = inputs[0] else {
            unreachable!("port type checked")
        };
        check_dims(inputs[0], self.lengths.len())?;
        let cells: u32 = self.cells.iter().product();
        for (port, i, want) in [
            ("cells", 1, n),
            ("cell_start", 2, cells),
            ("cell_count", 3, cells),
        ] {
            let Some(ValueType::Indices { n: m }) = inputs[i] else {
                unreachable!("port type checked")
            };
            if m != want {
                return Err(PortError::new(
                    port,
                    format!("has {m} entries, expected {want}"),
                ));
            }
        }
        let entries = n as u64 * self.width as u64;
        if entries > u32::MAX as u64 {
            return Err(PortError::new(
                "positions",
                format!(
                    "{n} particles x {} neighbours do not fit one list",
                    self.width
                ),
            ));
        }
        Ok(Signature::outputs(vec![
            ValueType::Indices { n: entries as u32 },
            ValueType::Indices { n },
        ]))
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn notes(&self, inputs: &[Option<ValueType>]) -> Vec<String> {
        let n = match inputs[0] {
            Some(ValueType::Particles { n, .. }) => n as u64,
            _ => 0,
        };
        vec![format!(
            "up to {} neighbours per particle within {} ({} MiB)",
            self.width,
            self.cutoff,
            (4 * n * self.width as u64) >> 20
        )]
    }

    /// The reference list holds every neighbour in the order the GPU finds them (cells
    /// by z, y, x offset, then the cell's particles), so it compares entry by entry.
    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        let pos = &inputs[0].as_ref().expect("required").data;
        let keys = &inputs[1].as_ref().expect("required").data;
        let start = &inputs[2].as_ref().expect("required").data;
        let count = &inputs[3].as_ref().expect("required").data;
        let dims = self.lengths.len();
        let n = pos.len() / dims;
        let [nx, ny, nz] = [0, 1, 2].map(|a| self.cells.get(a).copied().unwrap_or(1) as i64);
        let cut2 = (self.cutoff as f32 * self.cutoff as f32) as f64;
        let width = self.width as usize;
        outputs[0].data.fill(u32::MAX as f64);
        for i in 0..n {
            let key = keys[i] as i64;
            let c = [key % nx, (key / nx) % ny, key / (nx * ny)];
            let n3 = [nx, ny, nz];
            let range = |a: usize| -> (i64, i64) {
                if a < dims && self.periodic[a] {
                    if n3[a] >= 3 { (-1, 1) } else { (0, n3[a] - 1) }
                } else {
                    ((-1i64).max(-c[a]), 1i64.min(n3[a] - 1 - c[a]))
                }
            };
            let mut found = 0usize;
            let (zr, yr, xr) = (range(2), range(1), range(0));
            for dz in zr.0..=zr.1 {
                for dy in yr.0..=yr.1 {
                    for dx in xr.0..=xr.1 {
                        let cc = [
                            (c[0] + dx).rem_euclid(nx),
                            (c[1] + dy).rem_euclid(ny),
                            (c[2] + dz).rem_euclid(nz),
                        ];
                        let cell = (cc[0] + nx * (cc[1] + ny * cc[2])) as usize;
                        let first = start[cell] as usize;
                        for j in first..first + count[cell] as usize {
                            if j == i {
                                continue;
                            }
                            let mut r2 = 0.0;
                            for a in 0..dims {
                                let mut d = pos[dims * i + a] - pos[dims * j + a];
                                if self.periodic[a] {
                                    d -= self.lengths[a] * (d / self.lengths[a]).round();
                                }
                                r2 += d * d;
                            }
                            if r2 <= cut2 {
                                if found < width {
                                    outputs[0].data[found * n + i] = j as f64;
                                }
                                found += 1;
                            }
                        }
                    }
                }
            }
            outputs[1].data[i] = found as f64;
        }
    }
}

impl GpuKernels for NeighbourList {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let pos = io.inputs[0].expect("required");
        let ValueType::Particles { n, .. } = pos.ty else {
            unreachable!()
        };
        let mut b = vec![Binding::StorageRead; 4];
        b.extend([
            Binding::StorageReadWrite,
            Binding::StorageReadWrite,
            Binding::Uniform,
        ]);
        let kernel = cx.kernel(
            &KernelSpec::new(
                "neighbour_list",
                cx.shader("pairs/neighbour_list.wgsl")?,
                &b,
            )
            .constant("LIST_WIDTH", self.width as f64)
            .constant("DIM", self.lengths.len() as f64),
        )?;
        let g = NeighbourGeometry::new(&self.lengths, &self.cells, &self.periodic, n, self.cutoff);
        let geo = cx.uniform("neighbour geometry", bytemuck::bytes_of(&g));
        let list = io.outputs[0].buffer;
        Ok(vec![
            cx.fill(list, io.outputs[0].ty.words(), u32::MAX)?,
            cx.dispatch(
                &kernel,
                &[
                    pos.buffer,
                    io.inputs[1].expect("required").buffer,
                    io.inputs[2].expect("required").buffer,
                    io.inputs[3].expect("required").buffer,
                    list,
                    io.outputs[1].buffer,
                    &geo,
                ],
                cx.grid_1d(n as u64, WG_1D),
            ),
        ])
    }
}

/// Particles per tile of shaders/pairs/all_pairs.wgsl (its workgroup size).
const TILE: u32 = 128;

/// Words of pair params all_pairs.wgsl keeps in registers (its PAIR_PARAMS).
const ALL_PAIRS_PARAMS: usize = 8;

/// Threads all_pairs aims to launch: several times what a large GPU holds at once (an
/// H100/H200 holds about 270 000), so that N of a few thousand fills it too.
const ALL_PAIRS_THREADS: u64 = 1 << 20;

/// The runs of j tiles all_pairs cuts the sums into, and tiles per run: `requested` (at
/// most one a tile; 0: enough that N threads per run reach ALL_PAIRS_THREADS, each run
/// keeping at least 2 tiles), so that every run but the last is full.
fn all_pairs_slices(n: u32, requested: u32) -> (u32, u32) {
    let tiles = n.div_ceil(TILE).max(1);
    let slices = if requested > 0 {
        requested.min(tiles)
    } else {
        let wanted = ALL_PAIRS_THREADS
            .div_ceil(n.max(1) as u64)
            .min(u32::MAX as u64) as u32;
        wanted.clamp(1, (tiles / 2).max(1))
    };
    let per = tiles.div_ceil(slices);
    (tiles.div_ceil(per), per)
}

fn all_pairs_kind() -> NodeKind {
    NodeKind::declare(
        "all_pairs",
        "per particle, self term plus the pair kernel summed over every other particle within the cutoff (open boundaries; tiled in workgroup memory, O(N^2))",
    )
    .inputs(value_inputs())
    .outputs(out_port())
    .param(ParamSpec::number(
        "cutoff",
        Some(f64::MAX),
        0.0,
        f64::MAX,
        "pairs with |r| <= cutoff are summed (default: all)",
    ))
    .param(ParamSpec::integer(
        "slices",
        Some(0.0),
        0.0,
        65535.0,
        "runs of the j tiles summed apart and then added in order (tuning; 0: enough that about 10^6 threads run, each run at least 2 tiles of 128)",
    ))
    .params(kernel_params())
    .build(|p| {
        let cutoff = p.number("cutoff");
        if p.text("kernel") == "nonreciprocal" {
            return Err("kernel nonreciprocal is the plane's law: use nonreciprocal_forces for all pairs, neighbour_sum for a cutoff".into());
        }
        if matches!(p.text("kernel"), "rpy_near" | "poisson_near") {
            return Err(format!("kernel {} is the near field of a periodic split: use it in neighbour_sum", p.text("kernel")));
        }
        Ok(Box::new(AllPairs {
            kernel: PairKernel::from_params(p, cutoff)?,
            cutoff,
            slices: p.number("slices") as u32,
        }))
    })
}

pub struct AllPairs {
    kernel: PairKernel,
    cutoff: f64,
    slices: u32,
}

impl Node for AllPairs {
    /// Above a wall, every particle's centre lies above it (as libMobility refuses).
    fn checks_input(&self) -> bool {
        true
    }

    fn check_input(&self, port: usize, data: &HostArray) -> Result<(), RowError> {
        let PairKernel::RpyWall { wall_height, .. } = self.kernel else {
            return Ok(());
        };
        let (0, ValueType::Particles { k: 3, .. }, HostData::F32(values)) =
            (port, data.ty, &data.data)
        else {
            return Ok(());
        };
        for (row, x) in values.chunks_exact(3).enumerate() {
            if x.iter().any(|c| !c.is_finite()) {
                return Err(RowError::new(row, format!("position {x:?} is not finite")));
            }
            if (x[2] as f64) < wall_height {
                return Err(RowError::new(
                    row,
                    format!(
                        "z = {} is below the wall at wall_height = {wall_height}: a particle's centre must lie above the wall",
                        x[2]
                    ),
                ));
            }
        }
        Ok(())
    }

    fn infer(&self, inputs: &[Option<ValueType>], _: &DeviceCaps) -> Result<Signature, PortError> {
        let n = check_rows(&self.kernel, inputs)?;
        let k = self.kernel.out_comps();
        let signature = Signature::outputs(vec![ValueType::Particles { n, k }]);
        let (slices, _) = all_pairs_slices(n, self.slices);
        Ok(if slices > 1 {
            // The slices' partial sums.
            signature.with_scratch(vec![4 * slices as u64 * n as u64 * k as u64])
        } else {
            signature
        })
    }

    fn lowering(&self) -> Lowering<'_> {
        Lowering::Kernels(self)
    }

    fn notes(&self, inputs: &[Option<ValueType>]) -> Vec<String> {
        let n = match inputs[0] {
            Some(ValueType::Particles { n, .. }) => n as u64,
            _ => 0,
        };
        let (slices, per) = all_pairs_slices(n as u32, self.slices);
        vec![
            self.kernel.describe(),
            format!(
                "{} pairs in tiles of {TILE}, the j tiles in {slices} run{} of {per}",
                n * n.saturating_sub(1),
                if slices == 1 { "" } else { "s" }
            ),
        ]
    }

    fn cpu_reference(&self, inputs: &[Option<RefArray>], outputs: &mut [RefArray], _: RefCtx) {
        reference_sum(
            &self.kernel,
            &[],
            &[],
            self.cutoff,
            inputs,
            &mut outputs[0].data,
        );
    }
}

impl GpuKernels for AllPairs {
    fn compile(
        &self,
        cx: &mut CompileCtx<'_>,
        io: &NodeIo<'_>,
    ) -> Result<Vec<Dispatch>, CompileError> {
        let pos = io.inputs[0].expect("required");
        let ValueType::Particles { n, .. } = pos.ty else {
            unreachable!()
        };
        let values = io.inputs[1].map(|v| v.buffer);
        // all_pairs.wgsl copies the params into registers, PAIR_PARAMS words of them.
        if self.kernel.words().len() > ALL_PAIRS_PARAMS {
            return Err(CompileError::Unsupported(format!(
                "all_pairs holds {ALL_PAIRS_PARAMS} words of pair params, kernel {} has {}",
                self.kernel.name(),
                self.kernel.words().len()
            )));
        }
        let source = format!(
            "{}{}",
            self.kernel.source(cx)?,
            cx.shader("pairs/all_pairs.wgsl")?
        );
        let kernel = cx.kernel(
            &KernelSpec::new(
                format!("all_pairs ({})", self.kernel.name()),
                source,
                &[
                    Binding::StorageRead,
                    Binding::StorageRead,
                    Binding::StorageReadWrite,
                    Binding::Uniform,
                    Binding::StorageRead,
                    Binding::StorageRead,
                ],
            )
            .constant("HAS_VALUES", f64::from(u8::from(values.is_some()))),
        )?;
        let cut = self.cutoff.min(f32::MAX.sqrt() as f64 * 0.5) as f32;
        let (slices, per) = all_pairs_slices(n, self.slices);
        let shape = cx.uniform(
            "all_pairs shape",
            bytemuck::cast_slice(&[n, (cut * cut).to_bits(), per, slices]),
        );
        let (params, table) = pair_buffers(cx, &self.kernel);
        let sums = if slices > 1 {
            io.scratch[0]
        } else {
            io.outputs[0].buffer
        };
        let [gx, gy, _] = cx.grid_1d(n as u64, TILE);
        let mut dispatches = vec![cx.dispatch(
            &kernel,
            &[
                pos.buffer,
                values.unwrap_or(pos.buffer),
                sums,
                &shape,
                &params,
                &table,
            ],
            [gx, gy, slices],
        )];
        if slices > 1 {
            let words = n * self.kernel.out_comps();
            let sum = cx.kernel(&KernelSpec::new(
                "all_pairs_sum",
                cx.shader("pairs/all_pairs_sum.wgsl")?,
                &[
                    Binding::StorageRead,
                    Binding::StorageReadWrite,
                    Binding::Uniform,
                ],
            ))?;
            let shape = cx.uniform(
                "all_pairs_sum shape",
                bytemuck::cast_slice(&[words, slices]),
            );
            dispatches.push(cx.dispatch(
                &sum,
                &[sums, io.outputs[0].buffer, &shape],
                cx.grid_1d(words as u64, 256),
            ));
        }
        Ok(dispatches)
    }
}

pub fn register(r: &mut Registry) {
    r.add(neighbour_sum_kind());
    r.add(neighbour_list_kind());
    r.add(all_pairs_kind());
}
