//! Embeds every WGSL file under `shaders/` and every graph file under `graphs/` (not the
//! test fixtures) into the binary, so kernels need no file IO at run time, graphs are
//! found by name wherever the binary or the Python package goes, and the binary can be
//! copied alone (as to the GPU machine).
use std::fmt::Write;
use std::path::Path;

fn walk_ext(dir: &Path, root: &Path, ext: &str, out: &mut Vec<String>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .expect("read the folder to embed")
        .flatten()
        .collect();
    entries.sort_by_key(|e| e.path());
    for e in entries {
        let p = e.path();
        if p.is_dir() {
            if p.file_name().is_some_and(|n| n == "fixtures") {
                continue;
            }
            walk_ext(&p, root, ext, out);
        } else if p.extension().is_some_and(|x| x == ext) {
            out.push(
                p.strip_prefix(root)
                    .unwrap()
                    .to_string_lossy()
                    .replace('\\', "/"),
            );
        }
    }
}

/// Writes `OUT_DIR/<out>`: `pub static <name>: &[(&str, &str)]`, the path under
/// `<manifest>/<folder>` and the text of every file with extension `ext`.
fn embed(manifest: &str, folder: &str, ext: &str, name: &str, out: &str) {
    let root = Path::new(manifest).join(folder);
    println!("cargo:rerun-if-changed={folder}");
    let mut files = Vec::new();
    walk_ext(&root, &root, ext, &mut files);
    let mut code = format!("pub static {name}: &[(&str, &str)] = &[\n");
    for f in &files {
        let abs = root.join(f);
        println!("cargo:rerun-if-changed={}", abs.display());
        writeln!(
            code,
            "    ({f:?}, include_str!({:?})),",
            abs.display().to_string()
        )
        .unwrap();
    }
    code.push_str("];\n");
    let out = Path::new(&std::env::var("OUT_DIR").unwrap()).join(out);
    std::fs::write(out, code).unwrap();
}

fn main() {
    // Read at run time, not with env!(): a build-script binary reused from another
    // checkout (a copied target folder) would otherwise embed that checkout's shaders.
    let manifest = std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR");
    embed(&manifest, "shaders", "wgsl", "FILES", "shader_files.rs");
    embed(&manifest, "graphs", "json", "GRAPH_FILES", "graph_files.rs");
}
