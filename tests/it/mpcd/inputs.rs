//! Given MPCD data checked on the host before it runs (`Node::check_input`): particles
//! outside the plates, far periodic images, non-finite values and velocities beyond the
//! cell sums' fixed point are refused by input, node, port and row, through the API and
//! the binary (exit 2, no output written); data in range runs.

use std::collections::BTreeMap;
use std::process::Command;

use mesoflow::value::HostArray;

use crate::util::mpcd::random_particles;
use crate::util::{
    Rng, compile_cached, gpu, load_with, named, particles, plan_graph, root, tmpdir,
    try_run_program, types_of,
};

/// A replaced coordinate: (of the velocities, row, axis, value).
type Edit = (bool, usize, usize, f64);

/// `--set` values, the coordinate replaced, and what the error must say.
type Case<'a> = (&'a [(&'a str, &'a str)], Edit, &'a [&'a str]);

/// 100 particles in a box of side 4 (velocities of order 1), and the same with one
/// coordinate of one row replaced.
fn state(edit: Option<Edit>) -> BTreeMap<String, HostArray> {
    let mut rng = Rng::new(5);
    let (mut x, mut v) = random_particles(&mut rng, 100, &[4.0, 4.0, 4.0]);
    if let Some((velocity, row, axis, value)) = edit {
        let rows = if velocity { &mut v } else { &mut x };
        rows[row][axis] = value;
    }
    named(&[("positions", particles(&x)), ("velocities", particles(&v))])
}

/// One step of graphs/`file` with these `--set` values and inputs through the API: the
/// error, or `None` when it ran.
fn run_error(
    file: &str,
    sets: &[(&str, &str)],
    inputs: &BTreeMap<String, HostArray>,
    output: &str,
) -> Option<String> {
    let gpu = gpu().expect("GPU");
    let g = load_with(file, sets, 1, 0);
    let plan = plan_graph(&gpu.caps, &g, types_of(inputs), Some(&[output]), true);
    let mut program = compile_cached(&gpu, &g, &plan);
    try_run_program(&mut program, inputs, 1, mesoflow::exec::Profile::Off).err()
}

#[test]
fn given_mpcd_particles_out_of_range_are_refused_by_input_node_port_and_row() {
    if gpu().is_none() {
        return;
    }
    let cube = ("box", "[4, 4, 4]");
    let plates = ("walls", "\"plates\"");
    // In range: runs, with plates and without.
    assert_eq!(
        run_error("mpcd.json", &[cube, plates], &state(None), "positions"),
        None
    );
    let cases: [Case; 5] = [
        (
            &[cube, plates],
            (false, 17, 2, 4.2),
            &[
                "input `positions`",
                "node `start` (mpcd_init), port `positions`",
                "row 17",
                "z = 4.2 is outside the plates [-2, 2]",
                "walls = plates",
            ],
        ),
        (
            &[cube, plates],
            (false, 3, 2, -2.001),
            &["row 3", "z = -2.001 is outside the plates"],
        ),
        (
            &[cube],
            (false, 20, 0, 1e6),
            &[
                "row 20",
                "x = 1000000",
                "1024 box lengths",
                "periodic box [-2, 2)",
            ],
        ),
        (
            &[cube],
            (true, 5, 1, f64::NAN),
            &["input `velocities`", "row 5", "v_y = NaN is not finite"],
        ),
        (
            &[cube],
            (true, 7, 2, -300.0),
            &[
                "row 7",
                "|v_z| = 300 is not below 128 v_th = 128",
                "fixed point",
            ],
        ),
    ];
    for (sets, edit, needles) in cases {
        let e = run_error("mpcd.json", sets, &state(Some(edit)), "positions")
            .unwrap_or_else(|| panic!("{sets:?} {edit:?} ran"));
        for n in needles {
            assert!(e.contains(n), "{sets:?} {edit:?}: expected `{n}` in: {e}");
        }
    }
}

#[test]
fn a_solute_outside_the_plates_is_refused_by_the_node_that_streams_it() {
    if gpu().is_none() {
        return;
    }
    // The solute's positions reach `stream_solute` as the initial value of state `xs`.
    let mut rng = Rng::new(6);
    let (mut xs, vs) = random_particles(&mut rng, 20, &[4.0, 4.0, 4.0]);
    xs[11][2] = 2.5;
    let inputs = named(&[
        ("solute_positions", particles(&xs)),
        ("solute_velocities", particles(&vs)),
    ]);
    let e = run_error(
        "mpcd_solute.json",
        &[("box", "[4, 4, 4]"), ("walls", "\"plates\"")],
        &inputs,
        "solute_positions",
    )
    .expect("a solute outside the plates ran");
    for n in [
        "input `solute_positions`",
        "node `stream_solute` (mpcd_stream), port `positions`",
        "row 11",
        "z = 2.5 is outside the plates [-2, 2]",
    ] {
        assert!(e.contains(n), "expected `{n}` in: {e}");
    }
}

#[test]
fn the_binary_refuses_a_particle_outside_the_plates_with_exit_2_and_writes_nothing() {
    if gpu().is_none() {
        return;
    }
    let dir = tmpdir("mpcd-inputs");
    let given = state(Some((false, 17, 2, 4.2)));
    let file = |name: &str| {
        let p = dir.join(format!("{name}.npy"));
        mesoflow::npy::write(&p, &given[name]).unwrap();
        format!("{name}={}", p.display())
    };
    let out = dir.join("out.npy");
    let o = Command::new(env!("CARGO_BIN_EXE_mesoflow"))
        .arg("run")
        .arg(root().join("graphs/mpcd.json"))
        .args(["--set", "box=[4,4,4]", "--set", "walls=plates"])
        .args([
            "--input",
            &file("positions"),
            "--input",
            &file("velocities"),
        ])
        .args(["--output", &format!("positions={}", out.display())])
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .expect("run mesoflow");
    let text = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{text}");
    assert!(
        text.contains("input `positions`")
            && text.contains("row 17: z = 4.2 is outside the plates [-2, 2]"),
        "{text}"
    );
    assert!(!out.exists(), "an output was written");
    let _ = std::fs::remove_dir_all(&dir);
}
