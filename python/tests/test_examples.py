"""The Python examples run (small, no plots) and measure what they say."""

import importlib.util
import math
import pathlib

import numpy as np

EXAMPLES = pathlib.Path(__file__).resolve().parents[2] / "examples"


def load(name):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_diffusion_example_measures_the_self_diffusion():
    d = load("diffusion").main(n=400, steps=40, plot=None)
    want = load("diffusion").hasimoto(1.0, 32.0)
    # 400 x 40 displacements, correlated by hydrodynamics: within 10 %.
    assert abs(d / want - 1) < 0.1, (d, want)


def test_mpcd_example_gives_a_flow_profile():
    u = load("mpcd_profile").main(steps=400, warmup=100, plot=None)
    assert u.shape == (20,)
    # Flow along the force, fastest in the middle, slowest at the plates.
    assert u[10] > 0 and u[10] > u[0] and u[10] > u[-1]
    assert np.all(np.isfinite(u))


def test_speed_against_error_reads_the_benchmark_tables():
    data = load("speed_vs_error").main(plot=None)
    fcm = data["FCM (Gaussian)"]
    poisson = data["Poisson (fields and potentials)"]
    assert len(fcm) >= 3 and len(poisson) >= 3
    # Every measured error is within its tolerance, and tighter costs more.
    for points in (fcm, poisson):
        assert all(err <= tol for tol, _, err in points)
        ordered = sorted(points)
        assert ordered[0][1] >= ordered[-1][1]
