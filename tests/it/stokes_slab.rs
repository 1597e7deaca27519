//! The doubly periodic Stokes steps between the Chebyshev transforms (`slab_pressure_source`,
//! `slab_velocity_source`, `slab_walls`, `slab_curl`) against their f64 references on
//! random half spectra, even and odd sizes (unpaired Nyquist indices and none), every wall
//! mode; and the wall flow against the closed forms it must meet.

use mesoflow::value::{HostArray, ValueType};

use crate::util::{Rng, gpu, rel_max_err, run_node_and_reference, run_out};

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
