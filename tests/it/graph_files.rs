//! Every graph file under graphs/ is a fixture: valid ones must load and plan, and each
//! file under graphs/fixtures/invalid/ must fail with every line of its `.expect` file
//! appearing in the report (all problems are reported at once).

use std::path::{Path, PathBuf};

use mesoflow::plan::validate_file;

use crate::util::{registry, root};

fn graph_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            graph_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "json") {
            out.push(p);
        }
    }
    out.sort();
}

#[test]
fn every_valid_graph_file_loads_and_plans() {
    let mut files = Vec::new();
    graph_files(&root().join("graphs"), &mut files);
    let invalid = root().join("graphs/fixtures/invalid");
    let mut checked = 0;
    for f in files.iter().filter(|f| !f.starts_with(&invalid)) {
        if let Err(e) = validate_file(registry(), f) {
            panic!("{} should be valid:\n{e}", f.display());
        }
        checked += 1;
    }
    assert!(
        checked >= 4,
        "expected the example and fixture graphs, found {checked}"
    );
}

#[test]
fn every_invalid_fixture_reports_its_problems() {
    let dir = root().join("graphs/fixtures/invalid");
    let mut files = Vec::new();
    graph_files(&dir, &mut files);
    assert!(files.len() >= 10);
    for f in &files {
        let expect_file = f.with_extension("expect");
        let expected = std::fs::read_to_string(&expect_file)
            .unwrap_or_else(|_| panic!("{} has no {}", f.display(), expect_file.display()));
        let err = match validate_file(registry(), f) {
            Ok(_) => panic!("{} should fail", f.display()),
            Err(e) => e.to_string(),
        };
        for line in expected.lines().filter(|l| !l.trim().is_empty()) {
            assert!(
                err.contains(line.trim()),
                "{}: expected `{}` in:\n{err}",
                f.display(),
                line.trim()
            );
        }
        // Every problem names the file it comes from.
        for line in err.lines().skip(1) {
            assert!(
                line.contains(".json"),
                "{}: problem without a file: {line}",
                f.display()
            );
        }
    }
}
