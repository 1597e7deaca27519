//! The doubly periodic Stokes steps between the Chebyshev transforms (`slab_pressure_source`,
//! `slab_velocity_source`, `slab_walls`, `slab_curl`) against their f64 references on
//! random half spectra, even and odd sizes (unpaired Nyquist indices and none), every wall
//! mode; and the wall flow against the closed forms it must meet.

use mesoflow::value::{HostArray, ValueType};

use crate::util::{
    Rng, gpu, input_decl, load, named, reference, rel_max_err, run_graph, run_node_and_reference,
    run_out, tmpdir, write_graph,
};

fn spectrum(rng: &mut Rng, dims: [u32; 3], comps: u32) -> HostArray {
    rng.array(ValueType::HalfComplexGrid { dims, comps }, -1.0, 1.0)
}

#[test]
fn slab_nodes_match_their_references() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(77);
    for dims in [[8u32, 6, 9], [5, 7, 12]] {
        let box_ = r#""box": [7.0, 5.5]"#;
        let f = spectrum(&mut rng, dims, 3);
        let df = spectrum(&mut rng, dims, 3);
        let dfz = spectrum(&mut rng, dims, 1);
        let p = spectrum(&mut rng, dims, 1);
        let dp = spectrum(&mut rng, dims, 1);
        let (got, want) = run_out(
            "slab_pressure_source",
            &format!("{{{box_}}}"),
            &[("f", f.clone()), ("df", dfz)],
        );
        let (err, at) = rel_max_err(&got, &want);
        assert!(err <= 2e-6, "pressure source {dims:?}: {err:e} at {at}");

        let (mut got, want) = run_node_and_reference(
            "slab_velocity_source",
            &format!("{{{box_}, \"viscosity\": 0.7}}"),
            &[("f", f.clone()), ("p", p), ("dp", dp)],
        );
        for (port, want) in ["rhs", "boundary"].iter().zip(&want) {
            let (err, at) = rel_max_err(&got.remove(*port).unwrap(), want);
            assert!(
                err <= 2e-6,
                "velocity source {port} {dims:?}: {err:e} at {at}"
            );
        }

        for walls in ["none", "bottom", "slit"] {
            let (got, want) = run_out(
                "slab_walls",
                &format!("{{{box_}, \"zmin\": -1.5, \"zmax\": 2.0, \"walls\": \"{walls}\"}}"),
                &[("v", f.clone())],
            );
            let (err, at) = rel_max_err(&got, &want);
            assert!(err <= 5e-5, "walls {walls} {dims:?}: {err:e} at {at}");
        }

        let (got, want) = run_out(
            "slab_curl",
            &format!("{{{box_}, \"scale\": 0.5}}"),
            &[("x", f.clone()), ("dx", df.clone())],
        );
        let (err, at) = rel_max_err(&got, &want);
        assert!(err <= 2e-6, "curl {dims:?}: {err:e} at {at}");
    }
}

/// The wall flow cancels the velocity on the walls: after `slab_walls` the values at the
/// wall points are zero for every k (bottom: at zmin; slit: at both), the k = 0 mode
/// included, and v_z's k = 0 mode is zero.
#[test]
fn slab_walls_leave_no_velocity_on_the_walls() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(78);
    let dims = [8u32, 6, 17];
    let v = spectrum(&mut rng, dims, 3);
    let nk = (dims[0] / 2 + 1) as usize * dims[1] as usize;
    let nz = dims[2] as usize;
    for (walls, ends) in [("bottom", vec![nz - 1]), ("slit", vec![0, nz - 1])] {
        let (got, _) = run_out(
            "slab_walls",
            &format!(r#"{{"box": [6.0, 4.0], "zmin": 0.0, "zmax": 3.0, "walls": "{walls}"}}"#),
            &[("v", v.clone())],
        );
        let g = got.data.to_f64();
        for c in 0..3 {
            for &j in &ends {
                for k in 0..nk {
                    for part in 0..2 {
                        let x = g[2 * ((c * nz + j) * nk + k) + part];
                        assert!(
                            x.abs() < 1e-4,
                            "{walls}: component {c} at z index {j}, k {k}: {x}"
                        );
                    }
                }
            }
        }
    }
}

