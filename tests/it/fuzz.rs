//! Seeded fuzzing of what other people hand mesoflow (issue 19): mutated copies of the
//! shipped graph files (values, keys, structure, text), hostile `--set` values, and
//! mutated NPY headers. Every case must end, within a time bound, in a plan or an
//! error: never a panic, never a hang. A fixed number of cases and a fixed seed, so CI
//! runs the same cases each time (a few seconds of the 60 s budget on 2 cores).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use serde_json::Value;

use mesoflow::expr::ParamValue;
use mesoflow::graph::{self, InputShape, LoadOptions};
use mesoflow::value::{HostArray, ValueType};

use crate::util::{registry, root, tmpdir};

/// Graph-file cases and NPY cases per run.
const GRAPH_CASES: usize = 240;
const NPY_CASES: usize = 600;
/// What one case may take before it counts as a hang (debug build, loaded machine).
const CASE_TIME: Duration = Duration::from_secs(20);

/// Numbers that have broken planners: huge, tiny, negative, zero, past u32.
const HOSTILE_NUMBERS: &[f64] = &[
    1e30,
    -1.0,
    0.0,
    5e-324,
    1e308,
    -1e308,
    4294967295.0,
    4294967296.0,
    1e6,
    0.5,
    3.0,
    1e-300,
    65536.0,
    2147483648.0,
];

fn hostile_number(rng: &mut StdRng) -> f64 {
    HOSTILE_NUMBERS[rng.random_range(0..HOSTILE_NUMBERS.len())]
}

fn hostile_string(rng: &mut StdRng) -> String {
    let deep = rng.random_range(1..3000);
    match rng.random_range(0..9) {
        0 => format!("= {}1{}", "(".repeat(deep), ")".repeat(deep)),
        1 => format!("= {}1", "-".repeat(deep)),
        2 => "$no_such_param".into(),
        3 => "= 1/0".into(),
        4 => "= sqrt(-1)".into(),
        5 => format!("= [{}]", vec!["1e30"; deep.min(64)].join(", ")),
        6 => "= fcm_grid([1e30, 1e30, 1e30], 5e-324, 0, 'es')".into(),
        7 => "/dev/zero".into(),
        _ => "nope.out".into(),
    }
}

/// Every leaf (number, string) and every object key path of a JSON value.
fn paths(v: &Value, at: &mut Vec<PathStep>, out: &mut Vec<Vec<PathStep>>) {
    out.push(at.clone());
    match v {
        Value::Object(m) => {
            for (k, c) in m {
                at.push(PathStep::Key(k.clone()));
                paths(c, at, out);
                at.pop();
            }
        }
        Value::Array(a) => {
            for (i, c) in a.iter().enumerate() {
                at.push(PathStep::Index(i));
                paths(c, at, out);
                at.pop();
            }
        }
        _ => {}
    }
}

#[derive(Clone, Debug)]
enum PathStep {
    Key(String),
    Index(usize),
}

fn at_path<'a>(v: &'a mut Value, path: &[PathStep]) -> &'a mut Value {
    path.iter().fold(v, |v, s| match s {
        PathStep::Key(k) => &mut v[k.as_str()],
        PathStep::Index(i) => &mut v[*i],
    })
}

/// One structural mutation of a graph file's JSON.
fn mutate_json(rng: &mut StdRng, v: &mut Value) {
    let mut all = Vec::new();
    paths(v, &mut Vec::new(), &mut all);
    let path = all[rng.random_range(0..all.len())].clone();
    let target = at_path(v, &path);
    *target = match (rng.random_range(0..10), &*target) {
        (0..=3, Value::Number(_)) => serde_json::json!(hostile_number(rng)),
        (0..=3, Value::String(_)) => Value::String(hostile_string(rng)),
        (0..=3, Value::Array(a)) if !a.is_empty() => {
            let n = hostile_number(rng);
            Value::Array(a.iter().map(|_| serde_json::json!(n)).collect())
        }
        (4, Value::Object(m)) if !m.is_empty() => {
            let mut m = m.clone();
            let k = m
                .keys()
                .nth(rng.random_range(0..m.len()))
                .cloned()
                .expect("a key");
            m.remove(&k);
            Value::Object(m)
        }
        (5, Value::Array(a)) if !a.is_empty() => {
            let mut a = a.clone();
            let i = rng.random_range(0..a.len());
            a.push(a[i].clone()); // a duplicate node, input or element
            Value::Array(a)
        }
        (6, _) => Value::Null,
        (7, _) => serde_json::json!([]),
        (8, _) => serde_json::json!({}),
        _ => serde_json::json!(hostile_number(rng)),
    };
}

