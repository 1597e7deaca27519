//! What spreading and interpolation must keep: conservation, adjointness, periodic
//! images, empty input, every particle served once under folded dispatches; bad params.

use std::collections::BTreeMap;

use mesoflow::value::{HostArray, ValueType};

use crate::util::spread::{WINDOWS, params, positions};
use crate::util::{
    Rng, gpu, reference, rel_max_err, run_node, run_out, validation_error, with_caps,
};

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

#[test]
fn spreading_conserves_and_interpolation_is_its_adjoint() {
    if gpu().is_none() {
        return;
    }
    let mut rng = Rng::new(23);
    let lengths = [12.0, 9.0, 15.0];
    let cells = [24u32, 18, 30];
    let dv: f64 = (0..3).map(|a| lengths[a] / cells[a] as f64).product();
    let n = 400;
    let pos = positions(&mut rng, n, &lengths);
    let f = rng.array(ValueType::Particles { n, k: 2 }, -1.0, 1.0);
    let g = rng.array(
        ValueType::RealGrid {
            dims: [24, 18, 30],
            comps: 2,
        },
        -1.0,
        1.0,
    );
    for (w, extra) in WINDOWS {
        let p = params(w, extra, &lengths, &cells, "auto");
        let (sf, _) = run_out(
            "spread",
            &p,
            &[("positions", pos.clone()), ("values", f.clone())],
        );
        let (jg, _) = run_out(
            "interpolate",
            &p,
            &[("grid", g.clone()), ("positions", pos.clone())],
        );
        let (sf, jg, fv, gv) = (
            sf.data.to_f64(),
            jg.data.to_f64(),
            f.data.to_f64(),
            g.data.to_f64(),
        );
        // <S f, g>_dV = <f, J g>: the same weights on both sides, so f32 rounding only.
        let lhs = dv * dot(&sf, &gv);
        let rhs = dot(&fv, &jg);
        let scale = dv * sf.iter().zip(&gv).map(|(x, y)| (x * y).abs()).sum::<f64>();
        assert!(
            (lhs - rhs).abs() < 1e-5 * scale,
            "{w}: <Sf,g> = {lhs}, <f,Jg> = {rhs}"
        );
        // Conservation per component: sum_j (S f)_j dV = sum_i f_i. Peskin windows have
        // unit discrete mass exactly; the Gaussian and ES windows to their tolerance.
        let cells_n = sf.len() / 2;
        for c in 0..2 {
            let grid_total: f64 = sf[c * cells_n..(c + 1) * cells_n].iter().sum::<f64>() * dv;
            let particle_total: f64 = fv.iter().skip(c).step_by(2).sum();
            let abs_total: f64 = fv.iter().skip(c).step_by(2).map(|x| x.abs()).sum();
            let tol = if w.starts_with("peskin") { 1e-6 } else { 2e-4 };
            assert!(
                (grid_total - particle_total).abs() < tol * abs_total,
                "{w} component {c}: grid {grid_total} vs particles {particle_total}"
            );
        }
    }
}

#[test]
fn unwrapped_positions_wrap_like_their_images() {
    if gpu().is_none() {
        return;
    }
    let lengths = [10.0, 10.0, 10.0];
    let cells = [20u32, 20, 20];
    let base = [1.3f32, -2.2, 4.9];
    let shifted: Vec<f32> = base
        .iter()
        .zip([3.0f32, -2.0, 7.0])
        .map(|(x, k)| x + k * 10.0)
        .collect();
    let vals = HostArray::f32(ValueType::Particles { n: 1, k: 1 }, vec![1.0]);
    let p = params("peskin6", "", &lengths, &cells, "auto");
    let (a, _) = run_out(
        "spread",
        &p,
        &[
            (
                "positions",
                HostArray::f32(ValueType::Particles { n: 1, k: 3 }, base.to_vec()),
            ),
            ("values", vals.clone()),
        ],
    );
    let (b, _) = run_out(
        "spread",
        &p,
        &[
            (
                "positions",
                HostArray::f32(ValueType::Particles { n: 1, k: 3 }, shifted),
            ),
            ("values", vals),
        ],
    );
    let (diff, at) = rel_max_err(&a, &mesoflow::value::RefArray::new(b.ty, b.data.to_f64()));
    assert!(diff < 1e-5, "images differ by {diff:e} at {at}");
}