/// The chain slab_solve fuses, as graphs/lib/dpstokes_mobility.json runs it (the
/// forcing's coefficients `f` to the velocity's values with the walls), beside slab_solve's
/// kernels: `fused`, `staged` from f, `staged` from f's values along z (the inverse
/// transform of f, output `forcing_values`) and `lanes`; box [7, 5.5], eta 0.7, the domain [zmin, zmax].
fn chain_and_fused_graph(f: &HostArray, zmin: f64, zmax: f64, walls: &str) -> String {
    let node = |id: &str, kind: &str, p: &str, inputs: &str| {
        format!(r#"{{"id": "{id}", "kind": "{kind}", "params": {{{p}}}, "inputs": {{{inputs}}}}}"#)
    };
    let height = zmax - zmin;
    let b = r#""box": [7.0, 5.5]"#;
    let eta = r#""viscosity": 0.7"#;
    let domain = format!(r#""zmin": {zmin}, "zmax": {zmax}"#);
    let walls = format!(r#""walls": "{walls}""#);
    let nodes = [
        node(
            "fz",
            "chebyshev_derivative",
            &format!(r#""height": {height}, "first": 2, "count": 1"#),
            r#""x": "inputs.f""#,
        ),
        node(
            "ps",
            "slab_pressure_source",
            b,
            r#""f": "inputs.f", "df": "fz.out""#,
        ),
        node(
            "p",
            "chebyshev_bvp",
            &format!("{b}, {domain}"),
            r#""f": "ps.out""#,
        ),
        node(
            "pz",
            "chebyshev_derivative",
            &format!(r#""height": {height}"#),
            r#""x": "p.out""#,
        ),
        node(
            "vs",
            "slab_velocity_source",
            &format!("{b}, {eta}"),
            r#""f": "inputs.f", "p": "p.out", "dp": "pz.out""#,
        ),
        node(
            "v",
            "chebyshev_bvp",
            &format!("{b}, {domain}"),
            r#""f": "vs.rhs", "boundary": "vs.boundary""#,
        ),
        node(
            "values",
            "chebyshev",
            r#""direction": "inverse""#,
            r#""x": "v.out""#,
        ),
        node(
            "walls",
            "slab_walls",
            &format!("{b}, {domain}, {walls}"),
            r#""v": "values.out""#,
        ),
        node(
            "fused",
            "slab_solve",
            &format!("{b}, {eta}, {domain}, {walls}"),
            r#""f": "inputs.f""#,
        ),
        node(
            "staged",
            "slab_solve",
            &format!(r#"{b}, {eta}, {domain}, {walls}, "staged": true"#),
            r#""f": "inputs.f""#,
        ),
        node(
            "lanes",
            "slab_solve",
            &format!(r#"{b}, {eta}, {domain}, {walls}, "lanes": true"#),
            r#""f": "inputs.f""#,
        ),
        node(
            "forcing_values",
            "chebyshev",
            r#""direction": "inverse""#,
            r#""x": "inputs.f""#,
        ),
        node(
            "staged_values",
            "slab_solve",
            &format!(r#"{b}, {eta}, {domain}, {walls}, "staged": true, "values": true"#),
            r#""f": "forcing_values.out""#,
        ),
    ];
    format!(
        r#"{{"mesoflow": 1, "inputs": {{"f": {}}}, "nodes": [{}], "outputs": {{"chain": {{"from": "walls.out"}}, "fused": {{"from": "fused.out"}}, "staged": {{"from": "staged.out"}}, "lanes": {{"from": "lanes.out"}}, "staged_values": {{"from": "staged_values.out"}}, "forcing_values": {{"from": "forcing_values.out"}}}}}}"#,
        input_decl(&f.ty),
        nodes.join(", ")
    )
}

/// slab_solve, the fused solve between the transforms, gives the chain of nodes' result
/// (GPU against GPU) and its f64 reference (the chain's references) for every wall mode
/// and every kernel (`fused`; `staged`, also from the forcing's values along z, its
/// forward transform inside; `lanes`, whose segments pad the line to an even count a lane:
/// 3 points on 8 lanes of 2), on non-square grids of even sizes (unpaired Nyquist indices)
/// and odd ones, random spectra (the k = 0 and Nyquist modes among them), wave numbers that
/// leave the last workgroup part empty, an even number of points (the staged lines padded
/// to odd strides) and one long enough that a staged workgroup takes fewer wave numbers
/// (7).
#[test]
fn slab_solve_matches_the_chain_of_nodes() {
    let Some(gpu) = gpu() else { return };
    let mut rng = Rng::new(79);
    let dir = tmpdir("slab_solve_chain");
    let (zmin, zmax) = (-1.5, 2.0);
    // The fused kernel: three lines a thread up to 32 points (THREE_LINES_UP_TO), a thread
    // per line past them; at 70 points its transform is a loop over the matrix (past
    // WRITTEN_OUT_UP_TO). f32 rounding grows with n^2 past 40 points (the Chebyshev
    // derivative of the pressure scales as n^2): the tolerance with it.
    for dims in [
        [16u32, 12, 17],
        [9, 7, 12],
        [5, 4, 32],
        [6, 5, 40],
        [4, 3, 70],
        [3, 4, 3],
    ] {
        let tol = 2e-5 * (dims[2] as f64 / 40.0).powi(2).max(1.0);
        let f = spectrum(&mut rng, dims, 3);
        for walls in ["none", "bottom", "slit"] {
            let json = chain_and_fused_graph(&f, zmin, zmax, walls);
            let path = write_graph(&dir, &format!("{walls}-{}.json", dims[0]), &json);
            let g = load(&path);
            let out = run_graph(&gpu, &g, &named(&[("f", f.clone())]), None, 1, true);
            let chain = out["chain"].data.to_f64();
            let scale = chain.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            assert!(scale > 0.0);
            let params = format!(
                r#""box": [7.0, 5.5], "viscosity": 0.7, "zmin": {zmin}, "zmax": {zmax}, "walls": "{walls}""#
            );
            let want = reference("slab_solve", &format!("{{{params}}}"), &[Some(&f)]).remove(0);
            for kernel in ["fused", "staged", "staged_values", "lanes"] {
                let got = out[kernel].data.to_f64();
                let (mut worst, mut at) = (0.0f64, 0);
                for (i, (a, b)) in chain.iter().zip(&got).enumerate() {
                    let e = (a - b).abs() / scale;
                    if e > worst || e.is_nan() {
                        (worst, at) = (e, i);
                    }
                }
                assert!(
                    worst <= tol,
                    "slab_solve {kernel} {walls} {dims:?} against the chain: {worst:e} at {at}"
                );
                // And against its f64 reference (the chain's references composed).
                let (err, at) = rel_max_err(&out[kernel], &want);
                assert!(
                    err <= tol,
                    "slab_solve {kernel} {walls} {dims:?} against its reference: {err:e} at {at}"
                );
            }
            // The reference of the values' path: the forward transform of its input first.
            let values = &out["forcing_values"];
            let want_values = reference(
                "slab_solve",
                &format!(r#"{{{params}, "staged": true, "values": true}}"#),
                &[Some(values)],
            )
            .remove(0);
            let (err, at) = rel_max_err(&out["staged_values"], &want_values);
            assert!(
                err <= tol,
                "slab_solve staged from values {walls} {dims:?} against its reference: {err:e} at {at}"
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
