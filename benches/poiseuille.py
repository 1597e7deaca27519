"""MPCD-BC Poiseuille flow between plates against S2 §4.4 (digest part D, V10), for
benches/gpu.sh suite poiseuille: the mean velocity from `mesoflow run graphs/mpcd.json`'s
`momentum` (mean total momentum / N m), the viscosity from the curvature of
`velocity_profile`, the slip at the plates and the temperature.

  python3 benches/poiseuille.py DIR WANT FORCE N

DIR holds momentum.npy, profile.npy and temperature.npy; WANT is the source's mean
velocity; FORCE the body force per unit mass; N the solvent particle count (mass 1).
"""

import sys

import numpy as np


def parabola_fit(u, h):
    """u(z) = c0 + c2 z^2 over slabs centred on z in (-h/2, h/2): (c0, c2)."""
    nb = len(u)
    z = (np.arange(nb) + 0.5) / nb * h - h / 2
    c2, c0 = np.polyfit(z * z, u, 1)
    return c0, c2


def main():
    d, want, force, n = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4])
    p = np.load(f"{d}/momentum.npy").ravel()
    u = np.load(f"{d}/profile.npy").ravel()
    kt = float(np.load(f"{d}/temperature.npy").ravel()[0])
    h = len(u)
    mean = p[0] / n
    c0, c2 = parabola_fit(u, h)
    nu = -force / (2 * c2)
    slip = c0 + c2 * h * h / 4
    print(
        f"mean velocity {mean:.5f} (source {want}, {100 * (mean / want - 1):+.1f} %), "
        f"nu from the curvature {nu:.4f}, u_max {c0:.5f}, slip velocity {slip:.5f} "
        f"(slip length {slip / (-c2 * h):.3f} a), kT {kt:.4f}"
    )


if __name__ == "__main__":
    main()
