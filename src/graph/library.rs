//! The graph library: the shipped graph files (`graphs/`, fixtures left out), embedded in
//! the binary at build time (build.rs), so that subgraphs and graphs named without a path
//! (`fcm`, `lib/cell_list.json`) are found wherever the binary or the Python package is
//! installed, not only in a source checkout.
//!
//! The library's folders, in order: `MESOFLOW_GRAPH_LIB` (a path list) when set; else the
//! source checkout's `graphs/` when it is still there (a developer's edits take effect
//! without a rebuild); else the embedded files, written once into a folder of the system's
//! temporary directory named by the crate version and a hash of their contents (files are
//! what subgraph resolution reads; the folder is shared by every process of the same
//! build and never rewritten).

use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};

mod embedded {
    include!(concat!(env!("OUT_DIR"), "/graph_files.rs"));
}

/// The embedded graph files: path under `graphs/` and text.
pub fn embedded_files() -> &'static [(&'static str, &'static str)] {
    embedded::GRAPH_FILES
}

/// The folders subgraphs and named graphs are looked up in, in order.
pub fn library_folders() -> Vec<PathBuf> {
    if let Some(list) = std::env::var_os("MESOFLOW_GRAPH_LIB") {
        return std::env::split_paths(&list).collect();
    }
    let checkout = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/graphs"));
    if checkout.join("fcm.json").is_file() {
        return vec![checkout];
    }
    // Written out (and its contents hashed) once per process, not at every load.
    static WRITTEN: std::sync::OnceLock<Option<PathBuf>> = std::sync::OnceLock::new();
    match WRITTEN.get_or_init(|| materialized().ok()) {
        Some(dir) => vec![dir.clone()],
        None => vec![checkout],
    }
}

/// The embedded files written out once: `<tmp>/mesoflow-graphs-<version>-<hash>/`.
fn materialized() -> std::io::Result<PathBuf> {
    let mut hasher = std::collections::hash_map::DefaultHasher::new();
    for (name, text) in embedded_files() {
        name.hash(&mut hasher);
        text.hash(&mut hasher);
    }
    let dir = std::env::temp_dir().join(format!(
        "mesoflow-graphs-{}-{:016x}",
        env!("CARGO_PKG_VERSION"),
        hasher.finish()
    ));
    if dir.join(".complete").is_file() {
        return Ok(dir);
    }
    // Written into a private folder first, then renamed into place: a concurrent process
    // sees either no folder or a whole one.
    let staging = std::env::temp_dir().join(format!(
        "mesoflow-graphs-staging-{}-{}",
        std::process::id(),
        hasher.finish()
    ));
    let _ = std::fs::remove_dir_all(&staging);
    for (name, text) in embedded_files() {
        let path = staging.join(name);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent)?;
        }
        std::fs::write(path, text)?;
    }
    std::fs::write(staging.join(".complete"), "")?;
    match std::fs::rename(&staging, &dir) {
        Ok(()) => Ok(dir),
        Err(_) if dir.join(".complete").is_file() => {
            let _ = std::fs::remove_dir_all(&staging);
            Ok(dir)
        }
        Err(e) => Err(e),
    }
}

/// A graph named by path, or by name in the library: `fcm`, `fcm.json`, `examples/colloids`.
/// A name that is an existing file is that file; otherwise each library folder is tried
/// with the name and the name plus `.json`. `None` when nothing matches.
pub fn find(name: &str) -> Option<PathBuf> {
    let given = Path::new(name);
    if given.is_file() {
        return Some(given.to_path_buf());
    }
    for folder in library_folders() {
        for candidate in [folder.join(name), folder.join(format!("{name}.json"))] {
            if candidate.is_file() {
                return Some(candidate);
            }
        }
    }
    None
}

/// The names of the library's graphs (paths under the library without `.json`), for
/// listings and error messages.
pub fn names() -> Vec<String> {
    embedded_files()
        .iter()
        .map(|(name, _)| name.trim_end_matches(".json").to_string())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The embedded files written out are the shipped graphs, subgraphs included, and a
    /// second call reuses the folder.
    #[test]
    fn embedded_graphs_are_written_out_whole() {
        let dir = materialized().expect("a temporary folder");
        for (name, text) in embedded_files() {
            assert_eq!(
                &std::fs::read_to_string(dir.join(name)).unwrap(),
                text,
                "{name}"
            );
        }
        assert!(dir.join("lib/cell_list.json").is_file());
        assert!(
            !embedded_files()
                .iter()
                .any(|(n, _)| n.starts_with("fixtures/"))
        );
        assert_eq!(materialized().unwrap(), dir);
        assert!(names().contains(&"fcm".to_string()));
    }

    /// Names find library graphs with or without `.json`; an existing path is itself.
    #[test]
    fn names_and_paths_are_found() {
        let fcm = find("fcm").expect("fcm by name");
        assert!(fcm.ends_with("fcm.json"));
        assert_eq!(
            find("examples/colloids.json").unwrap().file_name().unwrap(),
            "colloids.json"
        );
        assert!(find("no_such_graph").is_none());
        let here = concat!(env!("CARGO_MANIFEST_DIR"), "/graphs/pse.json");
        assert_eq!(find(here).unwrap(), std::path::PathBuf::from(here));
    }
}
