//! harmonic_bonds against its f64 reference: a chain and random extra bonds in a periodic
//! box (bonds across the faces), an open box, and a particle bonded to nothing.

use mesoflow::value::{HostArray, ValueType};

use crate::util::{Rng, gpu, rel_max_err, run_node_and_reference};

/// Each particle's partners (every bond at both ends) as offsets and partner indices.
fn bond_lists(n: u32, bonds: &[(u32, u32)]) -> (HostArray, HostArray) {
    let mut lists = vec![Vec::new(); n as usize];
    for &(a, b) in bonds {
        lists[a as usize].push(b);
        lists[b as usize].push(a);
    }
    let mut start = vec![0u32];
    let mut partner = Vec::new();
    for l in &lists {
        partner.extend(l);
        start.push(partner.len() as u32);
    }
    (
        HostArray::u32(ValueType::Indices { n: n + 1 }, start),
        HostArray::u32(
            ValueType::Indices {
                n: partner.len() as u32,
            },
            partner,
        ),
    )
}

#[test]
fn harmonic_bonds_match_their_reference() {
    if gpu().is_none() {
        return;
    }
    let n = 301u32;
    let mut rng = Rng::new(31);
    // Positions across a box of 6 (so chain neighbours meet across the faces).
    let x = rng.array(ValueType::Particles { n, k: 3 }, -3.0, 3.0);
    // A chain over the first 300 (the last particle has no bond) and 40 random links.
    let mut bonds: Vec<(u32, u32)> = (0..299).map(|i| (i, i + 1)).collect();
    let pick = rng.array(ValueType::Particles { n: 80, k: 1 }, 0.0, 299.99);
    let picks = crate::util::f32s(&pick);
    for p in picks.chunks_exact(2) {
        if p[0] as u32 != p[1] as u32 {
            bonds.push((p[0] as u32, p[1] as u32));
        }
    }
    let (start, partner) = bond_lists(n, &bonds);
    for params in [
        r#"{"stiffness": 40, "rest_length": 1.5, "box": [6, 6, 6]}"#,
        r#"{"stiffness": 2.5}"#,
    ] {
        let (out, refs) = run_node_and_reference(
            "harmonic_bonds",
            params,
            &[
                ("positions", x.clone()),
                ("start", start.clone()),
                ("partner", partner.clone()),
            ],
        );
        for (port, r) in ["forces", "energy"].iter().zip(&refs) {
            let (err, at) = rel_max_err(&out[*port], r);
            assert!(
                err < 2e-5,
                "{params} {port}: relative error {err:e} at {at}"
            );
        }
        let e = crate::util::f32s(&out["energy"]);
        assert_eq!(e[300], 0.0, "the unbonded particle");
        assert!(
            e[..300].iter().all(|&v| v > 0.0),
            "every bonded particle stretched"
        );
    }
}