#[test]
fn no_particles_give_an_empty_grid_and_no_values() {
    if gpu().is_none() {
        return;
    }
    let lengths = [4.0, 4.0, 4.0];
    let cells = [8u32, 8, 8];
    let p = params("peskin4", "", &lengths, &cells, "auto");
    let pos = HostArray::f32(ValueType::Particles { n: 0, k: 3 }, vec![]);
    let vals = HostArray::f32(ValueType::Particles { n: 0, k: 1 }, vec![]);
    let (g, _) = run_out(
        "spread",
        &p,
        &[("positions", pos.clone()), ("values", vals)],
    );
    assert!(g.data.to_f64().iter().all(|&x| x == 0.0));
    let field = HostArray::f32(
        ValueType::RealGrid {
            dims: [8, 8, 8],
            comps: 1,
        },
        vec![1.0; 512],
    );
    let (u, _) = run_out("interpolate", &p, &[("grid", field), ("positions", pos)]);
    assert!(u.data.is_empty());
}

#[test]
fn bad_spread_params_are_plan_errors() {
    let pos = ValueType::Particles { n: 4, k: 3 };
    for (params, inputs, want) in [
        (
            r#"{"box": [4, 4, 4], "grid": [8, 8, 8], "window": "gaussian"}"#,
            [("positions", pos), ("values", pos)],
            "needs `width`",
        ),
        (
            r#"{"box": [4, 4], "grid": [8, 8], "window": "peskin4"}"#,
            [("positions", pos), ("values", pos)],
            "has 3 columns but the box has 2 axes",
        ),
        (
            r#"{"box": [4, 4, 4], "grid": [8, 8, 8], "window": "gaussian", "width": 2, "tolerance": 1e-14}"#,
            [("positions", pos), ("values", pos)],
            "more than the 32 supported",
        ),
    ] {
        let e = validation_error("spread", params, &inputs);
        assert!(e.contains(want), "{params}: {e}");
    }
}

#[test]
fn folded_dispatches_serve_every_particle_once() {
    // More workgroups than one dispatch dimension holds fold over (x, y); the grid then
    // rounds up past the particle slots, and those extra slots must stay empty. A small
    // dimension cap makes a small problem take that path.
    let Some(mut gpu) = gpu() else { return };
    let mut rng = Rng::new(12);
    let lengths = [8.0, 8.0, 8.0];
    let cells = [16u32, 16, 16];
    // 54 particles: 13 runs of 5 slots, 65 slots, which 3-wide rows round up to 66.
    let pos = positions(&mut rng, 54, &lengths);
    let vals = rng.array(ValueType::Particles { n: 54, k: 1 }, 0.5, 1.5);
    let field = rng.array(
        ValueType::RealGrid {
            dims: [16, 16, 16],
            comps: 1,
        },
        -1.0,
        1.0,
    );
    let data_s: BTreeMap<String, HostArray> = [
        ("positions".into(), pos.clone()),
        ("values".into(), vals.clone()),
    ]
    .into_iter()
    .collect();
    let data_i: BTreeMap<String, HostArray> = [
        ("grid".into(), field.clone()),
        ("positions".into(), pos.clone()),
    ]
    .into_iter()
    .collect();
    for (w, extra) in [("peskin6", ""), ("peskin3", "")] {
        let p = params(w, extra, &lengths, &cells, "auto");
        let (s, i) = with_caps(
            &mut gpu,
            |c| c.max_workgroups_per_dim = 3,
            |g| {
                (
                    run_node(g, "spread", &p, &data_s),
                    run_node(g, "interpolate", &p, &data_i),
                )
            },
        );
        let rs = reference("spread", &p, &[Some(&pos), Some(&vals)]).remove(0);
        let ri = reference("interpolate", &p, &[Some(&field), Some(&pos), None]).remove(0);
        assert!(
            rel_max_err(&s["out"], &rs).0 < 1e-5,
            "{w}: spread with folded dispatch"
        );
        assert!(
            rel_max_err(&i["out"], &ri).0 < 1e-5,
            "{w}: interpolate with folded dispatch"
        );
    }
}
