//! The `poisson` spectral node (1 component in, 1, 3 or 4 out): against its f64
//! reference, and rfft -> poisson -> irfft against the closed-form potential and field
//! of a smooth periodic charge density.

use std::collections::BTreeMap;
use std::f64::consts::PI;

use mesoflow::plan::{Launch, TransformFold};
use mesoflow::value::{HostArray, ValueType};

use crate::util::{
    Rng, assert_like_reference, gpu, input_decl, load, run_cached, tmpdir, validation_error,
    write_graph,
};

#[test]
fn poisson_matches_its_reference_for_every_output() {
    // assert_like_reference takes the GPU itself.
    if gpu().is_none() {
        return;
    }
    let dims = [12, 10, 8];
    for ty in [
        ValueType::HalfComplexGrid { dims, comps: 1 },
        ValueType::ComplexGrid { dims, comps: 1 },
    ] {
        let x = Rng::new(7).array(ty, -1.0, 1.0);
        for outputs in ["potential", "field", "both"] {
            for screening in [0.0, 0.15] {
                let params = format!(
                    r#"{{"box": [2.0, 1.5, 1.0], "permittivity": 0.8, "screening": {screening}, "outputs": "{outputs}"}}"#
                );
                assert_like_reference(
                    "poisson",
                    &params,
                    &[("x", x.clone())],
                    2e-6,
                    &format!("poisson {ty} {outputs} screening {screening}"),
                );
            }
        }
    }
}

#[test]
fn poisson_solves_for_a_smooth_periodic_density() {
    let Some(gpu) = gpu() else { return };
    let dims = [12u32, 10, 8];
    let lengths = [2.0f64, 1.5, 1.0];
    let (eps, s) = (0.8, 0.1);
    let ty = ValueType::RealGrid { dims, comps: 1 };
    let json = format!(
        r#"{{"mesoflow": 1, "inputs": {{"rho": {}}},
          "nodes": [
            {{"id": "f", "kind": "rfft", "inputs": {{"x": "inputs.rho"}}}},
            {{"id": "g", "kind": "poisson", "params": {{"box": [{}, {}, {}], "permittivity": {eps}, "screening": {s}, "outputs": "both"}}, "inputs": {{"x": "f.out"}}}},
            {{"id": "i", "kind": "irfft", "inputs": {{"x": "g.out"}}}}
          ],
          "outputs": {{"y": "i.out"}}}}"#,
        input_decl(&ty),
        lengths[0],
        lengths[1],
        lengths[2]
    );
    let g = load(&write_graph(&tmpdir("poisson"), "poisson.json", &json));
    let cells = (dims[0] * dims[1] * dims[2]) as usize;
    // rho = cos(kx x) + 0.5 sin(ky y), kx = 2 pi / Lx, ky = 4 pi / Ly, at x_i = i Lx / nx.
    let (kx, ky) = (2.0 * PI / lengths[0], 4.0 * PI / lengths[1]);
    let at = |cell: usize| {
        let (ix, iy) = (
            cell % dims[0] as usize,
            (cell / dims[0] as usize) % dims[1] as usize,
        );
        (
            ix as f64 * lengths[0] / dims[0] as f64,
            iy as f64 * lengths[1] / dims[1] as f64,
        )
    };
    let rho: Vec<f64> = (0..cells)
        .map(|c| {
            let (x, y) = at(c);
            (kx * x).cos() + 0.5 * (ky * y).sin()
        })
        .collect();
    let data: BTreeMap<String, HostArray> = [(
        "rho".to_string(),
        HostArray::f32(ty, rho.iter().map(|&r| r as f32).collect()),
    )]
    .into_iter()
    .collect();
    let (out, plan) = run_cached(&gpu, &g, &data, None, 1, true);
    // 1 component in, 4 out: the node runs alone, not folded into the rfft.
    assert!(
        plan.step.iter().all(|l| !matches!(
            l,
            Launch::Transform {
                fold: TransformFold::Hosts(_),
                ..
            }
        )),
        "poisson must not be folded"
    );
    // phi = exp(-s^2 k^2 / 2) rho_k / (eps k^2) per mode, E = -grad phi.
    let (gx, gy) = (
        (-0.5 * s * s * kx * kx).exp() / (eps * kx * kx),
        0.5 * (-0.5 * s * s * ky * ky).exp() / (eps * ky * ky),
    );
    let want: Vec<[f64; 4]> = (0..cells)
        .map(|c| {
            let (x, y) = at(c);
            [
                gx * (kx * x).cos() + gy * (ky * y).sin(),
                gx * kx * (kx * x).sin(),
                -gy * ky * (ky * y).cos(),
                0.0,
            ]
        })
        .collect();
    let y = out["y"].data.to_f64();
    assert_eq!(y.len(), 4 * cells);
    let names = ["phi", "Ex", "Ey", "Ez"];
    let scale = [gx + gy, gx * kx, gy * ky, gx * kx];
    for comp in 0..4 {
        let err = (0..cells)
            .map(|c| (y[comp * cells + c] - want[c][comp]).abs())
            .fold(0.0, f64::max);
        assert!(
            err <= 1e-5 * scale[comp],
            "{}: max error {err:e} against a scale of {:e}",
            names[comp],
            scale[comp]
        );
    }
}

#[test]
fn poisson_refuses_what_it_cannot_solve() {
    let three = ValueType::HalfComplexGrid {
        dims: [8, 6, 4],
        comps: 3,
    };
    let e = validation_error("poisson", r#"{"permittivity": 1.0}"#, &[("x", three)]);
    assert!(e.contains("poisson needs 1 components"), "{e}");
    let one = ValueType::HalfComplexGrid {
        dims: [8, 6, 4],
        comps: 1,
    };
    let e = validation_error(
        "poisson",
        r#"{"permittivity": 1e-17, "box": [1e9, 1.0, 1.0]}"#,
        &[("x", one)],
    );
    assert!(e.contains("`box`^2 / (4 pi^2 `permittivity`)"), "{e}");
    let e = validation_error(
        "poisson",
        r#"{"permittivity": 1.0, "outputs": "gradient"}"#,
        &[("x", one)],
    );
    assert!(e.contains("outputs"), "{e}");
}
