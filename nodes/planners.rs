//! Host-side planners graph files can call in param expressions, all in f64: an
//! FFT-friendly size, the FCM grid and window from a radius and a tolerance, Hasimoto's
//! periodic correction. Each is a thin wrapper over its node family's planner.

use crate::expr::{HostFunction, ParamValue};
use crate::node::Registry;
use crate::nodes::fcm::plan;
use crate::nodes::pse;

fn number(args: &[ParamValue], i: usize, what: &str) -> Result<f64, String> {
    match args.get(i) {
        Some(ParamValue::Number(x)) => Ok(*x),
        Some(other) => Err(format!(
            "argument {} ({what}) must be a number, got {}",
            i + 1,
            other.type_name()
        )),
        None => Err(format!("argument {} ({what}) is missing", i + 1)),
    }
}

fn positive(args: &[ParamValue], i: usize, what: &str) -> Result<f64, String> {
    let x = number(args, i, what)?;
    if x > 0.0 && x.is_finite() {
        Ok(x)
    } else {
        Err(format!(
            "argument {} ({what}) must be positive, got {x}",
            i + 1
        ))
    }
}

fn nonnegative(args: &[ParamValue], i: usize, what: &str) -> Result<f64, String> {
    let x = number(args, i, what)?;
    if x >= 0.0 && x.is_finite() {
        Ok(x)
    } else {
        Err(format!(
            "argument {} ({what}) must be zero or positive, got {x}",
            i + 1
        ))
    }
}

fn flag(args: &[ParamValue], i: usize, what: &str) -> Result<bool, String> {
    match args.get(i) {
        Some(ParamValue::Bool(b)) => Ok(*b),
        Some(ParamValue::Number(x)) => Ok(*x != 0.0),
        Some(other) => Err(format!(
            "argument {} ({what}) must be a boolean, got {}",
            i + 1,
            other.type_name()
        )),
        None => Err(format!("argument {} ({what}) is missing", i + 1)),
    }
}

fn numbers<'a>(args: &'a [ParamValue], i: usize, what: &str) -> Result<&'a [f64], String> {
    match args.get(i) {
        Some(ParamValue::Numbers(x)) => Ok(x),
        Some(other) => Err(format!(
            "argument {} ({what}) must be an array of numbers, got {}",
            i + 1,
            other.type_name()
        )),
        None => Err(format!("argument {} ({what}) is missing", i + 1)),
    }
}

fn text<'a>(args: &'a [ParamValue], i: usize, what: &str) -> Result<&'a str, String> {
    match args.get(i) {
        Some(ParamValue::Text(x)) => Ok(x),
        Some(other) => Err(format!(
            "argument {} ({what}) must be a string, got {}",
            i + 1,
            other.type_name()
        )),
        None => Err(format!("argument {} ({what}) is missing", i + 1)),
    }
}

/// The smallest cell size over the axes.
fn finest_cell(lengths: &[f64], cells: &[u32]) -> f64 {
    lengths
        .iter()
        .zip(cells)
        .map(|(l, &n)| l / n as f64)
        .fold(f64::INFINITY, f64::min)
}

/// A grid argument (cells per axis) as u32s: each a whole number from 1 to the longest
/// FFT axis, and the grid within `MAX_GRID_CELLS`, checked before any conversion.
fn grid_cells(args: &[ParamValue], i: usize) -> Result<Vec<u32>, String> {
    let what = format!("argument {} (grid)", i + 1);
    let cells = numbers(args, i, "grid")?
        .iter()
        .map(|&n| {
            if n.fract() != 0.0 {
                return Err(format!("{what}: {n} is not a whole number of cells"));
            }
            crate::nodes::fft::plan::cells_per_axis(&what, n)
        })
        .collect::<Result<Vec<u32>, String>>()?;
    crate::nodes::fft::plan::checked_grid(&what, cells)
}

/// A tolerance argument: strictly between 0 and 1 (its logarithm sets supports).
fn tolerance(args: &[ParamValue], i: usize) -> Result<f64, String> {
    let t = number(args, i, "tolerance")?;
    plan::check_tolerance(t).map_err(|e| format!("argument {} ({e})", i + 1))?;
    Ok(t)
}

