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

#[test]
fn a_duplicated_key_is_an_error_at_every_level() {
    use crate::util::{tmpdir, write_graph};
    let dir = tmpdir("duplicate-keys");
    std::fs::write(
        dir.join("sub.json"),
        r#"{"mesoflow": 1, "inputs": {"x": {"type": "particles", "cols": 3}},
            "nodes": [{"id": "s", "kind": "scale", "params": {"factor": 2}, "inputs": {"x": "inputs.x"}}],
            "outputs": {"y": "s.out", "y": "inputs.x"}}"#,
    )
    .unwrap();
    // (the graph, the key repeated, where it is); every file is valid without the repeat.
    let cases = [
        (
            r#"{"mesoflow": 1, "mesoflow": 1, "outputs": {"y": "c.out"},
                "nodes": [{"id": "c", "kind": "constant", "params": {"value": 1}}]}"#,
            "mesoflow",
            "the top level",
        ),
        (
            r#"{"mesoflow": 1, "params": {"k": {"default": 1}, "k": {"default": 2}},
                "nodes": [{"id": "c", "kind": "constant", "params": {"value": "$k"}}], "outputs": {"y": "c.out"}}"#,
            "k",
            "`params`",
        ),
        (
            r#"{"mesoflow": 1, "params": {"k": {"default": 1, "min": 0, "min": 2}},
                "nodes": [{"id": "c", "kind": "constant", "params": {"value": "$k"}}], "outputs": {"y": "c.out"}}"#,
            "min",
            "`params.k`",
        ),
        (
            r#"{"mesoflow": 1, "inputs": {"x": {"type": "particles", "cols": 3}, "x": {"type": "scalar"}},
                "nodes": [{"id": "s", "kind": "scale", "params": {"factor": 2}, "inputs": {"x": "inputs.x"}}], "outputs": {"y": "s.out"}}"#,
            "x",
            "`inputs`",
        ),
        (
            r#"{"mesoflow": 1, "inputs": {"x": {"type": "particles", "cols": 3}},
                "nodes": [{"id": "s", "kind": "scale", "kind": "affine", "params": {"factor": 2}, "inputs": {"x": "inputs.x"}}], "outputs": {"y": "s.out"}}"#,
            "kind",
            "`nodes[0]`",
        ),
        (
            r#"{"mesoflow": 1, "inputs": {"x": {"type": "particles", "cols": 3}, "z": {"type": "particles", "cols": 3}},
                "nodes": [{"id": "s", "kind": "add", "inputs": {"a": "inputs.x", "b": "inputs.x", "a": "inputs.z"}}], "outputs": {"y": "s.out"}}"#,
            "a",
            "`nodes[0].inputs`",
        ),
        (
            r#"{"mesoflow": 1, "inputs": {"x": {"type": "particles", "cols": 3}},
                "state": {"p": {"init": "inputs.x", "next": "state.p", "next": "inputs.x"}},
                "outputs": {"y": "state.p"}}"#,
            "next",
            "`state.p`",
        ),
        (
            r#"{"mesoflow": 1, "inputs": {"x": {"type": "particles", "cols": 3}},
                "outputs": {"y": "inputs.x", "y": {"from": "inputs.x", "doc": "again"}}}"#,
            "y",
            "`outputs`",
        ),
        // In a subgraph file: reported with that file.
        (
            r#"{"mesoflow": 1, "inputs": {"x": {"type": "particles", "cols": 3}},
                "nodes": [{"id": "m", "graph": "sub.json", "inputs": {"x": "inputs.x"}}], "outputs": {"y": "m.y"}}"#,
            "y",
            "`outputs`",
        ),
    ];
    for (i, (json, key, place)) in cases.iter().enumerate() {
        let path = write_graph(&dir, &format!("g{i}.json"), json);
        let err = match validate_file(registry(), &path) {
            Ok(_) => panic!("case {i}: a repeated `{key}` was accepted:\n{json}"),
            Err(e) => e.to_string(),
        };
        assert!(
            err.contains(&format!("duplicate key `{key}` in {place}")) && err.contains("line"),
            "case {i}: {err}"
        );
        let file = if i == cases.len() - 1 {
            "sub.json"
        } else {
            ".json"
        };
        assert!(err.contains(file), "case {i}: {err}");
    }
}