/// A mutated text of a graph file: JSON mutations, or cuts and byte flips of the text.
fn mutate_graph_text(rng: &mut StdRng, text: &str) -> String {
    if rng.random_bool(0.15) {
        let mut bytes = text.as_bytes().to_vec();
        for _ in 0..rng.random_range(1..4) {
            let i = rng.random_range(0..bytes.len());
            bytes[i] = b"{}[],:\"0-e9$=x"[rng.random_range(0..14)];
        }
        if rng.random_bool(0.3) {
            bytes.truncate(rng.random_range(0..bytes.len()));
        }
        return String::from_utf8_lossy(&bytes).into_owned();
    }
    let mut v: Value = serde_json::from_str(text).expect("shipped graphs are JSON");
    for _ in 0..rng.random_range(1..4) {
        mutate_json(rng, &mut v);
    }
    v.to_string()
}

fn graph_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            graph_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "json") {
            out.push(p);
        }
    }
}

fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap().flatten() {
        let p = e.path();
        let dest = to.join(e.file_name());
        if p.is_dir() {
            copy_tree(&p, &dest);
        } else {
            std::fs::copy(&p, &dest).unwrap();
        }
    }
}

/// Runs `work` on a thread of its own: its result, or why it gave none (a panic's
/// message, or a hang past CASE_TIME; the hung thread is left behind, the test fails).
fn bounded<T: Send + 'static>(work: impl FnOnce() -> T + Send + 'static) -> Result<T, String> {
    let (tx, rx) = mpsc::channel();
    std::thread::Builder::new()
        .stack_size(8 << 20)
        .spawn(move || {
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(work));
            let _ = tx.send(r);
        })
        .expect("a thread");
    match rx.recv_timeout(CASE_TIME) {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(p)) => Err(format!(
            "panicked: {}",
            p.downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default()
        )),
        Err(_) => Err(format!("took longer than {CASE_TIME:?}")),
    }
}

/// The params a graph file declares, to aim `--set` values at.
fn param_names(text: &str) -> Vec<String> {
    serde_json::from_str::<Value>(text)
        .ok()
        .and_then(|v| {
            v.get("params")
                .and_then(|p| p.as_object())
                .map(|m| m.keys().cloned().collect())
        })
        .unwrap_or_default()
}

#[test]
fn mutated_graph_files_and_sets_never_panic_or_hang() {
    let shipped = root().join("graphs");
    let dir = tmpdir("fuzz-graphs");
    copy_tree(&shipped, &dir);
    let mut files = Vec::new();
    graph_files(&dir, &mut files);
    let mut rng = StdRng::seed_from_u64(19);
    let (mut planned, mut refused) = (0, 0);
    let mut findings = Vec::new();
    for case in 0..GRAPH_CASES {
        let file = files[rng.random_range(0..files.len())].clone();
        let original = std::fs::read_to_string(&file).unwrap();
        let with_sets = rng.random_bool(0.3);
        let mut overrides = BTreeMap::new();
        let what = if with_sets {
            let names = param_names(&original);
            if names.is_empty() {
                continue;
            }
            let name = names[rng.random_range(0..names.len())].clone();
            let value = if rng.random_bool(0.7) {
                ParamValue::Number(hostile_number(&mut rng))
            } else {
                ParamValue::Numbers(vec![hostile_number(&mut rng); 3])
            };
            let what = format!("--set {name}={value}");
            overrides.insert(name, value);
            what
        } else {
            let mutated = mutate_graph_text(&mut rng, &original);
            std::fs::write(&file, &mutated).unwrap();
            format!(
                "mutated text {}",
                mutated.chars().take(300).collect::<String>()
            )
        };
        let path = file.clone();
        let result = bounded(move || {
            if overrides.is_empty() {
                mesoflow::plan::validate_file(registry(), &path)
                    .map(|_| ())
                    .map_err(|e| e.to_string())
            } else {
                let opts = LoadOptions {
                    overrides,
                    ..Default::default()
                };
                graph::load(&path, registry(), &opts)
                    .map(|_| ())
                    .map_err(|e| e.to_string())
            }
        });
        std::fs::write(&file, &original).unwrap();
        match result {
            Ok(Ok(())) => planned += 1,
            Ok(Err(e)) => {
                assert!(!e.trim().is_empty(), "case {case}: an empty error");
                refused += 1;
            }
            Err(why) => findings.push(format!(
                "case {case}, {}: {what}: {why}",
                file.strip_prefix(&dir).unwrap().display()
            )),
        }
    }
    eprintln!(
        "fuzz: {GRAPH_CASES} graph cases: {planned} planned, {refused} refused with an error"
    );
    assert!(findings.is_empty(), "{}", findings.join("\n"));
    assert!(
        refused > GRAPH_CASES / 4,
        "most mutations should be refused: {refused}"
    );
}

