"""libMobility's interface (as libMobility's own tests use it) on SelfMobility, NBody
(open and above a wall), PSE, FCM and DPStokes: shapes, errors, and the mobilities against f64
references written here."""

import math

import numpy as np
import pytest

from mesoflow import libmobility as lm

from test_engine import rpy_reference


def make(Solver, periodicity, includeAngular=False, **parameters):
    s = Solver(*periodicity)
    s.setParameters(**parameters)
    # PSE takes no seed, as in libMobility.
    seed = None if Solver is lm.PSE else 3
    s.initialize(viscosity=1.0, hydrodynamicRadius=1.0, includeAngular=includeAngular, seed=seed)
    return s


CONFIGS = [
    (lm.SelfMobility, ("open", "open", "open"), {"parameter": 5.0}),
    (lm.NBody, ("open", "open", "open"), {"algorithm": "advise"}),
    (lm.NBody, ("open", "open", "single_wall"), {"algorithm": "advise", "wallHeight": 0.0, "delta": 1e-3}),
    (lm.PSE, ("periodic", "periodic", "periodic"), {"psi": 1.0, "Lx": 16, "Ly": 16, "Lz": 16, "shearStrain": 0.0}),
    (lm.FCM, ("periodic", "periodic", "periodic"), {"Lx": 16, "Ly": 16, "Lz": 16}),
    (lm.DPStokes, ("periodic", "periodic", "single_wall"), {"Lx": 16, "Ly": 16, "zmin": 0.0, "zmax": 9.0}),
]


