"""Poiseuille flow of an MPCD solvent between two plates (graphs/mpcd.json from Python):
the velocity profile after a warm-up, against the parabola fitted to it (whose curvature
gives the viscosity).

    python examples/mpcd_profile.py [steps]           # writes profile.png when matplotlib is there
"""

import sys

import numpy as np

import mesoflow


def main(steps=3000, warmup=600, plot="profile.png"):
    g = mesoflow.Graph(
        "mpcd",
        box=[8, 8, 10],
        walls="plates",
        force=0.03,
        warmup=warmup,
        profile_bins=20,
        seed=5,
    )
    program = g.compile(outputs=["velocity_profile", "temperature"])
    out = program.run(steps=steps)
    u = out["velocity_profile"].ravel()
    z = (np.arange(len(u)) + 0.5) / len(u) * 10 - 5
    a, b, c = np.polyfit(z, u, 2)
    print(f"temperature {float(out['temperature'].ravel()[0]):.4f}, centre velocity {u[len(u) // 2]:.4f}")
    print(f"parabola u = {a:.5f} z^2 + {b:.5f} z + {c:.5f} (viscosity from the curvature: {-0.03 * 10 / (2 * a):.3f} for density 10)")
    if plot:
        try:
            import matplotlib

            matplotlib.use("Agg")
            import matplotlib.pyplot as plt
        except ImportError:
            print("matplotlib is not installed: no plot")
            return u
        plt.plot(z, u, "o", label="mesoflow MPCD")
        plt.plot(z, a * z * z + b * z + c, "--", label="fitted parabola")
        plt.xlabel("z")
        plt.ylabel("u_x")
        plt.legend()
        plt.savefig(plot, dpi=120)
        print(f"wrote {plot}")
    return u


if __name__ == "__main__":
    main(*[int(a) for a in sys.argv[1:2]])
