//! The WGSL library: every file under `shaders/`, embedded at build time.
//!
//! WGSL has no include mechanism, so a shader may start with lines
//! `#import common/index.wgsl`; [`source`] replaces each with that file's text (each file
//! once, recursively). Everything else is plain WGSL.

use std::io::Write;

use super::DeviceCaps;

mod files {
    include!(concat!(env!("OUT_DIR"), "/shader_files.rs"));
}

/// All embedded shader paths, relative to `shaders/`.
pub fn paths() -> impl Iterator<Item = &'static str> {
    files::FILES.iter().map(|(p, _)| *p)
}

/// The raw text of one shader file: the embedded one, or, for kernel development, the
/// file of that path under the folder `MESOFLOW_SHADER_DIR` names when it has one (so
/// variants of a kernel can be timed without a rebuild; each file used is named on stderr).
pub fn raw(path: &str) -> Option<&'static str> {
    if let Some(text) = overridden(path) {
        return Some(text);
    }
    files::FILES
        .iter()
        .find(|(p, _)| *p == path)
        .map(|(_, s)| *s)
}

/// The folder of shader overrides, if `MESOFLOW_SHADER_DIR` names one.
fn override_dir() -> Option<&'static std::path::Path> {
    static DIR: std::sync::OnceLock<Option<std::path::PathBuf>> = std::sync::OnceLock::new();
    DIR.get_or_init(|| std::env::var_os("MESOFLOW_SHADER_DIR").map(Into::into))
        .as_deref()
}

fn overridden(path: &str) -> Option<&'static str> {
    use std::collections::HashMap;
    use std::sync::Mutex;
    // Per path: the override's text, or None where the folder has no such file (looked
    // up once per process, like the embedded files, so kernel builds read no file twice).
    static CACHE: Mutex<Option<HashMap<String, Option<&'static str>>>> = Mutex::new(None);
    let dir = override_dir()?;
    let mut cache = CACHE.lock().unwrap_or_else(|e| e.into_inner());
    let cache = cache.get_or_insert_with(HashMap::new);
    if let Some(text) = cache.get(path) {
        return *text;
    }
    let file = dir.join(path);
    let text = std::fs::read_to_string(&file).ok().map(|t| {
        let _ = writeln!(
            std::io::stderr(),
            "mesoflow: shader {path} overridden by {}",
            file.display()
        );
        &*Box::leak(t.into_boxed_str())
    });
    cache.insert(path.to_string(), text);
    text
}

/// Why a shader's imports could not be resolved.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ShaderError {
    #[error("no shader file `shaders/{0}`")]
    NoFile(String),
    #[error("import cycle: {0}")]
    Cycle(String),
    /// A library file lacks the line a kernel specialises.
    #[error("{file}: expected one line `{line}` to specialise")]
    NoMarker { file: String, line: String },
    /// The file that imports the failing one.
    #[error("in {file}: {source}")]
    In {
        file: String,
        #[source]
        source: Box<ShaderError>,
    },
}

/// A shader's text with its `#import` lines resolved.
pub fn source(path: &str) -> Result<String, ShaderError> {
    let mut out = String::new();
    let mut seen = Vec::new();
    append(path, &mut out, &mut seen, &mut Vec::new())?;
    Ok(out)
}

/// Resolves `#import` lines in a generated source.
pub fn resolve(text: &str) -> Result<String, ShaderError> {
    let mut out = String::new();
    let mut seen = Vec::new();
    append_text("<generated>", text, &mut out, &mut seen, &mut Vec::new())?;
    Ok(out)
}

fn append(
    path: &str,
    out: &mut String,
    seen: &mut Vec<String>,
    stack: &mut Vec<String>,
) -> Result<(), ShaderError> {
    if seen.iter().any(|s| s == path) {
        return Ok(());
    }
    if stack.iter().any(|s| s == path) {
        return Err(ShaderError::Cycle(format!(
            "{} -> {path}",
            stack.join(" -> ")
        )));
    }
    let text = raw(path).ok_or_else(|| ShaderError::NoFile(path.into()))?;
    stack.push(path.to_string());
    append_text(path, text, out, seen, stack)?;
    stack.pop();
    seen.push(path.to_string());
    Ok(())
}

fn append_text(
    name: &str,
    text: &str,
    out: &mut String,
    seen: &mut Vec<String>,
    stack: &mut Vec<String>,
) -> Result<(), ShaderError> {
    for line in text.lines() {
        if let Some(rest) = line.trim_start().strip_prefix("#import") {
            let dep = rest.trim();
            append(dep, out, seen, stack).map_err(|e| ShaderError::In {
                file: name.into(),
                source: Box::new(e),
            })?;
        } else {
            out.push_str(line);
            out.push('\n');
        }
    }
    Ok(())
}

/// The start and end markers of a portable function in the library that a device may
/// replace, and the replacement for devices with `SHADER_INT64`.
const PHILOX_MULHI: (&str, &str, &str) = (
    "// begin portable philox_mulhi",
    "// end portable philox_mulhi",
    "fn philox_mulhi(a: u32, b: u32) -> u32 {\n    return u32((u64(a) * u64(b)) >> 32u);\n}\n",
);

/// A kernel's source for this device: where it has 64-bit integers, Philox's high-half
/// multiply (`common/philox.wgsl`, built from 16-bit halves, about 14 integer operations)
/// becomes one 64-bit multiply. The same bits either way (exact integer arithmetic); the
/// random draws of MPCD collisions, noise and random nodes are unchanged.
pub fn specialise<'a>(source: &'a str, caps: &DeviceCaps) -> std::borrow::Cow<'a, str> {
    let (begin, end, int64) = PHILOX_MULHI;
    if !caps.int64 {
        return std::borrow::Cow::Borrowed(source);
    }
    match (source.find(begin), source.find(end)) {
        (Some(b), Some(e)) if b < e => {
            let mut out = String::with_capacity(source.len());
            out.push_str(&source[..b]);
            out.push_str(int64);
            out.push_str(&source[e + end.len()..]);
            std::borrow::Cow::Owned(out)
        }
        _ => std::borrow::Cow::Borrowed(source),
    }
}
