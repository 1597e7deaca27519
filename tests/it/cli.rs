//! The `mesoflow` binary: commands, and bad input getting a clear message, a non-zero
//! exit and no output file.

use std::path::Path;
use std::process::{Command, Output};

use mesoflow::value::{HostArray, ValueType};

use crate::util::{gpu, root, tmpdir};

fn mesoflow(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mesoflow"))
        .args(args)
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .expect("run mesoflow")
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// Expects failure with exit code 2 and every `needle` in the message.
fn fails_with(args: &[&str], needles: &[&str]) {
    let o = mesoflow(args);
    let t = text(&o);
    assert_eq!(
        o.status.code(),
        Some(2),
        "{args:?} should exit with 2:\n{t}"
    );
    assert!(!t.contains("panicked"), "{args:?} panicked:\n{t}");
    for n in needles {
        assert!(t.contains(n), "{args:?}: expected `{n}` in:\n{t}");
    }
}

fn relax() -> String {
    root()
        .join("graphs/examples/relax.json")
        .display()
        .to_string()
}

fn positions(dir: &Path, name: &str, values: Vec<f32>, n: u32) -> String {
    let p = dir.join(name);
    mesoflow::npy::write(
        &p,
        &HostArray::f32(ValueType::Particles { n, k: 3 }, values),
    )
    .unwrap();
    p.display().to_string()
}

#[test]
fn nodes_lists_every_kind_with_ports_and_params() {
    let o = mesoflow(&["nodes"]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    for k in crate::util::registry().kinds() {
        assert!(
            t.contains(&format!("{}: {}", k.name(), k.doc())),
            "missing {}",
            k.name()
        );
    }
    assert!(t.contains("prm  alpha"), "{t}");
    fails_with(
        &["nodes", "scal"],
        &["no node kind `scal` (did you mean `scale`?)"],
    );
}

#[test]
fn validate_reports_problems_with_exit_code_two() {
    let o = mesoflow(&["validate", &relax()]);
    assert!(o.status.success(), "{}", text(&o));
    let bad = root()
        .join("graphs/fixtures/invalid/bad_ref.json")
        .display()
        .to_string();
    fails_with(
        &["validate", &relax(), &bad],
        &["4 problems", "no node `nod1`"],
    );
}

/// Graphs of the library are found by name from any folder; an unknown name is an error
/// naming it.
#[test]
fn graphs_are_found_by_name_from_any_folder() {
    let o = Command::new(env!("CARGO_BIN_EXE_mesoflow"))
        .args(["validate", "rpy_open", "examples/relax"])
        .current_dir(std::env::temp_dir())
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .expect("run mesoflow");
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(
        t.contains("rpy_open: ok") && t.contains("examples/relax: ok"),
        "{t}"
    );
    fails_with(&["validate", "no_such_graph"], &["no_such_graph"]);
}

#[test]
fn inspect_prints_the_plan_and_dot() {
    let o = mesoflow(&["inspect", &relax(), "--set", "dt=0.5"]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(
        t.contains("dt = 0.5") && t.contains("fused x2") && t.contains("memory"),
        "{t}"
    );
    let o = mesoflow(&["inspect", &relax(), "--dot"]);
    assert!(
        String::from_utf8_lossy(&o.stdout).starts_with("digraph"),
        "{}",
        text(&o)
    );
}

/// `inspect` plans what `run` would: optional inputs absent unless given (fcm.json's
/// torque path at L = 64, which needs `rotation`, then never runs), the inputs not given
/// with the sizes the given ones fix (4 particles, not the size's default of 1000), and
/// `--with` to plan an optional input at its declared shape. Before, both first commands
/// exited with 2 (a torque-grid error; "input `torques` has 1000 rows").
#[test]
fn inspect_assumes_the_inputs_a_run_would_have() {
    let fcm = root().join("graphs/fcm.json").display().to_string();
    let o = mesoflow(&[
        "inspect",
        &fcm,
        "--set",
        "box=[64,64,64]",
        "--output",
        "velocities",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let dir = tmpdir("cli-inspect-inputs");
    let x = positions(&dir, "x.npy", vec![0.5; 12], 4);
    let f = positions(&dir, "f.npy", vec![1.0; 12], 4);
    let (xs, fs) = (format!("positions={x}"), format!("forces={f}"));
    let o = mesoflow(&[
        "inspect",
        &fcm,
        "--input",
        &xs,
        "--input",
        &fs,
        "--output",
        "velocities",
    ]);
    let t = text(&o);
    assert!(o.status.success() && t.contains("particles(4x3)"), "{t}");
    fails_with(
        &[
            "inspect",
            &fcm,
            "--input",
            &xs,
            "--with",
            "torques",
            "--output",
            "velocities",
        ],
        &["spread_torques"],
    );
    fails_with(
        &["inspect", &fcm, "--with", "positions"],
        &["--with positions: input `positions` is required"],
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_input_is_a_clear_error_and_leaves_no_output() {
    let dir = tmpdir("cli-bad");
    let out = dir.join("out.npy");
    let out_arg = format!("positions={}", out.display());
    let good = positions(&dir, "good.npy", vec![0.5; 12], 4);
    let missing = dir.join("missing.npy").display().to_string();
    fails_with(
        &[
            "run",
            &relax(),
            "--input",
            &format!("positions={missing}"),
            "--output",
            &out_arg,
        ],
        &["missing.npy", "cannot read"],
    );
    let short = dir.join("short.npy");
    mesoflow::npy::write(
        &short,
        &HostArray::f32(ValueType::Particles { n: 5, k: 1 }, vec![1.0; 5]),
    )
    .unwrap();
    fails_with(
        &[
            "run",
            &relax(),
            "--input",
            &format!("positions={}", short.display()),
        ],
        &["short.npy", "shape (5, 1) does not fit particles(nx3)"],
    );
    let mut v = vec![0.5; 12];
    v[4] = f32::NAN;
    let nan = positions(&dir, "nan.npy", v, 4);
    fails_with(
        &["run", &relax(), "--input", &format!("positions={nan}")],
        &["nan.npy", "element 4 is NaN"],
    );
    let input = format!("positions={good}");
    fails_with(
        &["run", &relax(), "--input", &input, "--set", "viscosity=2"],
        &["unknown param `viscosity`", "stiffness, dt"],
    );
    fails_with(
        &["run", &relax(), "--input", &input, "--set", "dt=-1"],
        &["bad value -1 for param `dt`", "below the minimum 0"],
    );
    fails_with(
        &["run", &relax(), "--input", &input, "--set", "dt=fast"],
        &["param `dt`", "expected a number"],
    );
    fails_with(
        &[
            "run",
            &relax(),
            "--input",
            &input,
            "--output",
            "velocity=v.npy",
        ],
        &["no output `velocity`", "positions, force"],
    );
    fails_with(
        &["run", &relax(), "--input", &input, "--input", &input],
        &["given twice"],
    );
    fails_with(
        &["run", &relax()],
        &["missing required inputs", "--input positions=FILE.npy"],
    );
    fails_with(
        &["run", &relax(), "--input", &input, "--steps", "0"],
        &["--steps must be at least 1"],
    );
    let nowhere = format!("positions={}", dir.join("no/such/dir/out.npy").display());
    fails_with(
        &["run", &relax(), "--input", &input, "--output", &nowhere],
        &["does not exist"],
    );
    fails_with(
        &["run", "no_such_graph.json"],
        &["no_such_graph.json", "cannot read graph file"],
    );
    assert!(!out.exists(), "a failed run left an output file");
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().contains("tmp"))
        .collect();
    assert!(leftovers.is_empty());
}

#[test]
fn run_writes_outputs_and_accepts_float64_and_flat_inputs() {
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("cli-run");
    // A float64, flat (3N,) input.
    let flat = dir.join("flat.npy");
    {
        use npyz::WriterBuilder;
        let mut f = std::io::BufWriter::new(std::fs::File::create(&flat).unwrap());
        let mut w = npyz::WriteOptions::<f64>::new()
            .default_dtype()
            .shape(&[6])
            .writer(&mut f)
            .begin_nd()
            .unwrap();
        w.extend([1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
        w.finish().unwrap();
    }
    let out = dir.join("out.npy");
    let o = mesoflow(&[
        "run",
        &relax(),
        "--input",
        &format!("positions={}", flat.display()),
        "--output",
        &format!("positions={}", out.display()),
        "--steps",
        "3",
        "--set",
        "stiffness=2",
        "--profile",
    ]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(t.contains("profile: GPU time per launch"), "{t}");
    let shape = ValueType::Particles { n: 2, k: 3 };
    let got = mesoflow::npy::read_input(
        &out,
        &mesoflow::graph::InputShape::Particles {
            rows: mesoflow::graph::Dim::Free,
            cols: 3,
        },
    )
    .unwrap();
    assert_eq!(got.ty, shape);
    let factor = (1.0f64 - 2.0 * 0.01).powi(3);
    for (g, x) in got.data.to_f64().iter().zip([1.0, 2.0, 3.0, 4.0, 5.0, 6.0]) {
        assert!((g - factor * x).abs() < 1e-5, "{g} vs {}", factor * x);
    }
}

#[test]
fn missing_or_unknown_adapters_are_clear_errors() {
    // No Vulkan driver at all: the loader finds none through a driver list that is empty.
    let o = Command::new(env!("CARGO_BIN_EXE_mesoflow"))
        .arg("info")
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .env("VK_DRIVER_FILES", "/nonexistent/icd.json")
        .env("VK_ICD_FILENAMES", "/nonexistent/icd.json")
        .output()
        .unwrap();
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(
        t.contains("no Vulkan adapter found") && t.contains("mesa-vulkan-drivers"),
        "{t}"
    );
    assert!(!t.contains("panicked"), "{t}");
    if gpu().is_some() {
        let o = Command::new(env!("CARGO_BIN_EXE_mesoflow"))
            .arg("info")
            .env("XDG_RUNTIME_DIR", std::env::temp_dir())
            .env("MESOFLOW_ADAPTER", "no-such-gpu")
            .output()
            .unwrap();
        let t = text(&o);
        assert_eq!(o.status.code(), Some(1), "{t}");
        assert!(
            t.contains("no Vulkan adapter matches MESOFLOW_ADAPTER=\"no-such-gpu\"")
                && t.contains("adapters found:"),
            "{t}"
        );
    }
}

/// The numbers on a table row after its label.
fn row_numbers(text: &str, label: &str) -> Vec<f64> {
    let row = text
        .lines()
        .find(|l| l.starts_with(label))
        .unwrap_or_else(|| panic!("no row `{label}` in:\n{text}"));
    row[label.len()..]
        .split_whitespace()
        .filter_map(|w| w.parse().ok())
        .collect()
}

#[test]
fn bench_tables_give_the_end_to_end_time_beside_the_launch_sum() {
    if gpu().is_none() {
        return;
    }
    let o = mesoflow(&["bench", "overhead", "--nodes", "4", "--reps", "2"]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(
        t.lines().any(|l| l.starts_with("us per node")
            && l.contains("end to end")
            && l.contains("launches")),
        "{t}"
    );
    // Wall, end to end and launch sum for the executor; wall and end to end for raw wgpu.
    let executor = row_numbers(&t, "mesoflow executor (graph file, planned)");
    assert_eq!(executor.len(), 3, "{t}");
    assert!(executor.iter().all(|&us| us > 0.0), "{t}");
    assert_eq!(row_numbers(&t, "raw wgpu").len(), 2, "{t}");

    let o = mesoflow(&["bench", "scan", "--n", "1000", "--reps", "2"]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(
        t.contains("the whole call end to end") && t.contains("launches ms"),
        "{t}"
    );
    fails_with(
        &["bench", "overhead", "--nodes", "0"],
        &["--nodes and --reps must be positive"],
    );
}
/// Runs mesoflow with its stdout a pipe whose reading end is already closed (as `| head`
/// leaves it once it has read enough): every write to stdout fails with a broken pipe.
fn mesoflow_into_closed_pipe(args: &[&str]) -> Output {
    let (reader, writer) = std::io::pipe().expect("a pipe");
    drop(reader);
    Command::new(env!("CARGO_BIN_EXE_mesoflow"))
        .args(args)
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .stdout(writer)
        .stderr(std::process::Stdio::piped())
        .output()
        .expect("run mesoflow")
}

#[test]
fn a_closed_stdout_ends_every_command_quietly_with_its_own_exit_code() {
    let bad = root()
        .join("graphs/fixtures/invalid/bad_ref.json")
        .display()
        .to_string();
    let mut cases: Vec<(Vec<String>, i32)> = vec![
        (vec!["nodes".into()], 0),
        (vec!["nodes".into(), "scale".into()], 0),
        (vec!["validate".into(), relax()], 0),
        // The failure is still reported by its exit code when nobody reads stdout.
        (vec!["validate".into(), relax(), bad], 2),
        (vec!["inspect".into(), relax()], 0),
        (vec!["inspect".into(), relax(), "--dot".into()], 0),
        (vec!["--help".into()], 0),
    ];
    let dir = tmpdir("cli-closed-stdout");
    if gpu().is_some() {
        let input = format!("positions={}", positions(&dir, "x.npy", vec![0.5; 12], 4));
        let written = format!("positions={}", dir.join("out.npy").display());
        cases.push((
            vec!["run".into(), relax(), "--input".into(), input.clone()],
            0,
        ));
        cases.push((
            vec![
                "run".into(),
                relax(),
                "--input".into(),
                input,
                "--output".into(),
                written,
                "--profile".into(),
            ],
            0,
        ));
        cases.push((vec!["info".into()], 0));
    }
    for (args, code) in &cases {
        let args: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
        let o = mesoflow_into_closed_pipe(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!err.contains("panicked"), "{args:?} panicked:\n{err}");
        assert_eq!(o.status.code(), Some(*code), "{args:?}:\n{err}");
        assert!(!err.contains("Broken pipe"), "{args:?}:\n{err}");
    }
    if gpu().is_some() {
        // Outputs are written whether or not anyone reads the report.
        assert!(dir.join("out.npy").exists());
    }
}

/// Number of problems a report announces on its first line (`N problems:`).
fn problem_count(report: &str) -> usize {
    let line = report
        .lines()
        .find(|l| l.contains(" problem"))
        .unwrap_or_else(|| panic!("no problem count in:\n{report}"));
    line.split_whitespace()
        .find_map(|w| w.parse().ok())
        .unwrap_or_else(|| panic!("no problem count in `{line}`"))
}

#[test]
fn one_bad_set_is_reported_as_its_root_cause_with_the_consequences_once() {
    let fcm = root().join("graphs/fcm.json").display().to_string();
    let bd = root().join("graphs/bd_fcm.json").display().to_string();
    for (graph, set, root_cause, dependant) in [
        (
            &fcm,
            "kernel=gauss",
            "bad value \"gauss\" for param `kernel`",
            "grid",
        ),
        (
            &fcm,
            "box=64",
            "bad value 64 for param `box`: expected an array of numbers",
            "grid",
        ),
        (
            &fcm,
            "tolerance=abc",
            "bad value \"abc\" for param `tolerance`",
            "beta",
        ),
        (
            &fcm,
            "radius=-1",
            "bad value -1 for param `radius`",
            "width",
        ),
        // Through a subgraph: the parent's param feeds fcm.json's.
        (
            &bd,
            "kernel=gauss",
            "bad value \"gauss\" for param `kernel`",
            "mobility",
        ),
    ] {
        let o = mesoflow(&["inspect", graph, "--set", set]);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(2), "{set}:\n{t}");
        assert_eq!(problem_count(&t), 1, "--set {set}:\n{t}");
        let first = t.lines().nth(1).unwrap_or_default();
        assert!(
            first.contains(root_cause),
            "--set {set}: root cause first:\n{t}"
        );
        assert!(
            first.contains(dependant),
            "--set {set}: its dependants named:\n{t}"
        );
        assert!(!t.contains("unknown param"), "--set {set}:\n{t}");
    }
    // The nearest name or choice is suggested.
    fails_with(
        &["inspect", &fcm, "--set", "viscosty=2"],
        &["unknown param `viscosty`", "did you mean `viscosity`?"],
    );
    fails_with(
        &["inspect", &fcm, "--set", "kernel=gauss"],
        &["did you mean \"gaussian\"?"],
    );
    // Independent problems are still each reported.
    let o = mesoflow(&[
        "inspect",
        &fcm,
        "--set",
        "kernel=gauss",
        "--set",
        "viscosity=-1",
    ]);
    assert_eq!(problem_count(&text(&o)), 2, "{}", text(&o));
}

#[test]
fn nodes_prints_ranges_as_people_write_them() {
    let o = mesoflow(&["nodes"]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    for unreadable in ["e-308", "[-inf, inf]", ", inf]", "17976931348623157"] {
        assert!(!t.contains(unreadable), "`{unreadable}` in:\n{t}");
    }
    let line = |kind: &str, param: &str| -> String {
        let o = mesoflow(&["nodes", kind]);
        String::from_utf8_lossy(&o.stdout)
            .lines()
            .find(|l| l.starts_with(&format!("  prm  {param} ")))
            .unwrap_or_else(|| panic!("{kind} has no param {param}"))
            .to_string()
    };
    // Params the kernels compute with in f32 carry the range where that is meaningful.
    assert!(line("all_pairs", "radius").contains("number in [1e-18, 1e18]"));
    assert!(line("all_pairs", "split").contains("number in [0, 1e18]"));
    assert!(line("affine", "scale").contains("number in [-1e18, 1e18], default 1"));
    assert!(line("all_pairs", "table_points").contains("integer in [16, 4194304]"));
    assert!(t.contains(mesoflow::node::F32_RANGE_NOTE), "{t}");
    // A bad node param value is told against the same readable range.
    let dir = tmpdir("cli-ranges");
    let g = crate::util::write_graph(
        &dir,
        "g.json",
        r#"{"mesoflow": 1, "inputs": {"x": {"type": "particles", "cols": 3}},
            "nodes": [{"id": "p", "kind": "all_pairs", "params": {"radius": -1}, "inputs": {"positions": "inputs.x", "values": "inputs.x"}}],
            "outputs": {"u": "p.out"}}"#,
    );
    let o = mesoflow(&["validate", &g.display().to_string()]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(2), "{t}");
    assert!(t.contains("-1 is outside [1e-18, 1e18]"), "{t}");
    assert!(!t.contains("e-308") && !t.contains("0.0000000"), "{t}");
}

/// The files in a folder whose names show a temporary output (`.NAME.PID.tmp`).
fn temporaries(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().to_string())
        .filter(|n| n.ends_with(".tmp"))
        .collect()
}

#[test]
fn outputs_are_named_once_and_go_to_distinct_files() {
    let dir = tmpdir("cli-output-names");
    let input = format!("positions={}", positions(&dir, "x.npy", vec![0.5; 12], 4));
    let a = dir.join("a.npy").display().to_string();
    fails_with(
        &[
            "run",
            &relax(),
            "--input",
            &input,
            "--output",
            &format!("positions={a}"),
            "--output",
            "positions",
        ],
        &["--output positions is given twice"],
    );
    fails_with(
        &[
            "run",
            &relax(),
            "--input",
            &input,
            "--output",
            &format!("positions={a}"),
            "--output",
            &format!("force={}", dir.join(".").join("a.npy").display()),
        ],
        &[
            "--output force",
            "a.npy",
            "also the file of --output positions",
        ],
    );
    fails_with(
        &[
            "inspect",
            &relax(),
            "--output",
            "force",
            "--output",
            "force",
        ],
        &["output `force` is asked for twice"],
    );
    assert!(!dir.join("a.npy").exists());
}

#[test]
fn a_graph_without_outputs_is_an_error() {
    let dir = tmpdir("cli-no-outputs");
    let g = crate::util::write_graph(
        &dir,
        "g.json",
        r#"{"mesoflow": 1, "nodes": [{"id": "c", "kind": "constant", "params": {"value": 1}}]}"#,
    )
    .display()
    .to_string();
    for cmd in ["validate", "inspect", "run"] {
        fails_with(&[cmd, &g], &["g.json", "declares no outputs"]);
    }
}

#[test]
fn when_one_output_cannot_be_written_none_is() {
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("cli-all-or-nothing");
    let input = format!("positions={}", positions(&dir, "x.npy", vec![0.5; 12], 4));
    let first = dir.join("first.npy");
    // A file name that is valid but leaves no room for the temporary's longer name.
    let long = dir.join(format!("{}.npy", "f".repeat(246)));
    let o = mesoflow(&[
        "run",
        &relax(),
        "--input",
        &input,
        "--output",
        &format!("positions={}", first.display()),
        "--output",
        &format!("force={}", long.display()),
    ]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(
        t.contains("--output force") && t.contains("no output was written"),
        "{t}"
    );
    assert!(
        !first.exists(),
        "an output was written although another failed:\n{t}"
    );
    assert!(!long.exists());
    assert!(temporaries(&dir).is_empty(), "{:?}", temporaries(&dir));
}

#[test]
fn an_interrupted_run_leaves_no_temporary_and_no_partial_set_of_outputs() {
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("cli-interrupt");
    // Four outputs of 16 MB each: writing them (each synced to disk) takes long enough
    // for the interrupt to arrive while a temporary exists.
    let g = crate::util::write_graph(
        &dir,
        "big.json",
        r#"{"mesoflow": 1,
            "nodes": [{"id": "c", "kind": "constant", "params": {"value": 1, "rows": 4000000}},
                      {"id": "d", "kind": "scale", "params": {"factor": 2}, "inputs": {"x": "c.out"}}],
            "outputs": {"a": "c.out", "b": "d.out", "c": "c.out", "d": "d.out"}}"#,
    )
    .display()
    .to_string();
    let outs: Vec<std::path::PathBuf> = ["a", "b", "c", "d"]
        .iter()
        .map(|n| dir.join(format!("{n}.npy")))
        .collect();
    let mut caught = 0;
    for _attempt in 0..5 {
        for o in &outs {
            let _ = std::fs::remove_file(o);
        }
        let mut args = vec!["run".to_string(), g.clone()];
        for (n, o) in ["a", "b", "c", "d"].iter().zip(&outs) {
            args.push("--output".into());
            args.push(format!("{n}={}", o.display()));
        }
        let mut child = Command::new(env!("CARGO_BIN_EXE_mesoflow"))
            .args(&args)
            .env("XDG_RUNTIME_DIR", std::env::temp_dir())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        // Interrupt as soon as a temporary output appears.
        let seen = loop {
            if !temporaries(&dir).is_empty() {
                break true;
            }
            if child.try_wait().unwrap().is_some() {
                break false;
            }
        };
        if seen {
            let _ = Command::new("kill")
                .args(["-INT", &child.id().to_string()])
                .status();
        }
        let o = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!err.contains("panicked"), "{err}");
        assert!(
            temporaries(&dir).is_empty(),
            "left behind: {:?}",
            temporaries(&dir)
        );
        let written = outs.iter().filter(|o| o.exists()).count();
        assert!(
            written == 0 || written == outs.len(),
            "{written} of 4 outputs written:\n{err}"
        );
        if seen {
            caught += 1;
            if written == 0 {
                assert_ne!(o.status.code(), Some(0), "interrupted but exit 0:\n{err}");
            }
        }
    }
    assert!(caught > 0, "no attempt was interrupted while writing");
    // 64 MB of outputs when the last attempt finished writing.
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn run_without_output_computes_every_output_the_inputs_and_params_allow() {
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("cli-no-output-arg");
    let x = positions(&dir, "x.npy", vec![0.5, 1.0, 1.5, -2.0, 3.0, 4.0], 2);
    let fcm = root().join("graphs/fcm.json").display().to_string();
    let o = mesoflow(&[
        "run",
        &fcm,
        "--input",
        &format!("positions={x}"),
        "--input",
        &format!("forces={x}"),
    ]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    let out = String::from_utf8_lossy(&o.stdout);
    for name in ["velocities:", "noise:", "fluctuating_velocities:"] {
        assert!(out.contains(name), "{name} not summarised:\n{t}");
    }
    // The one output these inputs and params cannot give is named, with the reason.
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!out.contains("angular_velocities:"), "{t}");
    assert!(
        err.contains("output `angular_velocities` is left out") && err.contains("too coarse"),
        "{t}"
    );
    // Asked for by name, it is an error, for the same reason.
    fails_with(
        &[
            "run",
            &fcm,
            "--input",
            &format!("positions={x}"),
            "--input",
            &format!("forces={x}"),
            "--output",
            "angular_velocities",
        ],
        &["too coarse"],
    );
}

#[test]
fn npy_inputs_of_an_unsupported_dtype_are_refused_with_the_file_named() {
    use npyz::WriterBuilder;
    let dir = tmpdir("cli-dtypes");
    let complex = dir.join("complex.npy");
    {
        let mut f = std::io::BufWriter::new(std::fs::File::create(&complex).unwrap());
        let mut w = npyz::WriteOptions::<num_complex::Complex<f32>>::new()
            .default_dtype()
            .shape(&[4, 3])
            .writer(&mut f)
            .begin_nd()
            .unwrap();
        w.extend((0..12).map(|i| num_complex::Complex::new(i as f32, 1.0)))
            .unwrap();
        w.finish().unwrap();
    }
    fails_with(
        &[
            "run",
            &relax(),
            "--input",
            &format!("positions={}", complex.display()),
        ],
        &["complex.npy", "complex", "particles(nx3)"],
    );
    fails_with(
        &[
            "inspect",
            &relax(),
            "--input",
            &format!("positions={}", complex.display()),
        ],
        &["complex.npy", "complex"],
    );
}

#[test]
fn outputs_with_nan_or_infinity_from_finite_inputs_exit_3_and_are_written() {
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("cli-nonfinite");
    let graph = root().join("graphs/fixtures/divide_by_zero.json");
    let graph = graph.display().to_string();
    // x / 0: 0 / 0 is NaN (element 0), the rest infinite.
    let mut v = vec![1.5; 12];
    v[0] = 0.0;
    let x = positions(&dir, "x.npy", v, 4);
    let (ratio, doubled) = (dir.join("ratio.npy"), dir.join("doubled.npy"));
    let o = mesoflow(&[
        "run",
        &graph,
        "--input",
        &format!("x={x}"),
        "--output",
        &format!("ratio={}", ratio.display()),
        "--output",
        &format!("doubled={}", doubled.display()),
    ]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(3), "{t}");
    assert!(!t.contains("panicked"), "{t}");
    for needle in [
        "output `ratio` has 1 NaN and 11 infinite of 12 values, the first at index 0 (NaN)",
        "from finite inputs",
        "the outputs were written all the same",
    ] {
        assert!(t.contains(needle), "expected `{needle}` in:\n{t}");
    }
    assert!(!t.contains("output `doubled` has"), "{t}");
    let shape = mesoflow::graph::InputShape::Particles {
        rows: mesoflow::graph::Dim::Free,
        cols: 3,
    };
    // Written, as asked, for the user to look at (npy's reader refuses non-finite
    // values as input, so the file is read raw).
    let raw = std::fs::read(&ratio).unwrap();
    let words: Vec<f32> = raw[raw.len() - 48..]
        .chunks(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    assert!(
        words[0].is_nan() && words[1..].iter().all(|w| w.is_infinite()),
        "{words:?}"
    );
    let d = mesoflow::npy::read_input(&doubled, &shape).unwrap();
    assert_eq!(d.data.to_f64()[1], 3.0);
    assert!(temporaries(&dir).is_empty());
    // Without the division asked for, the run is clean.
    let o = mesoflow(&[
        "run",
        &graph,
        "--input",
        &format!("x={x}"),
        "--output",
        "doubled",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    // A summary only (no file) is judged the same way.
    let o = mesoflow(&[
        "run",
        &graph,
        "--input",
        &format!("x={x}"),
        "--output",
        "ratio",
    ]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(3), "{t}");
    assert!(
        t.contains("output `ratio` has") && t.contains("nothing was written"),
        "{t}"
    );
}

/// The new physics graphs from the command line: poisson.json writes its outputs from NPY
/// positions and (N, 1) charges; rpy_wall.json refuses a particle below the wall by row,
/// exit 2, writing nothing.
#[test]
fn poisson_and_wall_graphs_run_from_the_command_line() {
    let dir = crate::util::tmpdir("cli-physics");
    let x = positions(&dir, "x.npy", vec![0.0, 0.0, 0.0, 2.0, 0.5, 0.0], 2);
    let q = dir.join("q.npy");
    mesoflow::npy::write(
        &q,
        &HostArray::f32(ValueType::Particles { n: 2, k: 1 }, vec![1.0, -1.0]),
    )
    .unwrap();
    let energy = dir.join("energy.npy");
    let o = mesoflow(&[
        "run",
        &root().join("graphs/poisson.json").display().to_string(),
        "--set",
        "box=[16,16,16]",
        "--input",
        &format!("positions={x}"),
        "--input",
        &format!("charges={}", q.display()),
        "--output",
        &format!("energy={}", energy.display()),
        "--output",
        "forces",
    ]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(energy.is_file() && t.contains("forces"), "{t}");
    let f = positions(&dir, "f.npy", vec![0.0; 6], 2);
    let below = positions(&dir, "below.npy", vec![0.0, 0.0, 2.0, 1.0, 0.0, 0.5], 2);
    let u = dir.join("u.npy");
    fails_with(
        &[
            "run",
            &root().join("graphs/rpy_wall.json").display().to_string(),
            "--set",
            "wall_height=1",
            "--input",
            &format!("positions={below}"),
            "--input",
            &format!("forces={f}"),
            "--output",
            &format!("velocities={}", u.display()),
        ],
        &["row 1", "below the wall"],
    );
    assert!(
        !u.exists(),
        "no output is written when the input is refused"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// An NPY file's shape and f32 values (npyz).
fn read_f32_npy(path: &Path) -> (Vec<u64>, Vec<f32>) {
    let bytes = std::fs::read(path).unwrap();
    let npy = npyz::NpyFile::new(&bytes[..]).unwrap();
    let shape = npy.shape().to_vec();
    (shape, npy.into_vec::<f32>().unwrap())
}

/// `--every K` streams frames while the run goes on: an NPY of (frames, ...) whose last
/// frame is the one-shot run's result bit for bit (the chunks run the same steps and
/// draws), a GSD trajectory two outputs share (its structure: tests in src/gsd.rs and,
/// with the `gsd` package, python/tests/test_gsd.py), and clear errors for K = 0, for
/// --profile with it, and for an NPY file asked for by two outputs.
#[test]
fn every_k_steps_streams_frames_to_npy_and_gsd() {
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("cli-every");
    let vals: Vec<f32> = (0..12).map(|i| (i as f32 * 0.37).sin()).collect();
    let input = format!("positions={}", positions(&dir, "x.npy", vals, 4));
    let graph = relax();
    let file = |name: &str| dir.join(name).display().to_string();
    let run = |extra: &[&str]| {
        let mut args = vec!["run", graph.as_str(), "--input", &input, "--steps", "5"];
        args.extend(extra);
        let o = mesoflow(&args);
        assert!(o.status.success(), "{extra:?}: {}", text(&o));
        text(&o)
    };
    run(&["--output", &format!("positions={}", file("once.npy"))]);
    let t = run(&[
        "--every",
        "2",
        "--output",
        &format!("positions={}", file("frames.npy")),
    ]);
    assert!(t.contains("(3 frames)"), "{t}");
    let (shape, frames) = read_f32_npy(&dir.join("frames.npy"));
    let (_, once) = read_f32_npy(&dir.join("once.npy"));
    assert_eq!(shape, vec![3, 4, 3], "frames after steps 2, 4 and 5");
    assert_eq!(
        &frames[24..],
        &once[..],
        "the last frame is the one-shot result"
    );
    assert_ne!(&frames[..12], &once[..], "the first frame is earlier");
    run(&[
        "--every",
        "2",
        "--output",
        &format!("positions={}", file("t.gsd")),
        "--output",
        &format!("force={}", file("t.gsd")),
    ]);
    let gsd = std::fs::read(dir.join("t.gsd")).unwrap();
    assert_eq!(&gsd[0..8], &0x65DF_65DF_65DF_65DFu64.to_le_bytes());
    let names = String::from_utf8_lossy(&gsd);
    for chunk in ["particles/position", "log/particles/force", "log/time"] {
        assert!(names.contains(chunk), "no {chunk} in the GSD file");
    }
    fails_with(
        &["run", &graph, "--input", &input, "--every", "0"],
        &["--every must be at least 1"],
    );
    fails_with(
        &[
            "run",
            &graph,
            "--input",
            &input,
            "--every",
            "2",
            "--profile",
        ],
        &["profile a run without it"],
    );
    fails_with(
        &[
            "run",
            &graph,
            "--input",
            &input,
            "--every",
            "2",
            "--output",
            &format!("positions={}", file("two.npy")),
            "--output",
            &format!("force={}", file("two.npy")),
        ],
        &["also the file of --output positions"],
    );
    assert!(temporaries(&dir).is_empty(), "{:?}", temporaries(&dir));
    assert!(!dir.join("two.npy").exists());
}

/// `--checkpoint` then `--resume`: 4 steps, a checkpoint, 2 more steps from it give the
/// positions of 6 steps in one run bit for bit (Brownian noise included: the draws are
/// keyed by the restored step), frames streamed after a resume count on from its step;
/// a resume with another seed, or of a file that is not a checkpoint, is an error that
/// says so and writes nothing.
#[test]
fn a_run_resumed_from_its_checkpoint_goes_on_bit_for_bit() {
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("cli-resume");
    let vals: Vec<f32> = (0..30).map(|i| 3.0 * (i as f32 * 0.61).sin()).collect();
    let input = format!("positions={}", positions(&dir, "x.npy", vals, 10));
    let graph = root().join("graphs/bd_fcm.json").display().to_string();
    let file = |name: &str| dir.join(name).display().to_string();
    let run = |extra: &[&str]| {
        let mut args = vec![
            "run",
            graph.as_str(),
            "--set",
            "box=[8,8,8]",
            "--set",
            "temperature=1",
            "--input",
            &input,
        ];
        args.extend(extra);
        mesoflow(&args)
    };
    let ok = |o: Output| assert!(o.status.success(), "{}", text(&o));
    ok(run(&[
        "--steps",
        "6",
        "--output",
        &format!("positions={}", file("once.npy")),
    ]));
    // The same outputs as the runs that go on from it (the plan is what is checkpointed).
    ok(run(&[
        "--steps",
        "4",
        "--output",
        "positions",
        "--checkpoint",
        &file("ck.gsd"),
    ]));
    ok(run(&[
        "--steps",
        "2",
        "--resume",
        &file("ck.gsd"),
        "--output",
        &format!("positions={}", file("resumed.npy")),
    ]));
    let (_, once) = read_f32_npy(&dir.join("once.npy"));
    let (_, resumed) = read_f32_npy(&dir.join("resumed.npy"));
    assert_eq!(
        once, resumed,
        "the resumed run differs from the one-shot run"
    );
    // With frames the checkpoint is rewritten after each (steps 2 and 4 here): the last
    // one, replacing the first, goes on as well.
    ok(run(&[
        "--steps",
        "4",
        "--every",
        "2",
        "--output",
        &format!("positions={}", file("frames.npy")),
        "--checkpoint",
        &file("ck2.gsd"),
    ]));
    ok(run(&[
        "--steps",
        "2",
        "--resume",
        &file("ck2.gsd"),
        "--output",
        &format!("positions={}", file("resumed2.npy")),
    ]));
    let (_, resumed2) = read_f32_npy(&dir.join("resumed2.npy"));
    assert_eq!(
        once, resumed2,
        "resumed from the checkpoint written with frames"
    );
    ok(run(&[
        "--steps",
        "2",
        "--every",
        "1",
        "--resume",
        &file("ck.gsd"),
        "--output",
        &format!("positions={}", file("t.gsd")),
    ]));
    let t = mesoflow::gsd::GsdRead::open(&dir.join("t.gsd")).unwrap();
    let step = |frame| {
        let (_, _, b) = t.chunk(frame, "configuration/step").unwrap();
        u64::from_le_bytes(b.try_into().unwrap())
    };
    assert_eq!((step(0), step(1)), (5, 6));
    let other_seed = run(&[
        "--seed",
        "7",
        "--steps",
        "2",
        "--resume",
        &file("ck.gsd"),
        "--output",
        &format!("positions={}", file("no.npy")),
    ]);
    assert_eq!(other_seed.status.code(), Some(2), "{}", text(&other_seed));
    assert!(
        text(&other_seed).contains("`seed 0` there, `seed 7` here"),
        "{}",
        text(&other_seed)
    );
    let not_one = run(&["--steps", "2", "--resume", &file("once.npy")]);
    assert_eq!(not_one.status.code(), Some(2), "{}", text(&not_one));
    assert!(
        text(&not_one).contains("not a GSD file"),
        "{}",
        text(&not_one)
    );
    assert!(!dir.join("no.npy").exists());
    assert!(temporaries(&dir).is_empty(), "{:?}", temporaries(&dir));
}

#[test]
fn kernel_stats_builds_the_dumped_kernels_or_names_what_the_driver_lacks() {
    use mesoflow::gpu::driver_stats::{read_dump, spirv};
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("cli-kernel-stats");
    let dump = dir.join("kernels");
    let p = positions(&dir, "p.npy", vec![1.0, 2.0, 1.5, 3.0, 4.0, 2.5], 2);
    let f = positions(&dir, "f.npy", vec![1.0, 0.0, 0.0, 0.0, 0.0, 1.0], 2);
    let graph = root().join("graphs/dpstokes.json").display().to_string();
    // The lanes slab solve: subgroup operations in the SPIR-V below.
    let o = Command::new(env!("CARGO_BIN_EXE_mesoflow"))
        .args([
            "run",
            &graph,
            "--set",
            "box=[8,8]",
            "--set",
            "zmax=4",
            "--set",
            "slab=lanes",
        ])
        .args([
            "--input",
            &format!("positions={p}"),
            "--input",
            &format!("forces={f}"),
        ])
        .args(["--output", "velocities"])
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .env("MESOFLOW_KERNEL_DUMP", &dump)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let mut files: Vec<_> = std::fs::read_dir(&dump)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    assert!(files.len() >= 5, "{files:?}");
    // Each dump is the kernel as compiled and builds to SPIR-V as wgpu builds it.
    let mut labels = Vec::new();
    for file in &files {
        let k = read_dump(file).unwrap();
        let words = spirv(&k, (1, 3)).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        assert_eq!(words[0], 0x0723_0203, "{}: not SPIR-V", file.display());
        labels.push(k.label);
    }
    assert!(labels.iter().any(|l| l == "slab solve lanes"), "{labels:?}");
    let mut args = vec!["kernel-stats".to_string()];
    args.extend(files.iter().map(|f| f.display().to_string()));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = mesoflow(&args);
    let t = text(&o);
    assert!(!t.contains("panicked"), "{t}");
    match o.status.code() {
        // A driver with statistics: every kernel's, under its label.
        Some(0) => {
            assert!(t.contains("driver statistics on"), "{t}");
            for l in &labels {
                assert!(t.contains(&format!("{l} (")), "{l}: {t}");
            }
        }
        // One without (the lavapipe of Mesa 22.3 on CI): a clear error naming the device,
        // a failure to run (1), as `info` without an adapter.
        Some(1) => assert!(
            t.contains("does not report kernel statistics")
                && t.contains("VK_KHR_pipeline_executable_properties"),
            "{t}"
        ),
        other => panic!("exit {other:?}: {t}"),
    }
    // A file that is not a dump: exit 2 naming it, before any device opens.
    fails_with(
        &["kernel-stats", &relax()],
        &["relax.json", "not a MESOFLOW_KERNEL_DUMP file"],
    );
}
