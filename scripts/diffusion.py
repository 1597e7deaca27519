#!/usr/bin/env python3
"""Self-diffusion of colloids from a trajectory of positions (an NPY file of shape
(frames, N, 3), one frame per step, as `mesoflow run ... --output positions=FILE.npy
--every 1` writes), against kT times the self-mobility of a sphere in a cubic periodic
box (Hasimoto). Standard library only, so the main job needs nothing installed.

usage: diffusion.py TRAJECTORY.npy DT SIDE [RADIUS VISCOSITY TEMPERATURE]
"""
import ast
import math
import sys
from array import array


def read_npy(path):
    with open(path, "rb") as f:
        if f.read(6) != b"\x93NUMPY":
            raise SystemExit(f"{path}: not an NPY file")
        major = f.read(2)[0]
        size = int.from_bytes(f.read(2 if major == 1 else 4), "little")
        header = ast.literal_eval(f.read(size).decode("latin1"))
        if header["descr"] != "<f4" or header["fortran_order"]:
            raise SystemExit(f"{path}: expected little-endian f32 in C order, got {header}")
        data = array("f")
        data.frombytes(f.read())
    return header["shape"], data


def hasimoto(a, length):
    """The self-mobility of a sphere in a cubic periodic box, times 6 pi eta a."""
    x = a / length
    c = 16 * math.pi**2 / 45 + 630 * 0.19457**2
    return 1 - 2.8372974794806195 * x + 4 * math.pi / 3 * x**3 - c * x**6


def main():
    if len(sys.argv) not in (4, 7):
        raise SystemExit(__doc__)
    path, dt, side = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
    a, eta, kt = (float(v) for v in sys.argv[4:7]) if len(sys.argv) == 7 else (1.0, 1.0, 1.0)
    (frames, n, k), x = read_npy(path)
    if k != 3 or frames < 2:
        raise SystemExit(f"{path}: expected (frames >= 2, N, 3), got {(frames, n, k)}")
    row = 3 * n
    sums = [0.0, 0.0, 0.0]
    for f in range(1, frames):
        before, after = x[(f - 1) * row : f * row], x[f * row : (f + 1) * row]
        for axis in range(3):
            sums[axis] += math.fsum(
                (p - q) ** 2 for p, q in zip(after[axis::3], before[axis::3])
            )
    steps = frames - 1
    measured = [s / (n * steps * 2 * dt) for s in sums]
    theory = kt * hasimoto(a, side) / (6 * math.pi * eta * a)
    # Independent particles plus the Oseen correlation of pairs (6.6 n a^2 / L^2 times
    # the independent variance), over the steps.
    rel = math.sqrt((2 / n + 13.2 * a**2 / side**2) / steps)
    print(f"self-diffusion from {steps} steps of {n} particles (per axis x, y, z):")
    print("  measured " + " ".join(f"{d:.5f}" for d in measured))
    print(f"  theory   {theory:.5f} (kT hasimoto(a, L) / (6 pi eta a)); expected within "
          f"{300 * rel:.2g}% (3 standard errors)")
    worst = max(abs(d / theory - 1) for d in measured)
    print(f"  largest deviation {100 * worst:.2f}%")
    if worst > 3 * rel:
        raise SystemExit("diffusion: off by more than 3 standard errors")


if __name__ == "__main__":
    main()
