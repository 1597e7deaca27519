//! Host-side planners graph files can call in param expressions, all in f64: an
//! FFT-friendly size, the FCM grid and window from a radius and a tolerance, Hasimoto's
//! periodic correction. Each is a thin wrapper over its node family's planner.

use crate::expr::{HostFunction, ParamValue};
use crate::nodes::fcm::plan;

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

fn arity(args: &[ParamValue], n: usize) -> Result<(), String> {
    if args.len() == n {
        Ok(())
    } else {
        Err(format!("takes {n} arguments, got {}", args.len()))
    }
}

/// Every host function.
pub static FUNCTIONS: &[HostFunction] = &[
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
        name: "fcm_grid",
        doc: "fcm_grid(box, radius, tolerance, kernel): FFT-friendly cells per axis for FCM",
        call: |a| {
            arity(a, 4)?;
            let g = plan::grid(
                numbers(a, 0, "box")?,
                number(a, 1, "radius")?,
                number(a, 2, "tolerance")?,
                text(a, 3, "kernel")?,
            )?;
            Ok(ParamValue::Numbers(g.into_iter().map(f64::from).collect()))
        },
    },
    HostFunction {
        name: "fcm_support",
        doc: "fcm_support(tolerance, kernel): the window support in cells FCM uses for the ES window (0: the window's own rule)",
        call: |a| {
            arity(a, 2)?;
            let t = number(a, 0, "tolerance")?;
            Ok(ParamValue::Number(if text(a, 1, "kernel")? == "es" {
                plan::es_support(t) as f64
            } else {
                0.0
            }))
        },
    },
    HostFunction {
        name: "fcm_beta",
        doc: "fcm_beta(tolerance, kernel): the ES shape parameter FCM uses (0 for other windows)",
        call: |a| {
            arity(a, 2)?;
            let t = number(a, 0, "tolerance")?;
            Ok(ParamValue::Number(if text(a, 1, "kernel")? == "es" {
                plan::es_beta(plan::es_support(t))
            } else {
                0.0
            }))
        },
    },
    HostFunction {
        name: "fcm_radius",
        doc: "fcm_radius(box, grid, radius, tolerance, kernel): the hydrodynamic radius the window has on that grid",
        call: |a| {
            arity(a, 5)?;
            let cells: Vec<u32> = numbers(a, 1, "grid")?.iter().map(|&n| n as u32).collect();
            Ok(ParamValue::Number(plan::effective_radius(
                numbers(a, 0, "box")?,
                &cells,
                number(a, 2, "radius")?,
                number(a, 3, "tolerance")?,
                text(a, 4, "kernel")?,
            )?))
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

/// The host function of a name.
pub fn lookup(name: &str) -> Option<&'static HostFunction> {
    FUNCTIONS.iter().find(|f| f.name == name)
}
