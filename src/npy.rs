//! NPY files in and out: the arrays numpy users already have.
//!
//! Reading checks everything a run relies on (dtype, shape against the graph input's
//! declaration, finite values) and says which file and element are wrong. Writing goes to
//! temporary files in the same folders, renamed once all are complete, so no partial
//! output and no partial set of outputs is left; an interrupt removes the temporaries
//! ([`abandon_writes`]).

use std::fs::File;
use std::io::{BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, MutexGuard};

use npyz::WriterBuilder;
use thiserror::Error;

use crate::graph::InputShape;
use crate::value::{Elem, HostArray, HostData, ValueType};

#[derive(Debug, Error)]
#[non_exhaustive]
pub enum NpyError {
    #[error("{path}: cannot read: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: cannot write: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Content { path: PathBuf, message: String },
}

fn content(path: &Path, message: impl Into<String>) -> NpyError {
    NpyError::Content {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// Raw numbers of a file, widened, with its shape.
enum Numbers {
    Float(Vec<f64>),
    Int(Vec<i128>),
}

fn read_numbers(path: &Path) -> Result<(Vec<u64>, Numbers, bool), NpyError> {
    let f = File::open(path).map_err(|source| NpyError::Read {
        path: path.into(),
        source,
    })?;
    let npy = npyz::NpyFile::new(BufReader::new(f))
        .map_err(|e| content(path, format!("not a valid NPY file: {e}")))?;
    let shape = npy.shape().to_vec();
    if npy.order() == npyz::Order::Fortran && shape.iter().filter(|&&d| d > 1).count() > 1 {
        return Err(content(
            path,
            "Fortran-ordered arrays are not supported; save with np.ascontiguousarray",
        ));
    }
    let dtype = match npy.dtype() {
        npyz::DType::Plain(ts) => ts.to_string(),
        other => {
            return Err(content(
                path,
                format!(
                    "unsupported dtype {} (a record or array dtype): use float32 or float64",
                    other.descr()
                ),
            ));
        }
    };
    let bad = |e: std::io::Error| content(path, format!("reading data: {e}"));
    let (nums, complex) = match dtype.as_str() {
        "<f4" | "=f4" => (
            Numbers::Float(
                npy.into_vec::<f32>()
                    .map_err(bad)?
                    .into_iter()
                    .map(f64::from)
                    .collect(),
            ),
            false,
        ),
        "<f8" | "=f8" => (Numbers::Float(npy.into_vec::<f64>().map_err(bad)?), false),
        "<c8" => {
            let v: Vec<num_complex::Complex<f32>> = npy.into_vec().map_err(bad)?;
            (
                Numbers::Float(
                    v.into_iter()
                        .flat_map(|c| [c.re as f64, c.im as f64])
                        .collect(),
                ),
                true,
            )
        }
        "<c16" => {
            let v: Vec<num_complex::Complex<f64>> = npy.into_vec().map_err(bad)?;
            (
                Numbers::Float(v.into_iter().flat_map(|c| [c.re, c.im]).collect()),
                true,
            )
        }
        "<i4" => (
            Numbers::Int(
                npy.into_vec::<i32>()
                    .map_err(bad)?
                    .into_iter()
                    .map(i128::from)
                    .collect(),
            ),
            false,
        ),
        "<i8" => (
            Numbers::Int(
                npy.into_vec::<i64>()
                    .map_err(bad)?
                    .into_iter()
                    .map(i128::from)
                    .collect(),
            ),
            false,
        ),
        "<u4" => (
            Numbers::Int(
                npy.into_vec::<u32>()
                    .map_err(bad)?
                    .into_iter()
                    .map(i128::from)
                    .collect(),
            ),
            false,
        ),
        "<u8" => (
            Numbers::Int(
                npy.into_vec::<u64>()
                    .map_err(bad)?
                    .into_iter()
                    .map(i128::from)
                    .collect(),
            ),
            false,
        ),
        other => {
            return Err(content(
                path,
                format!(
                    "unsupported dtype {other}: use float32 or float64 (or integers for index arrays)"
                ),
            ));
        }
    };
    Ok((shape, nums, complex))
}

fn shape_text(s: &[u64]) -> String {
    let parts: Vec<String> = s.iter().map(|d| d.to_string()).collect();
    if parts.len() == 1 {
        format!("({},)", parts[0])
    } else {
        format!("({})", parts.join(", "))
    }
}

/// The type a file's shape gives for a declared input, or why it does not fit.
fn type_for(shape: &[u64], complex: bool, decl: &InputShape) -> Result<ValueType, String> {
    let to_u32 = |x: u64| u32::try_from(x).map_err(|_| format!("dimension {x} is too large"));
    let total: u64 = shape.iter().product();
    let complex_input = matches!(
        decl,
        InputShape::Fixed(ValueType::ComplexGrid { .. } | ValueType::HalfComplexGrid { .. })
    );
    if complex && !complex_input {
        return Err(format!(
            "complex values do not fit {}, a real input: give float32 or float64 values",
            decl.describe()
        ));
    }
    match decl {
        InputShape::Particles { cols, .. } => match shape {
            [n, k] if *k == *cols as u64 => Ok(ValueType::Particles {
                n: to_u32(*n)?,
                k: *cols,
            }),
            [len] if len % *cols as u64 == 0 => Ok(ValueType::Particles {
                n: to_u32(len / *cols as u64)?,
                k: *cols,
            }),
            [n] if *cols == 1 => Ok(ValueType::Particles {
                n: to_u32(*n)?,
                k: 1,
            }),
            _ => Err(format!(
                "shape {} does not fit {}: expected (N, {cols}) or flat ({cols}N,)",
                shape_text(shape),
                decl.describe()
            )),
        },
        InputShape::Indices { .. } => match shape {
            [n] => Ok(ValueType::Indices { n: to_u32(*n)? }),
            _ => Err(format!(
                "shape {} does not fit {}: expected (N,)",
                shape_text(shape),
                decl.describe()
            )),
        },
        InputShape::Fixed(t @ ValueType::Scalar) => {
            if total == 1 && shape.len() <= 1 {
                Ok(*t)
            } else {
                Err(format!(
                    "shape {} is not a scalar: expected () or (1,)",
                    shape_text(shape)
                ))
            }
        }
        InputShape::Fixed(t @ ValueType::RealGrid { .. }) => {
            if total == t.words() && !complex {
                Ok(*t)
            } else {
                Err(format!(
                    "shape {} does not fit {}: expected {}",
                    shape_text(shape),
                    decl.describe(),
                    shape_text(&t.npy_shape())
                ))
            }
        }
        InputShape::Fixed(t) => {
            // Complex values: a complex array, or float pairs along a trailing axis of 2.
            let words = if complex { total * 2 } else { total };
            if words == t.words() && (complex || shape.last() == Some(&2)) {
                Ok(*t)
            } else {
                Err(format!(
                    "shape {} does not fit {}: expected {} (float) or the same without the trailing 2 (complex)",
                    shape_text(shape),
                    decl.describe(),
                    shape_text(&t.npy_shape())
                ))
            }
        }
    }
}

/// Reads a graph input from an NPY file, checked against its declaration.
pub fn read_input(path: &Path, decl: &InputShape) -> Result<HostArray, NpyError> {
    let (shape, nums, complex) = read_numbers(path)?;
    let ty = type_for(&shape, complex, decl).map_err(|m| content(path, m))?;
    match (ty.elem(), nums) {
        (Elem::F32, Numbers::Float(v)) => {
            let mut out = Vec::with_capacity(v.len());
            for (i, x) in v.into_iter().enumerate() {
                if !x.is_finite() {
                    return Err(content(
                        path,
                        format!("element {i} is {x}; inputs must be finite"),
                    ));
                }
                if x.abs() > f32::MAX as f64 {
                    return Err(content(
                        path,
                        format!("element {i} = {x} does not fit in float32"),
                    ));
                }
                out.push(x as f32);
            }
            Ok(HostArray::f32(ty, out))
        }
        (Elem::F32, Numbers::Int(v)) => Ok(HostArray::f32(
            ty,
            v.into_iter().map(|x| x as f32).collect(),
        )),
        (Elem::U32, Numbers::Int(v)) => {
            let mut out = Vec::with_capacity(v.len());
            for (i, x) in v.into_iter().enumerate() {
                out.push(u32::try_from(x).map_err(|_| {
                    content(path, format!("element {i} = {x} is not a valid u32 index"))
                })?);
            }
            Ok(HostArray::u32(ty, out))
        }
        (Elem::U32, Numbers::Float(_)) => {
            Err(content(path, "index arrays must have an integer dtype"))
        }
    }
}

/// Temporary files that [`write_all`] has created and not yet renamed or removed, for
/// [`abandon_writes`] to remove. Its lock is also held while a set of outputs is renamed,
/// so that an interrupt lands before the first rename or after the last.
static PENDING: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
/// Set by [`abandon_writes`]: no temporary is created after it.
static ABANDONED: AtomicBool = AtomicBool::new(false);

fn pending() -> MutexGuard<'static, Vec<PathBuf>> {
    PENDING.lock().unwrap_or_else(|p| p.into_inner())
}

/// Removes every temporary output being written and keeps new ones from being created:
/// for a signal handler, before the process exits (an interrupted run leaves no
/// `.NAME.PID.tmp` behind). Where a set of outputs is being renamed it waits for the
/// renames, so the set is in place whole or not at all.
pub fn abandon_writes() {
    let mut files = pending();
    ABANDONED.store(true, Ordering::SeqCst);
    for f in files.drain(..) {
        let _ = std::fs::remove_file(f);
    }
}

/// Creates the hidden temporary a file is written to before its rename (beside it:
/// [`temporary`]), registered under the lock the interrupt handler takes, so that an
/// interrupt removes it and none is created after one.
pub fn create_temporary(path: &Path) -> std::io::Result<(PathBuf, File)> {
    let mut files = pending();
    if ABANDONED.load(Ordering::SeqCst) {
        return Err(std::io::Error::other("interrupted"));
    }
    let tmp = temporary(path);
    let file = File::create(&tmp)?;
    files.push(tmp.clone());
    Ok((tmp, file))
}

/// Renames a finished temporary into place (it was synced by its writer).
pub fn finish_temporary(tmp: &Path, path: &Path) -> std::io::Result<()> {
    let mut files = pending();
    let renamed = std::fs::rename(tmp, path);
    files.retain(|f| f != tmp);
    renamed
}

/// Removes a temporary that will not be finished (a no-op once it was renamed).
pub fn abandon_temporary(tmp: &Path) {
    let mut files = pending();
    if files.iter().any(|f| f == tmp) {
        let _ = std::fs::remove_file(tmp);
        files.retain(|f| f != tmp);
    }
}

/// A failure of [`write_all`]: which output (its index) and why.
#[derive(Debug, Error)]
#[error("{source}")]
pub struct WriteAllError {
    pub index: usize,
    pub source: NpyError,
    /// Outputs already renamed into place when a rename failed (0 otherwise: a failure
    /// while writing, or a target that cannot be replaced, leaves none).
    pub in_place: usize,
}

/// The temporary a file is written to before it is renamed: in the same folder (a
/// rename does not cross file systems), hidden, named after the process.
fn temporary(path: &Path) -> PathBuf {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_else(|| "out".into());
    dir.join(format!(".{name}.{}.tmp", std::process::id()))
}

/// Writes arrays (float32 or uint32) to NPY files, all or none: each to a temporary file
/// first (synced to disk), and only when every one is complete are they renamed over
/// their files, one after another. When one fails to write, every temporary is removed
/// and no file is touched. A rename can still fail (a file system that fails between
/// renames); the error then says how many outputs were already in place.
pub fn write_all(outputs: &[(&Path, &HostArray)]) -> Result<(), WriteAllError> {
    let fail = |index: usize, path: &Path, source: std::io::Error| WriteAllError {
        index,
        source: NpyError::Write {
            path: path.into(),
            source,
        },
        in_place: 0,
    };
    let mut temps: Vec<PathBuf> = Vec::with_capacity(outputs.len());
    let written = (|| {
        for (i, (path, a)) in outputs.iter().enumerate() {
            if outputs[..i].iter().any(|(p, _)| p == path) {
                return Err(fail(
                    i,
                    path,
                    std::io::Error::other("the same file is written twice"),
                ));
            }
            let (tmp, file) = create_temporary(path).map_err(|e| fail(i, path, e))?;
            temps.push(tmp);
            write_npy(file, a).map_err(|e| fail(i, path, e))?;
        }
        // A folder in an output's place would refuse its rename: refuse before any.
        for (i, (path, _)) in outputs.iter().enumerate() {
            if path.is_dir() {
                return Err(fail(i, path, std::io::Error::other("it is a folder")));
            }
        }
        Ok(())
    })();
    let mut files = pending();
    let result = match written {
        Err(e) => Err(e),
        Ok(()) => {
            let mut result = Ok(());
            for (i, ((path, _), tmp)) in outputs.iter().zip(&temps).enumerate() {
                if let Err(e) = std::fs::rename(tmp, path) {
                    result = Err(WriteAllError {
                        in_place: i,
                        ..fail(i, path, e)
                    });
                    break;
                }
            }
            result
        }
    };
    // What was not renamed is removed (a renamed temporary no longer exists).
    for tmp in &temps {
        let _ = std::fs::remove_file(tmp);
        files.retain(|f| f != tmp);
    }
    result
}

/// Writes one array atomically: a temporary file, then a rename (see [`write_all`]).
pub fn write(path: &Path, a: &HostArray) -> Result<(), NpyError> {
    write_all(&[(path, a)]).map_err(|e| e.source)
}

/// The elements of one array as an NPY body of `shape`, in their own dtype.
fn write_elements<T>(w: &mut impl Write, shape: &[u64], v: &[T]) -> std::io::Result<()>
where
    T: npyz::Serialize + npyz::AutoSerialize + Copy,
{
    let mut npy = npyz::WriteOptions::<T>::new()
        .default_dtype()
        .shape(shape)
        .writer(w)
        .begin_nd()?;
    npy.extend(v.iter().copied())?;
    npy.finish()
}

/// The NPY form of an array into a new file, synced to disk.
fn write_npy(file: File, a: &HostArray) -> std::io::Result<()> {
    let mut w = BufWriter::new(file);
    let shape = a.ty.npy_shape();
    match &a.data {
        HostData::F32(v) => write_elements(&mut w, &shape, v)?,
        HostData::U32(v) => write_elements(&mut w, &shape, v)?,
    }
    w.flush()?;
    w.get_ref().sync_all()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::Dim;

    fn tmpdir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("mesoflow-npy-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn round_trip_particles() {
        let d = tmpdir("rt");
        let p = d.join("x.npy");
        let a = HostArray::f32(
            ValueType::Particles { n: 2, k: 3 },
            vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
        );
        write(&p, &a).unwrap();
        let b = read_input(
            &p,
            &InputShape::Particles {
                rows: Dim::Free,
                cols: 3,
            },
        )
        .unwrap();
        assert_eq!(a, b);
        // No temporary file is left next to the output.
        let names: Vec<_> = std::fs::read_dir(&d)
            .unwrap()
            .flatten()
            .map(|e| e.file_name())
            .collect();
        assert_eq!(names.len(), 1);
    }

    #[test]
    fn a_set_of_outputs_is_written_whole_or_not_at_all() {
        let d = tmpdir("all-or-none");
        let a = HostArray::f32(ValueType::Particles { n: 1, k: 3 }, vec![1.0, 2.0, 3.0]);
        let (first, second) = (d.join("first.npy"), d.join("second.npy"));
        // The second output's place is taken by a folder: neither is written.
        std::fs::create_dir_all(&second).unwrap();
        let e = write_all(&[(&first, &a), (&second, &a)]).unwrap_err();
        assert_eq!((e.index, e.in_place), (1, 0));
        assert!(e.to_string().contains("second.npy"), "{e}");
        assert!(!first.exists());
        // The same file twice is refused.
        let e = write_all(&[(&first, &a), (&first, &a)]).unwrap_err();
        assert_eq!(e.index, 1);
        assert!(!first.exists());
        std::fs::remove_dir(&second).unwrap();
        write_all(&[(&first, &a), (&second, &a)]).unwrap();
        assert!(first.exists() && second.exists());
        let names: Vec<_> = std::fs::read_dir(&d)
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().to_string())
            .collect();
        assert!(names.iter().all(|n| !n.ends_with(".tmp")), "{names:?}");
    }

    #[test]
    fn shape_rules() {
        let p = InputShape::Particles {
            rows: Dim::Free,
            cols: 3,
        };
        assert_eq!(
            type_for(&[6], false, &p).unwrap(),
            ValueType::Particles { n: 2, k: 3 }
        );
        assert!(type_for(&[5], false, &p).unwrap_err().contains("(N, 3)"));
        assert!(type_for(&[2, 2], false, &p).is_err());
        assert_eq!(
            type_for(&[], false, &InputShape::Fixed(ValueType::Scalar)).unwrap(),
            ValueType::Scalar
        );
        assert_eq!(
            type_for(&[1], false, &InputShape::Fixed(ValueType::Scalar)).unwrap(),
            ValueType::Scalar
        );
        assert!(type_for(&[2], false, &InputShape::Fixed(ValueType::Scalar)).is_err());
        // Complex values fit complex inputs only.
        assert!(
            type_for(&[2, 3], true, &p)
                .unwrap_err()
                .contains("complex values")
        );
        assert!(
            type_for(&[], true, &InputShape::Fixed(ValueType::Scalar))
                .unwrap_err()
                .contains("a real input")
        );
        let spectrum = ValueType::ComplexGrid {
            dims: [2, 1, 1],
            comps: 1,
        };
        assert_eq!(
            type_for(&[1, 1, 1, 2], true, &InputShape::Fixed(spectrum)).unwrap(),
            spectrum
        );
    }
}
