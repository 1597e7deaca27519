//! The dependency rules of ARCHITECTURE.md that the compiler does not check: the node
//! families live in `nodes/` and enter the engine crate as the module `nodes` (so that
//! the folder stays where users look for it), which would let engine code name them.
//! These tests read the sources and fail where a dependency points the wrong way.

use std::path::{Path, PathBuf};

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// Lines of the files under `dir` (relative to the crate) that contain any of `needles`,
/// as `file:line: text`, skipping the files `allowed` names (paths relative to `dir`).
fn offending(dir: &str, allowed: &[&str], needles: &[&str]) -> Vec<String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join(dir);
    let mut files = Vec::new();
    rust_files(&root, &mut files);
    let mut found = Vec::new();
    for f in files {
        let rel = f
            .strip_prefix(&root)
            .unwrap()
            .to_string_lossy()
            .replace('\\', "/");
        if allowed
            .iter()
            .any(|a| rel == *a || rel.starts_with(&format!("{a}/")))
        {
            continue;
        }
        for (i, line) in std::fs::read_to_string(&f).unwrap().lines().enumerate() {
            if needles.iter().any(|n| line.contains(n)) {
                found.push(format!("{dir}/{rel}:{}: {}", i + 1, line.trim()));
            }
        }
    }
    found
}

#[test]
fn the_engine_names_no_node_family() {
    // The binary (main, cli, bench) is outside the engine and may use the families.
    let found = offending(
        "src",
        &["main.rs", "cli.rs", "bench"],
        &["crate::nodes", "mesoflow::nodes", "super::nodes"],
    );
    assert!(
        found.is_empty(),
        "engine code reaches into nodes/ (the registry is handed to it instead):\n{}",
        found.join("\n")
    );
}

#[test]
fn bench_does_not_depend_on_cli() {
    let found = offending("src/bench", &[], &["crate::cli", "super::cli"]);
    assert!(
        found.is_empty(),
        "bench imports the command line:\n{}",
        found.join("\n")
    );
}

#[test]
fn node_families_reach_the_engine_only_through_its_contract() {
    // Nodes use the engine's public layers, never the planner's or executor's insides.
    let found = offending(
        "nodes",
        &[],
        &["crate::plan::", "crate::exec::", "crate::graph::load"],
    );
    assert!(
        found.is_empty(),
        "node code reaches into the planner or executor:\n{}",
        found.join("\n")
    );
}