/// An NPY file's bytes with its header text (the dict after the preamble) mutated.
fn mutate_npy(rng: &mut StdRng, bytes: &[u8]) -> Vec<u8> {
    let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let header = String::from_utf8_lossy(&bytes[10..10 + header_len]).into_owned();
    let data = &bytes[10 + header_len..];
    let shape = [
        "(1099511627776, 3)",
        "(4294967296,)",
        "(-1, 3)",
        "(0, 3)",
        "(3, 4294967295)",
        "()",
        "(2, 3, 4, 5)",
        "(18446744073709551615,)",
        "(65536, 65536)",
        "(abc)",
    ];
    let dtype = [
        "'<f4'",
        "'>f4'",
        "'<f8'",
        "'<i8'",
        "'<u8'",
        "'|b1'",
        "'<f2'",
        "'<c8'",
        "'O'",
        "'<U4'",
        "[('a', '<f4')]",
    ];
    let mut h = header.clone();
    match rng.random_range(0..5) {
        0 => {
            let s = shape[rng.random_range(0..shape.len())];
            let start = h.find("'shape': ").map(|i| i + 9).unwrap_or(0);
            let end = h[start..].find(')').map(|i| start + i + 1).unwrap_or(start);
            h.replace_range(start..end, s);
        }
        1 => {
            let d = dtype[rng.random_range(0..dtype.len())];
            let start = h.find("'descr': ").map(|i| i + 9).unwrap_or(0);
            let end = h[start..].find(',').map(|i| start + i).unwrap_or(start);
            h.replace_range(start..end, d);
        }
        2 => h = h.replace("False", "True"),
        3 => {
            let i = rng.random_range(0..h.len());
            h.truncate(i);
        }
        _ => {
            let mut b = h.into_bytes();
            let i = rng.random_range(0..b.len());
            b[i] = b"(){}',:0-9x"[rng.random_range(0..11)];
            h = String::from_utf8_lossy(&b).into_owned();
        }
    }
    // Keep the header padded as NPY wants (to 64 bytes), or not at all.
    let mut out = bytes[..8].to_vec();
    let mut h = h.into_bytes();
    if rng.random_bool(0.8) {
        while !(10 + h.len() + 1).is_multiple_of(64) {
            h.push(b' ');
        }
        h.push(b'\n');
    }
    out.extend_from_slice(&(h.len() as u16).to_le_bytes());
    out.extend_from_slice(&h);
    let keep = if rng.random_bool(0.2) {
        rng.random_range(0..=data.len())
    } else {
        data.len()
    };
    out.extend_from_slice(&data[..keep]);
    out
}

#[test]
fn mutated_npy_headers_never_panic() {
    let dir = tmpdir("fuzz-npy");
    let mut rng = StdRng::seed_from_u64(190);
    let particles = HostArray::f32(
        ValueType::Particles { n: 4, k: 3 },
        (0..12).map(|i| i as f32 * 0.5).collect(),
    );
    let index = HostArray::u32(ValueType::Indices { n: 5 }, vec![0, 1, 2, 3, 4]);
    let mut originals = Vec::new();
    for (name, a) in [("p.npy", &particles), ("i.npy", &index)] {
        let p = dir.join(name);
        mesoflow::npy::write(&p, a).unwrap();
        originals.push(std::fs::read(&p).unwrap());
    }
    let decls = [
        InputShape::Particles {
            rows: mesoflow::graph::Dim::Free,
            cols: 3,
        },
        InputShape::Indices {
            rows: mesoflow::graph::Dim::Free,
        },
    ];
    let (mut read, mut refused) = (0, 0);
    let mut findings = Vec::new();
    for case in 0..NPY_CASES {
        let which = rng.random_range(0..2);
        let bytes = mutate_npy(&mut rng, &originals[which]);
        let path = dir.join(format!("case{case}.npy"));
        std::fs::write(&path, &bytes).unwrap();
        let decl = decls[rng.random_range(0..2)].clone();
        let p = path.clone();
        match bounded(move || mesoflow::npy::read_input(&p, &decl).map(|_| ())) {
            Ok(Ok(())) => read += 1,
            Ok(Err(e)) => {
                assert!(!e.to_string().is_empty());
                refused += 1;
            }
            Err(why) => findings.push(format!(
                "case {case}: header {:?}: {why}",
                String::from_utf8_lossy(&bytes[10..bytes.len().min(138)])
            )),
        }
        let _ = std::fs::remove_file(&path);
    }
    eprintln!("fuzz: {NPY_CASES} NPY cases: {read} read, {refused} refused with an error");
    assert!(findings.is_empty(), "{}", findings.join("\n"));
    assert!(
        refused > NPY_CASES / 4,
        "most mutations should be refused: {refused}"
    );
}