/// A box argument: lengths positive and finite.
fn box_lengths(args: &[ParamValue], i: usize) -> Result<&[f64], String> {
    let lengths = numbers(args, i, "box")?;
    match lengths.iter().find(|l| !(**l > 0.0 && l.is_finite())) {
        Some(l) => Err(format!(
            "argument {} (box): lengths must be positive and finite, got {l}",
            i + 1
        )),
        None => Ok(lengths),
    }
}

fn arity(args: &[ParamValue], n: usize) -> Result<(), String> {
    if args.len() == n {
        Ok(())
    } else {
        Err(format!("takes {n} arguments, got {}", args.len()))
    }
}

/// Every host function.
static FUNCTIONS: &[HostFunction] = &[
    HostFunction {
        name: "dpstokes_plan",
        doc: "dpstokes_plan(box, radius, tolerance, zmin, zmax, walls, rotation, kernel): the doubly periodic Stokes grid and windows, [nx, ny, points, zlo, zhi, support, torque_support, width, torque_width, beta, torque_beta]. kernel es: ES windows with a half-width as a length (radius exactly a on any grid), FCM's ES cells and beta at the tolerance for forces, a cell more for torques; kernel gaussian: FCM's Gaussians (a / sqrt(pi); torques a / (6 sqrt(pi))^(1/3)) at FCM's cells per standard deviation. FFT-friendly x and y (fine enough for the torque window with rotation); the Chebyshev domain [zlo, zhi] is [zmin, zmax] padded by the half support on each open side; points so the mid-height spacing is at most the x cell",
        call: |a| {
            arity(a, 8)?;
            let lengths = box_lengths(a, 0)?;
            let radius = positive(a, 1, "radius")?;
            let t = tolerance(a, 2)?;
            let zmin = number(a, 3, "zmin")?;
            let zmax = number(a, 4, "zmax")?;
            let walls = text(a, 5, "walls")?;
            let rotation = flag(a, 6, "rotation")?;
            let kernel = text(a, 7, "kernel")?;
            crate::nodes::stokes_slab::plan(lengths, radius, t, zmin, zmax, walls, rotation, kernel)
                .map(ParamValue::Numbers)
        },
    },
    HostFunction {
        name: "dpstokes_slab",
        doc: "dpstokes_slab(slab, points, grid): how lib/dpstokes_mobility.json solves between its Chebyshev transforms, 'fused' (slab_solve's one kernel, a wave number's lines in registers, from the forcing's coefficients), 'lanes' (slab_solve's lanes kernel, a wave number's line over subgroup lanes), 'staged' (slab_solve's staged kernel, from the forcing's values along z: no forward chebyshev dispatch) or 'chain' (the nodes one by one): slab as given, auto the staged kernel up to slab_solve's STAGED_UP_TO wave numbers (grid [nx, ny]: (nx / 2 + 1) ny of them), the fused one past them, the chain past slab_solve's points",
        call: |a| {
            arity(a, 3)?;
            let points = number(a, 1, "points")?;
            let grid = numbers(a, 2, "grid")?;
            if grid.len() < 2 || grid.iter().any(|g| !(g.is_finite() && *g >= 1.0)) {
                return Err(format!(
                    "argument 3 (grid) must hold 2 cell counts, got {grid:?}"
                ));
            }
            let waves = (grid[0] as u64 / 2 + 1) * grid[1] as u64;
            let path = match text(a, 0, "slab")? {
                p @ ("fused" | "lanes" | "staged" | "chain") => p,
                "auto" if points > crate::nodes::slab_solve::MAX_POINTS as f64 => "chain",
                "auto" if waves <= crate::nodes::slab_solve::STAGED_UP_TO => "staged",
                "auto" => "fused",
                other => {
                    return Err(format!(
                        "slab must be auto, fused, lanes, staged or chain, got `{other}`"
                    ));
                }
            };
            Ok(ParamValue::Text(path.into()))
        },
    },
    HostFunction {
        name: "next_fft",
        doc: "next_fft(n): the smallest size >= n whose prime factors are 2, 3, 5 and 7",
        call: |a| {
            arity(a, 1)?;
            let n = number(a, 0, "size")?;
            if !(0.0..=4096.0 * 4096.0).contains(&n) {
                return Err(format!("size {n} is out of range"));
            }
            Ok(ParamValue::Number(
                crate::nodes::fft::next_friendly(n.ceil() as u32) as f64,
            ))
        },
    },
    HostFunction {
        name: "poisson_cutoff",
        doc: "poisson_cutoff(width, split, tolerance, box): the smallest distance at which the Ewald-split Poisson near field of Gaussian charges (standard deviation width) has fallen to tolerance of its value at 0 (G(0)) and its field to tolerance of its peak (computed in f64); refused past half the smallest box length; 0 for split 0 (unsplit: no near field)",
        call: |a| {
            arity(a, 4)?;
            let width = positive(a, 0, "width")?;
            let split = nonnegative(a, 1, "split")?;
            let t = tolerance(a, 2)?;
            let lengths = box_lengths(a, 3)?;
            crate::nodes::poisson::cutoff(width, split, t, lengths).map(ParamValue::Number)
        },
    },
    HostFunction {
        name: "poisson_split",
        doc: "poisson_split(width, tolerance, box): the Ewald split xi the Poisson cost model finds cheapest for charges of this width (0: unsplit, everything on the grid)",
        call: |a| {
            arity(a, 3)?;
            let width = positive(a, 0, "width")?;
            let t = tolerance(a, 1)?;
            crate::nodes::poisson::default_split(width, t, box_lengths(a, 2)?)
                .map(ParamValue::Number)
        },
    },
    HostFunction {
        name: "poisson_far_width",
        doc: "poisson_far_width(width, split): the far field's Gaussian standard deviation g_t = sqrt(width^2 + 1 / (4 split^2)) (width itself for split 0)",
        call: |a| {
            arity(a, 2)?;
            let width = positive(a, 0, "width")?;
            let split = nonnegative(a, 1, "split")?;
            Ok(ParamValue::Number(crate::nodes::poisson::far_width(
                width, split,
            )))
        },
    },
    HostFunction {
        name: "poisson_grid",
        doc: "poisson_grid(box, far_width, tolerance): the far field's cells per axis, UAMMD's rule h = (1.3 - min(-0.1 log10 tol, 0.9)) g_t, at least 32 per axis, rounded up to a full-rate FFT size",
        call: |a| {
            arity(a, 3)?;
            let lengths = box_lengths(a, 0)?;
            let g = positive(a, 1, "far_width")?;
            let t = tolerance(a, 2)?;
            let grid = crate::nodes::poisson::grid(lengths, g, t)?;
            Ok(ParamValue::Numbers(
                grid.into_iter().map(f64::from).collect(),
            ))
        },
    },
    HostFunction {
        name: "poisson_support",
        doc: "poisson_support(box, grid, far_width, tolerance): the far field's Gaussian support in cells (where it falls to the tolerance of its peak, at least 3)",
        call: |a| {
            arity(a, 4)?;
            let lengths = box_lengths(a, 0)?;
            let grid = grid_cells(a, 1)?;
            let g = positive(a, 2, "far_width")?;
            let t = tolerance(a, 3)?;
            crate::nodes::poisson::support(lengths, &grid, g, t)
                .map(|p| ParamValue::Number(p as f64))
        },
    },
    HostFunction {
        name: "poisson_cells",
        doc: "poisson_cells(box, cutoff, grid): cells per axis of the cell list that orders the charges (at least the cutoff wide; unsplit, cutoff 0, coarse cells for spreading locality)",
        call: |a| {
            arity(a, 3)?;
            let lengths = box_lengths(a, 0)?;
            let cutoff = nonnegative(a, 1, "cutoff")?;
            let grid = grid_cells(a, 2)?;
            Ok(ParamValue::Numbers(
                crate::nodes::poisson::cells(lengths, cutoff, &grid)
                    .into_iter()
                    .map(f64::from)
                    .collect(),
            ))
        },
    },
    HostFunction {
        name: "poisson_background",
        doc: "poisson_background(box, split, permittivity): c of the term c Q_tot added to every potential so that the potential's mean over the box is zero for any split, as unsplit (the uniform neutralising background): -1 / (4 split^2 permittivity V); 0 for split 0",
        call: |a| {
            arity(a, 3)?;
            let lengths = box_lengths(a, 0)?;
            let split = nonnegative(a, 1, "split")?;
            let eps = positive(a, 2, "permittivity")?;
            Ok(ParamValue::Number(crate::nodes::poisson::background(
                lengths, split, eps,
            )))
        },
    },
    HostFunction {
        name: "fcm_grid",
        doc: "fcm_grid(box, radius, tolerance, kernel[, rotation[, split]]): FFT-friendly cells per axis for FCM; for the Gaussian, refined until some support keeps the self-mobility within the tolerance at the worst placement; with rotation true, fine enough for the torque Gaussian too (Gaussian kernel only); with split > 0 (PSE's far field, which plans its own grid) without the refinement",
        call: |a| {
            if !(4..=6).contains(&a.len()) {
                return Err(format!("takes 4 to 6 arguments, got {}", a.len()));
            }
            let rotation = a.len() >= 5 && flag(a, 4, "rotation")?;
            let split = if a.len() == 6 {
                number(a, 5, "split")?
            } else {
                0.0
            };
            let args = (
                box_lengths(a, 0)?,
                number(a, 1, "radius")?,
                tolerance(a, 2)?,
                text(a, 3, "kernel")?,
            );
            let g = if split > 0.0 {
                plan::nominal_grid_for(args.0, args.1, args.2, args.3, rotation)?
            } else {
                plan::grid_for(args.0, args.1, args.2, args.3, rotation)?
            };
            Ok(ParamValue::Numbers(g.into_iter().map(f64::from).collect()))
        },
    },
    HostFunction {
        name: "fcm_upsampling",
        doc: "fcm_upsampling(tolerance): the cells a Gaussian's standard deviation must span for FCM at this tolerance, g_u = min(0.55 - 0.11 log10(3 tol), 1.65)",
        call: |a| {
            arity(a, 1)?;
            Ok(ParamValue::Number(plan::gaussian_upsampling(number(
                a,
                0,
                "tolerance",
            )?)))
        },
    },
    HostFunction {
        name: "fcm_support",
        doc: "fcm_support(tolerance, kernel, width, box, grid[, split]): the window support in cells FCM uses: ES by its tolerance rule; the Gaussian (standard deviation width) the fewest cells that keep the self-mobility within the tolerance at the worst placement (computed in f64; refused on a grid too coarse for it); 0 (the window's own) for Peskin; with split > 0 (PSE's far field, whose planner sets its support) the Gaussian's erfc rule",
        call: |a| {
            if !(5..=6).contains(&a.len()) {
                return Err(format!("takes 5 or 6 arguments, got {}", a.len()));
            }
            let t = tolerance(a, 0)?;
            let lengths = box_lengths(a, 3)?;
            let cells = grid_cells(a, 4)?;
            let split = if a.len() == 6 {
                number(a, 5, "split")?
            } else {
                0.0
            };
            if lengths.len() != cells.len() {
                return Err(format!(
                    "box and grid have {} and {} values",
                    lengths.len(),
                    cells.len()
                ));
            }
            // Only the Gaussian has a width (fcm_width is 0 for the other kernels).
            Ok(ParamValue::Number(match text(a, 1, "kernel")? {
                "es" => plan::es_support(t) as f64,
                "gaussian" if split > 0.0 => {
                    let sigma = positive(a, 2, "width")?;
                    plan::gaussian_support(t, sigma / finest_cell(lengths, &cells)) as f64
                }
                "gaussian" => {
                    let sigma = positive(a, 2, "width")?;
                    plan::force_support(t, sigma, lengths, &cells)? as f64
                }
                _ => 0.0,
            }))
        },
    },
    HostFunction {
        name: "fcm_torque_support",
        doc: "fcm_torque_support(tolerance, width, box, grid): support in cells of FCM's torque Gaussian (standard deviation width): cut where the tail past the nearest edge is at most 2 tol per axis, S = ceil(1 + 2 sqrt(2) (width / h) erfc^-1(2 tol))",
        call: |a| {
            arity(a, 4)?;
            let t = tolerance(a, 0)?;
            let sigma = positive(a, 1, "width")?;
            let lengths = box_lengths(a, 2)?;
            let cells = grid_cells(a, 3)?;
            if lengths.len() != cells.len() {
                return Err(format!(
                    "box and grid have {} and {} values",
                    lengths.len(),
                    cells.len()
                ));
            }
            Ok(ParamValue::Number(
                plan::gaussian_support(t, sigma / finest_cell(lengths, &cells)) as f64,
            ))
        },
    },
    HostFunction {
        name: "fcm_beta",
        doc: "fcm_beta(tolerance, kernel): the ES shape parameter FCM uses (0 for other windows)",
        call: |a| {
            arity(a, 2)?;
            let t = tolerance(a, 0)?;
            Ok(ParamValue::Number(if text(a, 1, "kernel")? == "es" {
                plan::es_beta(plan::es_support(t))
            } else {
                0.0
            }))
        },
    },
    HostFunction {
        name: "fcm_width",
        doc: "fcm_width(radius, kernel): the Gaussian window's standard deviation radius / sqrt(pi) for FCM forces (0 for other windows, which ignore it); kernel may be left out: the Gaussian",
        call: |a| {
            if a.len() != 1 {
                arity(a, 2)?;
            }
            let r = number(a, 0, "radius")?;
            let gaussian = a.len() == 1 || text(a, 1, "kernel")? == "gaussian";
            Ok(ParamValue::Number(if gaussian {
                plan::gaussian_width(r)
            } else {
                0.0
            }))
        },
    },
    HostFunction {
        name: "fcm_rotation_upsampling",
        doc: "fcm_rotation_upsampling(tolerance): the cells FCM's torque Gaussian's standard deviation must span, g_u(tolerance / 10) (rotation has no 1/k^2 to damp aliasing)",
        call: |a| {
            arity(a, 1)?;
            Ok(ParamValue::Number(plan::rotation_upsampling(number(
                a,
                0,
                "tolerance",
            )?)))
        },
    },
    HostFunction {
        name: "fcm_torque_width",
        doc: "fcm_torque_width(radius): the standard deviation radius / (6 sqrt(pi))^(1/3) of FCM's torque Gaussian (rotational mobility 1 / (8 pi eta a^3))",
        call: |a| {
            arity(a, 1)?;
            Ok(ParamValue::Number(plan::torque_width(number(
                a, 0, "radius",
            )?)))
        },
    },
    HostFunction {
        name: "fcm_sort_cells",
        doc: "fcm_sort_cells(grid): cells per axis of the Morton order particles are sorted in before spreading (8 grid cells each, at most 1024 per axis)",
        call: |a| {
            arity(a, 1)?;
            Ok(ParamValue::Numbers(
                grid_cells(a, 0)?
                    .iter()
                    .map(|&g| plan::sort_cells(g as f64))
                    .collect(),
            ))
        },
    },
    HostFunction {
        name: "fcm_sort_particles",
        doc: "fcm_sort_particles(grid): whether sorting particles pays, that is whether the 3 components of the grid outgrow the cache",
        call: |a| {
            arity(a, 1)?;
            let cells: f64 = numbers(a, 0, "grid")?.iter().product();
            Ok(ParamValue::Bool(
                cells * 3.0 * 4.0 > crate::nodes::spread::LARGE_GRID_BYTES as f64,
            ))
        },
    },
    HostFunction {
        name: "mpcd_sort_every",
        doc: "mpcd_sort_every(box, cell): steps between MPCD reorderings by cell: 20 from 5e5 cells up, 0 (never) below (H200, 10 particles a cell: every 20 steps 8.9e9 -> 1.09e10 particle-steps/s at 10^6 cells, slower at 10^5, where the 3 MB of cell sums stay in cache; the threshold lies between, not measured finer)",
        call: |a| {
            arity(a, 2)?;
            let cell = number(a, 1, "cell")?;
            let cells: f64 = box_lengths(a, 0)?.iter().map(|l| l / cell).product();
            Ok(ParamValue::Number(if cells >= 5e5 { 20.0 } else { 0.0 }))
        },
    },
    HostFunction {
        name: "mpcd_shell_count",
        doc: "mpcd_shell_count(density, radius, cell): virtual particles filling a solid sphere's shell at the solvent's density (mpcd_sphere_fill's per_sphere): round(density x 4/3 pi (R^3 - R_in^3) / a^3), R_in = max(R - 2 sqrt(3) a, 0)",
        call: |a| {
            arity(a, 3)?;
            let density = number(a, 0, "density")?;
            let radius = number(a, 1, "radius")?;
            let cell = number(a, 2, "cell")?;
            if !(density > 0.0 && radius > 0.0 && cell > 0.0) {
                return Err(format!(
                    "density, radius and cell must be positive, got {density}, {radius}, {cell}"
                ));
            }
            let k = crate::nodes::mpcd::shell_count(density, radius, cell).round();
            if !(1.0..=16_777_216.0).contains(&k) {
                return Err(format!(
                    "{k} virtual particles per sphere: outside 1 to 2^24"
                ));
            }
            Ok(ParamValue::Number(k))
        },
    },
    HostFunction {
        name: "fcm_sort_bits",
        doc: "fcm_sort_bits(grid): key bits of that Morton order (3 per level of the largest axis)",
        call: |a| {
            arity(a, 1)?;
            let most = grid_cells(a, 0)?
                .iter()
                .map(|&g| plan::sort_cells(g as f64))
                .fold(1.0, f64::max);
            Ok(ParamValue::Number(3.0 * most.log2().ceil().max(1.0)))
        },
    },
    HostFunction {
        name: "fcm_sort_bins",
        doc: "fcm_sort_bins(grid): bins of that Morton order (its largest key + 1: every key cell_hash makes for fcm_sort_cells(grid) in morton order), for bin_sort",
        call: |a| {
            arity(a, 1)?;
            let last: Vec<u32> = grid_cells(a, 0)?
                .iter()
                .map(|&g| plan::sort_cells(g as f64) as u32 - 1)
                .collect();
            if !(2..=3).contains(&last.len()) {
                return Err(format!(
                    "argument 1 (grid) needs 2 or 3 axes, got {}",
                    last.len()
                ));
            }
            Ok(ParamValue::Number(
                crate::nodes::cells::morton(&last) as f64 + 1.0,
            ))
        },
    },
    HostFunction {
        name: "fcm_radius",
        doc: "fcm_radius(box, grid, radius, tolerance, kernel): the hydrodynamic radius the window has on that grid",
        call: |a| {
            arity(a, 5)?;
            let cells = grid_cells(a, 1)?;
            Ok(ParamValue::Number(plan::effective_radius(
                box_lengths(a, 0)?,
                &cells,
                number(a, 2, "radius")?,
                tolerance(a, 3)?,
                text(a, 4, "kernel")?,
            )?))
        },
    },
    HostFunction {
        name: "pse_split",
        doc: "pse_split(radius, tolerance, box): the default Ewald splitting parameter xi of PSE, 0.5 / radius, raised where the near-field cutoff would pass half the smallest box side",
        call: |a| {
            arity(a, 3)?;
            Ok(ParamValue::Number(pse::default_split(
                positive(a, 0, "radius")?,
                tolerance(a, 1)?,
                box_lengths(a, 2)?,
            )?))
        },
    },
    HostFunction {
        name: "pse_cutoff",
        doc: "pse_cutoff(radius, split, tolerance, box): the PSE near-field cutoff, where the near field falls below a quarter of the tolerance times the periodic self-mobility (computed in f64)",
        call: |a| {
            arity(a, 4)?;
            Ok(ParamValue::Number(pse::cutoff(
                positive(a, 0, "radius")?,
                positive(a, 1, "split")?,
                tolerance(a, 2)?,
                box_lengths(a, 3)?,
            )?))
        },
    },
    HostFunction {
        name: "pse_grid",
        doc: "pse_grid(box, split, tolerance): FFT-friendly far-field cells per axis, spacing pi / (2 split sqrt(-ln tolerance))",
        call: |a| {
            arity(a, 3)?;
            let g = pse::grid(
                box_lengths(a, 0)?,
                positive(a, 1, "split")?,
                tolerance(a, 2)?,
            )
            .map_err(|e| format!("{e}: lower the split"))?;
            Ok(ParamValue::Numbers(g.into_iter().map(f64::from).collect()))
        },
    },
    HostFunction {
        name: "pse_width",
        doc: "pse_width(radius, split, tolerance, box, grid): standard deviation of the far-field Gaussian: of the cheapest Gaussian whose error bound (aliasing and truncation, every placement and pair, computed in f64) is within three quarters of the tolerance",
        call: |a| {
            arity(a, 5)?;
            let w = pse::far_window(
                positive(a, 0, "radius")?,
                positive(a, 1, "split")?,
                tolerance(a, 2)?,
                box_lengths(a, 3)?,
                &grid_cells(a, 4)?,
            )?;
            Ok(ParamValue::Number(w.width))
        },
    },
    HostFunction {
        name: "pse_support",
        doc: "pse_support(radius, split, tolerance, box, grid, width): support in cells of the far-field Gaussian of that width: the fewest whose error bound is within three quarters of the tolerance",
        call: |a| {
            arity(a, 6)?;
            Ok(ParamValue::Number(pse::support(
                positive(a, 0, "radius")?,
                positive(a, 1, "split")?,
                tolerance(a, 2)?,
                box_lengths(a, 3)?,
                &grid_cells(a, 4)?,
                positive(a, 5, "width")?,
            )? as f64))
        },
    },
    HostFunction {
        name: "pse_cells",
        doc: "pse_cells(box, cutoff): cells per axis of the near field's cell list (at least the cutoff wide)",
        call: |a| {
            arity(a, 2)?;
            Ok(ParamValue::Numbers(
                pse::neighbour_cells(box_lengths(a, 0)?, positive(a, 1, "cutoff")?)
                    .into_iter()
                    .map(f64::from)
                    .collect(),
            ))
        },
    },
    HostFunction {
        name: "hasimoto",
        doc: "hasimoto(radius, L): self-mobility of a sphere in a cubic periodic box of side L, times 6 pi eta a",
        call: |a| {
            arity(a, 2)?;
            Ok(ParamValue::Number(plan::hasimoto(
                number(a, 0, "radius")?,
                number(a, 1, "L")?,
            )))
        },
    },
];

