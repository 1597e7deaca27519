"""mesoflow's DPStokes (through its libMobility interface) against the reference data of
libMobility's own wall tests (github.com/stochasticHydroTools/libMobility, tests/ref/ and
tests/test_wall_mobility.py's set-up: Lx = Ly = 76.8, zmin = 0, zmax = 19.2, a = 1,
eta = 1 / (4 sqrt(pi)), the particles at the box's centre, mobilities in units of the
Stokes drag's 1 / (6 pi eta a)). Three references:
  self_mobility_bw_ref.npz   the physics: periodized Rotne-Prager-Blake sums in f64 (the
                             DoublyPeriodicStokes repository), heights 1a to 8a
  self_mobility_{bw,sc}_w4   libMobility's DPStokes itself (its default kernel, f64)
  pair_mobility_{bw,sc}_w4   the same for two spheres 3a, 4a, 8a apart along x
Prints, per reference, the largest deviation of each mobility entry; against the physics
also the relative deviation at h >= 2a and 3a (below them the closed forms are themselves
off), and libMobility's own (self_mobility_bw_w4, interpolated to the same heights).
Any adapter (lavapipe takes a few minutes: --stride thins the heights).
Usage: python benches/dpstokes_libmobility.py LIBMOBILITY/tests/ref [--tolerance T] [--stride S]"""
import argparse
import pathlib

import numpy as np

import mesoflow.libmobility as lm

ETA = 1 / 4 / np.sqrt(np.pi)
SIDE, TOP = 76.8, 19.2
DRAG = 6 * np.pi * ETA


def solver(mode, tolerance):
    s = lm.DPStokes("periodic", "periodic", mode)
    s.setParameters(Lx=SIDE, Ly=SIDE, zmin=0.0, zmax=TOP)
    s.initialize(viscosity=ETA, hydrodynamicRadius=1.0, tolerance=tolerance)
    return s


def matrix(s, positions):
    """The 3N x 3N mobility column by column, in units of 1 / (6 pi eta a)."""
    n = len(positions)
    s.setPositions(np.asarray(positions, np.float32))
    m = np.zeros((3 * n, 3 * n))
    for j in range(3 * n):
        f = np.zeros(3 * n, np.float32)
        f[j] = 1.0
        m[:, j] = np.asarray(s.Mdot(f.reshape(n, 3))[0], np.float64).ravel()
    return m * DRAG


def self_rows(s, heights):
    return np.array([np.diag(matrix(s, [[SIDE / 2, SIDE / 2, h]])) for h in heights])


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("ref", type=pathlib.Path)
    p.add_argument("--tolerance", type=float, default=1e-4)
    p.add_argument("--stride", type=int, default=3)
    args = p.parse_args()
    print(f"mesoflow DPStokes, tolerance {args.tolerance}, against libMobility's tests/ref")
    print(f"{'reference':<24} {'walls':<10} {'heights':>8} {'max |dM|':>10} {'rel. h>=2a':>11} {'h>=3a':>9}")
    for mode, tag in (("single_wall", "bw"), ("two_walls", "sc")):
        s = solver(mode, args.tolerance)
        refs = [f"self_mobility_{tag}_w4"] + (["self_mobility_bw_ref"] if tag == "bw" else [])
        for name in refs:
            r = np.load(args.ref / f"{name}.npz")
            hs = r["heights"].flatten()[:: args.stride]
            want = np.array([np.diag(m)[:3] for m in r["M"][:: args.stride]])
            got = self_rows(s, hs)

            def rel(m, h0):
                far = hs >= h0
                return np.abs(m[far] / want[far] - 1).max() if far.any() else float("nan")

            print(f"{name:<24} {mode:<10} {len(hs):>8} {np.abs(got - want).max():>10.2e} "
                  f"{rel(got, 2.0):>11.2e} {rel(got, 3.0):>9.2e}")
            if name == "self_mobility_bw_ref":
                w4 = np.load(args.ref / "self_mobility_bw_w4.npz")
                wh = w4["heights"].flatten()
                theirs = np.array([[np.interp(h, wh, w4["M"][:, c, c]) for c in range(3)] for h in hs])
                print(f"{'  libMobility w4 on it':<24} {mode:<10} {len(hs):>8} "
                      f"{np.abs(theirs - want).max():>10.2e} {rel(theirs, 2.0):>11.2e} {rel(theirs, 3.0):>9.2e}")
        r = np.load(args.ref / f"pair_mobility_{tag}_w4.npz")
        hs = r["heights"].flatten()[:: args.stride]
        worst = 0.0
        for i, sep in enumerate((3.0, 4.0, 8.0)):
            for k, h in enumerate(r["heights"].flatten()):
                if k % args.stride:
                    continue
                c = SIDE / 2
                got = matrix(s, [[c + sep / 2, c, h], [c - sep / 2, c, h]])
                worst = max(worst, np.abs(got - r["M"][i, k, :6, :6]).max())
        print(f"{'pair_mobility_' + tag + '_w4':<24} {mode:<10} {3 * len(hs):>8} {worst:>10.2e} {'':>11}")


if __name__ == "__main__":
    main()