def positions(n, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(0.5, 8.0, (n, 3)).astype(np.float32)


@pytest.mark.parametrize(("Solver", "periodicity", "parameters"), CONFIGS)
def test_shapes_follow_the_inputs(Solver, periodicity, parameters):
    s = make(Solver, periodicity, **parameters)
    assert s.precision == "float"
    x = positions(4)
    s.setPositions(x)
    f = np.ones((4, 3), np.float64)
    mf, mt = s.Mdot(f)
    assert mf.shape == (4, 3) and mt is None
    mf, _ = s.Mdot(f.ravel())
    assert mf.shape == (12,)
    s.setPositions(x.ravel())
    w, _ = s.sqrtMdotW()
    assert w.shape == (4, 3)
    d, _ = s.divM()
    assert d.shape == (4, 3)
    v, _ = s.LangevinVelocities(1.0, 1.0, f)
    assert v.shape == f.shape
    v0, _ = s.LangevinVelocities(1.0, 0.0, f)
    assert np.allclose(v0, s.Mdot(f)[0], atol=1e-6)
    # Changing N.
    s.setPositions(positions(7, 1))
    assert s.Mdot(np.ones((7, 3)))[0].shape == (7, 3)
    assert s.sqrtMdotW()[0].shape == (7, 3)


@pytest.mark.parametrize(("Solver", "periodicity", "parameters"), [c for c in CONFIGS if c[0] is not lm.PSE])
def test_torques_come_back_both_ways(Solver, periodicity, parameters):
    s = make(Solver, periodicity, includeAngular=True, **parameters)
    s.setPositions(positions(5))
    t = np.random.default_rng(2).random((5, 3))
    mf, mt = s.Mdot(torques=t)
    assert mf.shape == t.shape and mt.shape == t.shape
    assert np.linalg.norm(mt) > 0
    if Solver is not lm.SelfMobility:
        assert np.linalg.norm(mf) > 0
    mf, mt = s.Mdot(forces=t)
    assert np.linalg.norm(mf) > 0
    if Solver is not lm.SelfMobility:
        assert np.linalg.norm(mt) > 0


def test_errors_are_runtime_errors_with_reasons():
    with pytest.raises(RuntimeError, match="periodicity"):
        lm.NBody("periodic", "periodic", "periodic")
    with pytest.raises(RuntimeError, match="periodicity"):
        lm.PSE("open", "open", "open")
    s = lm.NBody("open", "open", "open")
    s.setParameters(algorithm="advise")
    with pytest.raises(RuntimeError, match="initialize"):
        s.setPositions(positions(2))
    s.initialize(viscosity=1.0, hydrodynamicRadius=1.0)
    with pytest.raises(RuntimeError, match="setPositions"):
        s.Mdot(np.ones((2, 3)))
    s.setPositions(positions(2))
    with pytest.raises(RuntimeError, match="includeAngular"):
        s.Mdot(np.ones((2, 3)), np.ones((2, 3)))
    with pytest.raises(RuntimeError, match="does not match"):
        s.Mdot(np.ones((3, 3)))
    with pytest.raises(RuntimeError, match="3-vectors"):
        s.setPositions(np.ones(7))
    w = lm.NBody("open", "open", "single_wall")
    with pytest.raises(RuntimeError, match="wallHeight"):
        w.initialize(viscosity=1.0, hydrodynamicRadius=1.0)
    w.setParameters(wallHeight=1.0)
    w.initialize(viscosity=1.0, hydrodynamicRadius=1.0)
    with pytest.raises(RuntimeError, match="below the wall"):
        w.setPositions([[0, 0, 3.0], [1, 1, 0.5]])
    p = lm.PSE("periodic", "periodic", "periodic")
    p.setParameters(psi=0.5, Lx=16, Ly=16, Lz=16)
    with pytest.raises(RuntimeError, match="torques"):
        p.initialize(viscosity=1.0, hydrodynamicRadius=1.0, includeAngular=True)
    with pytest.raises(RuntimeError, match="setParameters takes"):
        p.setParameters(split=0.5)


def test_self_mobility_is_the_stokes_drag():
    s = make(lm.SelfMobility, ("open", "open", "open"), includeAngular=True)
    s.setPositions(positions(3))
    u, w = s.Mdot(np.ones((3, 3)), np.ones((3, 3)))
    assert np.allclose(u, 1 / (6 * math.pi), rtol=1e-6)
    assert np.allclose(w, 1 / (8 * math.pi), rtol=1e-6)


def test_nbody_open_is_rpy():
    s = make(lm.NBody, ("open", "open", "open"))
    x = positions(9, 4).astype(np.float64)
    f = np.random.default_rng(5).normal(size=(9, 3))
    s.setPositions(x)
    u, _ = s.Mdot(f)
    want = rpy_reference(x, f)
    assert np.abs(u - want).max() < 2e-6 * np.abs(want).max()


def test_nbody_wall_self_mobility_is_swan_and_brady_s():
    s = make(lm.NBody, ("open", "open", "single_wall"), wallHeight=0.5)
    for h in [1.0, 1.5, 3.0, 6.0]:
        s.setPositions([[0.2, -0.1, 0.5 + h]])
        ux, _ = s.Mdot([[1.0, 0, 0]])
        uz, _ = s.Mdot([[0, 0, 1.0]])
        q = 1 / h
        par = (1 - 9 / 16 * q + q**3 / 8 - q**5 / 16) / (6 * math.pi)
        perp = (1 - 9 / 8 * q + q**3 / 2 - q**5 / 8) / (6 * math.pi)
        assert abs(ux[0, 0] - par) < 2e-6 * par
        assert abs(uz[0, 2] - perp) < 2e-6 * par


def hasimoto(a, l):
    """Self-mobility of a sphere in a periodic cube, over 6 pi eta a (Hasimoto)."""
    x = a / l
    return 1 - 2.837297 * x + 4.19 * x**3 - 27.4 * x**6


@pytest.mark.parametrize("Solver", [lm.PSE, lm.FCM])
def test_periodic_self_mobility_is_hasimoto_s(Solver):
    params = {"Lx": 16, "Ly": 16, "Lz": 16}
    if Solver is lm.PSE:
        params["psi"] = 0.5
    s = Solver("periodic", "periodic", "periodic")
    s.setParameters(**params)
    s.initialize(viscosity=1.0, hydrodynamicRadius=1.0, tolerance=1e-3)
    s.setPositions([[1.3, -2.1, 0.7]])
    u, _ = s.Mdot([[1.0, 0, 0]])
    want = hasimoto(1.0, 16.0) / (6 * math.pi)
    assert abs(u[0, 0] - want) < 1.5e-3 * want


def test_noise_covariance_is_the_mobility():
    s = make(lm.NBody, ("open", "open", "open"))
    x = np.array([[0, 0, 0], [2.5, 0.3, 0]], np.float64)
    s.setPositions(x)
    samples = np.array([s.sqrtMdotW()[0].ravel() for _ in range(3000)])
    cov = samples.T @ samples / len(samples)
    m = np.array([s.Mdot(e.reshape(2, 3))[0].ravel() for e in np.eye(6)]).T
    se = np.sqrt((np.outer(np.diag(m), np.diag(m)) + m * m) / len(samples))
    assert np.all(np.abs(cov - m) < 5 * se)


def test_parameters_by_position_and_their_checks():
    s = lm.NBody("open", "open", "open")
    s.setParameters("advise", 1, 12)
    s.initialize(viscosity=1.0, hydrodynamicRadius=1.5)
    s.setPositions(positions(12))
    with pytest.raises(RuntimeError, match="only valid for bottom wall"):
        lm.NBody("open", "open", "open").setParameters(wallHeight=0.5)
    with pytest.raises(RuntimeError, match="required for a bottom wall"):
        lm.NBody("open", "open", "single_wall").setParameters("advise")
    lm.NBody("open", "open", "single_wall").setParameters(wallHeight=0.5)
    for nbatch, nper, n in [(5, 1, 10), (2, -1, 8)]:
        b = lm.NBody("open", "open", "open")
        b.setParameters("advise", nbatch, nper)
        with pytest.raises(RuntimeError, match="batch"):
            b.initialize(viscosity=1.0, hydrodynamicRadius=1.5)
            b.setPositions(positions(n))
    p = lm.PSE("periodic", "periodic", "periodic")
    p.setParameters(1.0, 10.0, 10.0, 10.0)
    p.initialize(hydrodynamicRadius=1.0, viscosity=1.0)
    with pytest.raises(RuntimeError, match="seed"):
        p.initialize(hydrodynamicRadius=1.0, viscosity=1.0, seed=12345)
    with pytest.raises(RuntimeError):
        lm.PSE("periodicasdas", "periodic", "open")


def test_batches_do_not_see_each_other():
    x = positions(8, 6).astype(np.float64)
    f = np.random.default_rng(7).normal(size=(8, 3))
    s = lm.NBody("open", "open", "open")
    s.setParameters("advise", 2, 4)
    s.initialize(viscosity=1.0, hydrodynamicRadius=1.0)
    s.setPositions(x)
    u, _ = s.Mdot(f)
    want = np.concatenate([rpy_reference(x[:4], f[:4]), rpy_reference(x[4:], f[4:])])
    assert np.abs(u - want).max() < 2e-6 * np.abs(want).max()
    u, _ = s.Mdot(f)  # each batch's positions sent again
    assert np.abs(u - want).max() < 2e-6 * np.abs(want).max()
    assert s.sqrtMdotW()[0].shape == (8, 3)


def test_outputs_come_back_as_the_positions_came():
    torch = pytest.importorskip("torch")
    s = make(lm.NBody, ("open", "open", "open"), includeAngular=True)
    x = torch.rand(5, 3)
    s.setPositions(x)
    u, w = s.Mdot(torch.rand(5, 3), torch.rand(5, 3))
    assert type(u) is type(x) and type(w) is type(x)
    assert type(s.LangevinVelocities(1.0, 1.0)[0]) is type(x)


def test_dpstokes_above_a_wall_is_rotne_prager_blake_s():
    """libMobility's DPStokes geometry: a wall at zmin; far from the periodic images
    (h << L) the self-mobilities are Swan and Brady's within the window's percent."""
    s = lm.DPStokes("periodic", "periodic", "single_wall")
    s.setParameters(Lx=32.0, Ly=32.0, zmin=0.0, zmax=6.0)
    s.initialize(viscosity=1.0, hydrodynamicRadius=1.0, tolerance=1e-3, seed=3)
    for h in [2.0, 3.0]:
        s.setPositions([[0.4, -0.3, h]])
        ux, _ = s.Mdot([[1.0, 0, 0]])
        uz, _ = s.Mdot([[0, 0, 1.0]])
        q = 1 / h
        par = (1 - 9 / 16 * q + q**3 / 8 - q**5 / 16) / (6 * math.pi)
        perp = (1 - 9 / 8 * q + q**3 / 2 - q**5 / 8) / (6 * math.pi)
        assert abs(ux[0, 0] - par) < 0.02 * par
        assert abs(uz[0, 2] - perp) < 0.02 * perp
        assert abs(ux[0, 1]) + abs(ux[0, 2]) < 1e-6 * ux[0, 0]
    # Below the wall: an exception naming the particle.
    with pytest.raises(RuntimeError, match="particle 1"):
        s.setPositions([[0, 0, 2.0], [0, 0, -0.5]])
    # Two walls: symmetric about the mid-plane.
    t = lm.DPStokes("periodic", "periodic", "two_walls")
    t.setParameters(16.0, 16.0, -2.0, 4.0)
    t.initialize(viscosity=1.0, hydrodynamicRadius=1.0, tolerance=1e-3, seed=3)
    t.setPositions([[0.1, 0.2, -0.5]])
    low, _ = t.Mdot([[0.3, 0.0, 1.0]])
    t.setPositions([[0.1, 0.2, 2.5]])
    high, _ = t.Mdot([[0.3, 0.0, -1.0]])
    assert np.allclose(high[0] * [1, 1, -1], low[0], rtol=0, atol=1e-3 * abs(low[0, 0]))

def _dp_mdot(pos, forces, lx, ly):
    """libMobility's test_dpstokes.py set-up: a wall at zmin = -8, zmax = 8, eta = 1 / (6 pi)."""
    s = lm.DPStokes(periodicityX="periodic", periodicityY="periodic", periodicityZ="single_wall")
    s.setParameters(Lx=lx, Ly=ly, zmin=-8.0, zmax=8.0)
    s.initialize(viscosity=1 / (6 * np.pi), hydrodynamicRadius=1.0)
    s.setPositions(pos)
    mf, _ = s.Mdot(forces=forces)
    return mf


def test_dpstokes_periodic_copies_and_isotropy_as_libmobility_tests_them():
    """libMobility's own DPStokes checks (its tests/test_dpstokes.py, with its tolerances):
    doubling the box along x or y with the particles copied gives the same velocities, and
    a force along x in a box long in x moves a particle as the same force along y in the
    box turned (non-square boxes, any height over the wall)."""
    rng = np.random.default_rng(11)
    pos = rng.uniform(-8, 8, (2, 3)).astype(np.float32)
    forces = rng.uniform(-1, 1, (2, 3)).astype(np.float32)
    forces -= forces.mean(axis=0)
    cube = _dp_mdot(pos, forces, 16.0, 16.0)
    for shift, (lx, ly) in (([16.0, 0.0, 0.0], (32.0, 16.0)), ([0.0, 16.0, 0.0], (16.0, 32.0))):
        copies = np.vstack((pos, pos + np.array(shift, dtype=np.float32)))
        doubled = _dp_mdot(copies, np.vstack((forces, forces)), lx, ly)[: len(pos)]
        assert np.allclose(doubled, cube, rtol=1e-3, atol=1e-2)
    for _ in range(3):
        p = rng.uniform(-8, 8, 3).astype(np.float32)
        along_x = _dp_mdot(p, np.array([1.0, 0.0, 0.0]), 32.0, 16.0).ravel()
        along_y = _dp_mdot(p, np.array([0.0, 1.0, 0.0]), 16.0, 32.0).ravel()
        assert np.allclose(along_x[[0, 1, 2]], along_y[[1, 0, 2]], rtol=1e-3, atol=1e-2)