/// Adds the planners to the registry.
pub fn register(r: &mut Registry) {
    for f in FUNCTIONS {
        r.add_function(*f);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn call(name: &str, args: &[ParamValue]) -> Result<ParamValue, String> {
        let f = FUNCTIONS
            .iter()
            .find(|f| f.name == name)
            .expect("a planner");
        (f.call)(args)
    }

    /// poisson_cutoff is callable from expressions and names its refusals.
    #[test]
    fn poisson_cutoff_from_expressions() {
        let n = |x: f64| ParamValue::Number(x);
        let v = |x: &[f64]| ParamValue::Numbers(x.to_vec());
        let rc = match call("poisson_cutoff", &[n(1.0), n(0.5), n(1e-4), v(&[40.0; 3])]).unwrap() {
            ParamValue::Number(x) => x,
            other => panic!("not a number: {other:?}"),
        };
        let want =
            crate::nodes::pairs::poisson::poisson_cutoff(1.0, 0.5, 1e-4, &[40.0; 3]).unwrap();
        assert_eq!(rc, want);
        // Unsplit: no near field.
        assert_eq!(
            call("poisson_cutoff", &[n(1.0), n(0.0), n(1e-4), v(&[4.0; 3])]).unwrap(),
            n(0.0)
        );
        let err = call("poisson_cutoff", &[n(1.0), n(0.5), n(1e-4), v(&[4.0; 3])]).unwrap_err();
        assert!(err.contains("half the smallest box length"), "{err}");
        let err = call("poisson_cutoff", &[n(1.0), n(-1.0), n(1e-4), v(&[40.0; 3])]).unwrap_err();
        assert!(err.contains("split"), "{err}");
    }

    /// Planners are called from expressions with their errors named.
    #[test]
    fn planners_in_expressions() {
        let r = crate::nodes::registry();
        let s = crate::expr::Scope::new(r.functions());
        assert_eq!(crate::expr::eval("next_fft(97)", &s).unwrap(), 98.0);
        assert!(
            crate::expr::eval("next_fft('x')", &s)
                .unwrap_err()
                .to_string()
                .contains("next_fft")
        );
    }

    /// Grids from hostile boxes, radii, splits and tolerances are errors naming the
    /// limit, never a panic of the FFT size search or a saturated conversion.
    #[test]
    fn hostile_sizes_are_errors_naming_the_limit() {
        let n = |x: f64| ParamValue::Number(x);
        let v = |x: &[f64]| ParamValue::Numbers(x.to_vec());
        let t = |x: &str| ParamValue::Text(x.into());
        for (name, args, wanted) in [
            (
                "fcm_grid",
                vec![v(&[1e30; 3]), n(1.0), n(1e-3), t("gaussian")],
                "MAX_LENGTH",
            ),
            (
                "fcm_grid",
                vec![v(&[8.0; 3]), n(5e-324), n(1e-3), t("es")],
                "MAX_LENGTH",
            ),
            (
                "fcm_grid",
                vec![v(&[1000.0; 3]), n(0.4), n(1e-3), t("peskin3")],
                "MAX_GRID_CELLS",
            ),
            (
                "fcm_grid",
                vec![v(&[8.0; 3]), n(1.0), n(0.0), t("es")],
                "tolerance",
            ),
            (
                "pse_grid",
                vec![v(&[128.0; 3]), n(1e6), n(1e-3)],
                "MAX_LENGTH",
            ),
            (
                "pse_grid",
                vec![v(&[1e30; 3]), n(0.5), n(1e-3)],
                "MAX_LENGTH",
            ),
            (
                "pse_width",
                vec![n(1.0), n(0.5), n(1e-3), v(&[8.0; 3]), v(&[1e30; 3])],
                "MAX_LENGTH",
            ),
            (
                "pse_support",
                vec![
                    n(1.0),
                    n(0.5),
                    n(1e-3),
                    v(&[8.0; 3]),
                    v(&[f64::NAN; 3]),
                    n(1.0),
                ],
                "argument 5 (grid)",
            ),
            (
                "fcm_sort_bins",
                vec![v(&[f64::NAN; 3])],
                "argument 1 (grid)",
            ),
            (
                "fcm_support",
                vec![n(0.0), t("es"), n(1.0), v(&[8.0; 3]), v(&[8.0; 3])],
                "tolerance",
            ),
            (
                "fcm_radius",
                vec![v(&[8.0; 3]), v(&[0.5; 3]), n(1.0), n(1e-3), t("es")],
                "whole number",
            ),
            // PSE's near field: a split of 1e6 used to run the quadrature for minutes.
            (
                "pse_cutoff",
                vec![n(1.0), n(1e6), n(1e-3), v(&[8.0; 3])],
                "MAX_FAR_PANELS",
            ),
            (
                "pse_split",
                vec![n(5e-324), n(1e-3), v(&[8.0; 3])],
                "MAX_FAR_PANELS",
            ),
        ] {
            let got = std::panic::catch_unwind(|| call(name, &args));
            let Ok(Err(e)) = got else {
                panic!("{name}({args:?}) gave {got:?}, not an error");
            };
            assert!(e.contains(wanted), "{name}({args:?}): {e}");
        }
    }

    /// fcm_sort_bins covers every Morton key of fcm_sort_cells(grid), and no more than
    /// the largest one needs.
    /// The kernels other than the Gaussian have no width (fcm_width gives them 0): their
    /// support does not need one.
    #[test]
    fn fcm_support_takes_a_zero_width_for_kernels_without_one() {
        let n = ParamValue::Number;
        let t = |s: &str| ParamValue::Text(s.into());
        let v = |x: &[f64]| ParamValue::Numbers(x.to_vec());
        let support = |kernel: &str| {
            call(
                "fcm_support",
                &[n(1e-3), t(kernel), n(0.0), v(&[32.0; 3]), v(&[48.0; 3])],
            )
        };
        assert_eq!(
            support("es"),
            Ok(n(crate::nodes::fcm::plan::es_support(1e-3) as f64))
        );
        assert_eq!(support("peskin4"), Ok(n(0.0)));
        let e = support("gaussian").unwrap_err();
        assert!(e.contains("width") && e.contains("positive"), "{e}");
    }

    #[test]
    fn sort_bins_cover_every_morton_key_of_the_sort_cells() {
        for grid in [
            vec![1.0, 1.0, 1.0],
            vec![18.0, 18.0, 18.0],
            vec![64.0, 24.0, 40.0],
            vec![200.0, 8.0, 9.0],
            vec![96.0, 30.0],
        ] {
            let grid_value = ParamValue::Numbers(grid.clone());
            let Ok(ParamValue::Numbers(cells)) =
                call("fcm_sort_cells", std::slice::from_ref(&grid_value))
            else {
                panic!("fcm_sort_cells({grid:?})");
            };
            let Ok(ParamValue::Number(bins)) = call("fcm_sort_bins", &[grid_value]) else {
                panic!("fcm_sort_bins({grid:?})");
            };
            let c: Vec<u32> = cells.iter().map(|&c| c as u32).collect();
            let mut largest = 0;
            for z in 0..c.get(2).copied().unwrap_or(1) {
                for y in 0..c[1] {
                    for x in 0..c[0] {
                        let i = if c.len() == 3 {
                            vec![x, y, z]
                        } else {
                            vec![x, y]
                        };
                        largest = largest.max(crate::nodes::cells::morton(&i));
                    }
                }
            }
            assert_eq!(bins, largest as f64 + 1.0, "{grid:?}");
        }
        // 256^3 grid cells: 32^3 sort cells, 2^15 bins (a power of two per axis fills it).
        assert_eq!(
            call("fcm_sort_bins", &[ParamValue::Numbers(vec![256.0; 3])]),
            Ok(ParamValue::Number(32768.0))
        );
        assert!(
            call("fcm_sort_bins", &[ParamValue::Numbers(vec![8.0])])
                .unwrap_err()
                .contains("2 or 3 axes")
        );
    }
}
