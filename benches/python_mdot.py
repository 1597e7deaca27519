"""The cost of driving mesoflow from Python (issue 23): a loop of libMobility-style `Mdot`
calls against the GPU time of one mobility product.

For each case (FCM at tolerance 1e-3: N = 10^5 in L = 128, N = 10^3 in L = 128 and in
L = 16; NBody open at N = 10^3) it prints
  - `per call`: the median over rounds of the wall time per call of a Python loop of `Mdot`
    (forces in from numpy, velocities out to numpy, the positions sent once), and
  - `gpu per product`: the wall time per step of one `Program.run(steps=S)` of the same
    graph (one upload, S products submitted together, one download), i.e. the GPU time of
    one M F with the per-call cost spread over S,
  - `engine per call`: a loop of `Program.run(forces=F)` on that program (the engine
    API, without libMobility's wrapper), with its host time by phase after the table,
and the ratio and difference (the per-call overhead) of `per call` to `gpu per product`.

    python3 benches/python_mdot.py [--calls 1000] [--rounds 3]

Needs the mesoflow package importable (`pip install .`, or PYTHONPATH at an unpacked
wheel) and a GPU adapter.
"""
import argparse
import statistics
import time

import numpy as np

import mesoflow
from mesoflow import libmobility


def loop_time(solver, forces, calls, rounds):
    solver.Mdot(forces)  # compiles
    for _ in range(10):
        solver.Mdot(forces)
    times = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        for _ in range(calls):
            u, _ = solver.Mdot(forces)
        times.append((time.perf_counter() - t0) / calls)
    assert u.shape == forces.shape and np.isfinite(u).all()
    return statistics.median(times)


def product_time(graph_name, params, positions, forces, steps, rounds):
    """(GPU time per product, engine run per call): `steps` products in one run, and a
    loop of `Program.run(forces=...)` calls (the engine API without libmobility's
    wrapper)."""
    n = len(positions)
    program = mesoflow.Graph(graph_name, **params).compile(
        outputs=["velocities"], positions=(n, 3), forces=(n, 3)
    )
    program.run(positions=positions, forces=forces)
    batched, calls = [], []
    for _ in range(rounds):
        t0 = time.perf_counter()
        program.run(steps=steps)
        batched.append((time.perf_counter() - t0) / steps)
        before = program.host_times
        t0 = time.perf_counter()
        for _ in range(steps):
            program.run(forces=forces)
        calls.append((time.perf_counter() - t0) / steps)
        after = program.host_times
    phases = {k: (after[k] - before[k]) / steps * 1e6 for k in after}
    return statistics.median(batched), statistics.median(calls), phases


def fcm(n, side, tolerance):
    s = libmobility.FCM("periodic", "periodic", "periodic")
    s.setParameters(Lx=side, Ly=side, Lz=side)
    s.initialize(viscosity=1.0, hydrodynamicRadius=1.0, tolerance=tolerance)
    params = dict(viscosity=1.0, radius=1.0, box=[side] * 3, tolerance=tolerance)
    return s, "fcm", params


def nbody(n, side, tolerance):
    s = libmobility.NBody("open", "open", "open")
    s.setParameters()
    s.initialize(viscosity=1.0, hydrodynamicRadius=1.0, tolerance=tolerance)
    return s, "rpy_open", dict(viscosity=1.0, radius=1.0)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=1000)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    print("adapter:", mesoflow.device_summary())
    print(
        f"median over {args.rounds} rounds of {args.calls} calls; float32 numpy arrays in and out"
    )
    print(
        f"{'solver':>8} {'N':>7} {'L':>5} {'tol':>6} {'per call ms':>12} "
        f"{'gpu per product ms':>19} {'engine per call ms':>19} {'ratio':>6} {'overhead us':>12}"
    )
    cases = [
        (fcm, 100_000, 128.0, 1e-3),
        (fcm, 1_000, 128.0, 1e-3),
        (fcm, 1_000, 16.0, 1e-3),
        (nbody, 1_000, 20.0, 1e-3),
    ]
    breakdown = []
    for make, n, side, tol in cases:
        rng = np.random.default_rng(n)
        x = (rng.random((n, 3)) * side).astype(np.float32)
        f = rng.standard_normal((n, 3)).astype(np.float32)
        solver, graph, params = make(n, side, tol)
        solver.setPositions(x)
        call = loop_time(solver, f, args.calls, args.rounds)
        gpu, engine, phases = product_time(graph, params, x, f, args.calls, args.rounds)
        print(
            f"{graph:>8} {n:>7} {side:>5.0f} {tol:>6.0e} {call * 1e3:>12.4f} "
            f"{gpu * 1e3:>19.4f} {engine * 1e3:>19.4f} {call / gpu:>6.2f} {(call - gpu) * 1e6:>12.1f}",
            flush=True,
        )
        breakdown.append((graph, n, side, phases))
    print("engine per call, host time by phase (us; Program.host_times):")
    for graph, n, side, phases in breakdown:
        print(f"  {graph} N = {n} L = {side:.0f}: " + ", ".join(f"{k} {v:.1f}" for k, v in phases.items()))


if __name__ == "__main__":
    main()
