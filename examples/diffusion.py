"""Colloids diffusing with hydrodynamic interactions, driven from Python: a Brownian
dynamics loop around mesoflow's libMobility interface (FCM in a periodic box), the mean
squared displacement against 6 kT mu t, mu Hasimoto's periodic self-mobility.

    python examples/diffusion.py [N] [steps]         # writes msd.png when matplotlib is there
"""

import math
import sys

import numpy as np

from mesoflow import libmobility


def hasimoto(a, l):
    x = a / l
    return (1 - 2.837297 * x + 4.19 * x**3 - 27.4 * x**6) / (6 * math.pi * a)


def main(n=2000, steps=200, side=32.0, dt=0.05, kT=1.0, plot="msd.png"):
    solver = libmobility.FCM("periodic", "periodic", "periodic")
    solver.setParameters(Lx=side, Ly=side, Lz=side)
    solver.initialize(viscosity=1.0, hydrodynamicRadius=1.0, tolerance=1e-3, seed=1)
    rng = np.random.default_rng(1)
    x0 = rng.uniform(-side / 2, side / 2, (n, 3))
    x = x0.copy()
    msd = []
    for _ in range(steps):
        solver.setPositions(x)
        # No forces: dx = sqrt(2 kT dt) M^(1/2) W (FCM's mobility needs no drift).
        dx, _ = solver.sqrtMdotW(prefactor=math.sqrt(2 * kT * dt))
        x = x + dx
        msd.append(np.mean(np.sum((x - x0) ** 2, axis=1)))
    t = dt * np.arange(1, steps + 1)
    theory = 6 * kT * hasimoto(1.0, side) * t
    slope = np.polyfit(t, msd, 1)[0] / 6
    print(
        f"{n} colloids, {steps} steps of dt = {dt}: D measured {slope:.5f}, "
        f"theory kT mu = {kT * hasimoto(1.0, side):.5f} (ratio {slope / (kT * hasimoto(1.0, side)):.3f})"
    )
    if plot:
        try:
            import matplotlib

            matplotlib.use("Agg")
            import matplotlib.pyplot as plt
        except ImportError:
            print("matplotlib is not installed: no plot")
            return slope
        plt.plot(t, msd, label="mesoflow FCM")
        plt.plot(t, theory, "--", label="6 kT mu t (Hasimoto)")
        plt.xlabel("t")
        plt.ylabel("mean squared displacement")
        plt.legend()
        plt.savefig(plot, dpi=120)
        print(f"wrote {plot}")
    return slope


if __name__ == "__main__":
    args = [int(a) for a in sys.argv[1:3]]
    main(*args)
