"""libMobility's Python interface on mesoflow's graphs.

A script written for libMobility runs after changing its import::

    from mesoflow import libmobility as libMobility
    solver = libMobility.NBody("open", "open", "single_wall")
    solver.setParameters(wallHeight=0.0)
    solver.initialize(viscosity=1.0, hydrodynamicRadius=1.0, includeAngular=True)
    solver.setPositions(x)
    u, w = solver.Mdot(forces, torques)

Solvers and the graphs behind them:

- ``SelfMobility`` (any periodicity): no hydrodynamic interactions, computed with numpy.
- ``NBody`` ("open", "open", "open" or "single_wall"): ``rpy_open.json`` /
  ``rpy_wall.json`` (Rotne-Prager-Yamakawa, Rotne-Prager-Blake above a wall at
  ``wallHeight``), every pair.
- ``PSE`` ("periodic" x3): ``pse.json``, ``psi`` the Ewald split.
- ``FCM`` ("periodic" x3, not in libMobility): ``fcm.json``.
- ``DPStokes`` ("periodic", "periodic", "open", "single_wall" or "two_walls"):
  ``dpstokes.json`` (Fourier in x, y, Chebyshev in z; walls at ``zmin`` and ``zmax``).

Where mesoflow differs from libMobility: ``precision`` is always "float" (the GPU
computes in f32; arrays of any float dtype are taken and float32 is returned);
``NBody``'s ``algorithm``, ``Nbatch`` and ``NperBatch`` are accepted but one all-pairs
kernel serves every size (batches are not supported: ``Nbatch`` other than 1 or -1 is an
error); ``divM`` is a random finite difference per call (as libMobility's), zero where
the mobility does not depend on positions (open, periodic).
"""

import math
import os

import numpy as np

from . import _mesoflow

__all__ = ["SelfMobility", "NBody", "PSE", "FCM", "DPStokes"]

_PERIODICITIES = ("open", "unspecified", "single_wall", "two_walls", "periodic")


def _error(message):
    return RuntimeError(message)


def _framework(array):
    """The array library an input came from (torch, cupy, jax, tensorflow, numpy)."""
    module = type(array).__module__.split(".")[0]
    return module if module in ("torch", "cupy", "jax", "jaxlib", "tensorflow") else "numpy"


def _like(result, template):
    """`result` (numpy) as an array of the library and device `template` came from."""
    if result is None:
        return None
    kind = _framework(template)
    if kind == "torch":
        import torch

        return torch.as_tensor(result, device=template.device)
    if kind == "cupy":
        import cupy

        with cupy.cuda.Device(template.device.id):
            return cupy.asarray(result)
    if kind in ("jax", "jaxlib"):
        import jax

        return jax.device_put(result, list(template.devices())[0])
    if kind == "tensorflow":
        import tensorflow as tf

        with tf.device(template.device):
            return tf.convert_to_tensor(result)
    return result


def _host(array):
    """Any array (numpy, torch, cupy, jax, tensorflow, lists) as numpy, on the host."""
    if array is None:
        return None
    kind = _framework(array)
    if kind == "torch":
        return array.detach().cpu().numpy()
    if kind == "cupy":
        return array.get()
    if kind == "tensorflow":
        return array.numpy()
    return np.asarray(array)


def _as_rows(name, array, n=None):
    """An array of 3-vectors as float32 (N, 3); the shape check of libMobility."""
    if array is None:
        return None
    a = _host(array)
    if a.size % 3 != 0 or a.size == 0:
        raise _error(f"{name}: {a.size} values is not a whole number of 3-vectors")
    if n is not None and a.size != 3 * n:
        raise _error(
            f"{name}: {a.size // 3} vectors for {n} particles (the number of {name} does "
            "not match the number of particles)"
        )
    return np.ascontiguousarray(a, dtype=np.float32).reshape(-1, 3)


class _Solver:
    """The libMobility interface shared by every solver."""

    precision = "float"
    _allowed = ()

    def __init__(self, periodicityX, periodicityY, periodicityZ):
        periodicity = (periodicityX, periodicityY, periodicityZ)
        for p in periodicity:
            if p not in _PERIODICITIES:
                raise _error(f"[Mobility] unknown periodicity {p!r}")
        if periodicity not in self._allowed:
            raise _error(
                f"[Mobility] {type(self).__name__} does not support the periodicity "
                f"{periodicity}; it takes {', '.join(map(str, self._allowed))}"
            )
        self.periodicity = periodicity
        self._parameters = {}
        self._initialized = False
        self._positions = None
        self._programs = {}

    # -- libMobility's calls ------------------------------------------------------------

    def setParameters(self, *args, **parameters):
        """libMobility's parameters by position (in its order) or by name."""
        if len(args) > len(self._parameter_names):
            raise _error(
                f"[Mobility] {type(self).__name__}.setParameters takes at most "
                f"{len(self._parameter_names)} parameters ({', '.join(self._parameter_names)})"
            )
        for name, value in zip(self._parameter_names, args):
            if name in parameters:
                raise _error(f"[Mobility] parameter {name} given twice")
            parameters[name] = value
        unknown = set(parameters) - set(self._parameter_names)
        if unknown:
            raise _error(
                f"[Mobility] {type(self).__name__}.setParameters takes "
                f"{', '.join(self._parameter_names)}; not {', '.join(sorted(unknown))}"
            )
        self._check_parameters(parameters)
        self._parameters = dict(parameters)
        self._initialized = False
        self._programs = {}

    def _check_parameters(self, parameters):
        pass

    def initialize(
        self,
        viscosity,
        hydrodynamicRadius,
        includeAngular=False,
        tolerance=1e-4,
        seed=None,
        **extra,
    ):
        if extra:
            raise _error(f"[Mobility] initialize takes no {', '.join(extra)}")
        if not (viscosity > 0 and hydrodynamicRadius > 0):
            raise _error("[Mobility] viscosity and hydrodynamicRadius must be positive")
        if includeAngular and not self._supports_angular:
            raise _error(f"[Mobility] {type(self).__name__} does not support torques")
        self.viscosity = float(viscosity)
        self.hydrodynamicRadius = float(hydrodynamicRadius)
        self.includeAngular = bool(includeAngular)
        self.tolerance = float(tolerance)
        self._seed_given = seed is not None
        if seed is None or seed == 0:
            seed = int.from_bytes(os.urandom(4), "little")
        self.seed = int(seed)
        self._programs = {}
        self._setup()
        self._initialized = True

    def setPositions(self, positions):
        self._require_initialized()
        x = _as_rows("positions", positions)
        self._check_positions(x)
        self._positions = x
        self._sent_positions = {}
        self._template = positions

    def Mdot(self, forces=None, torques=None):
        self._require_positions()
        n = len(self._positions)
        if torques is not None and not self.includeAngular:
            raise _error(
                "[libMobility] Received torques but the solver was initialized with includeAngular=False"
            )
        f = _as_rows("forces", forces, n)
        t = _as_rows("torques", torques, n)
        shape = (
            _host(forces).shape if forces is not None
            else _host(torques).shape if torques is not None
            else (n, 3)
        )
        if f is None:
            f = np.zeros((n, 3), np.float32)
        u, w = self._mdot(f, t)
        return self._shaped(u, w, shape, torques)

    def sqrtMdotW(self, prefactor=1.0):
        self._require_positions()
        u, w = self._noise()
        n = len(self._positions)
        return self._shaped(prefactor * u, None if w is None else prefactor * w, (n, 3), None)

    def divM(self, prefactor=1.0):
        self._require_positions()
        n = len(self._positions)
        u, w = self._divergence()
        return self._shaped(prefactor * u, None if w is None else prefactor * w, (n, 3), None)

    def LangevinVelocities(self, dt, kbt, forces=None, torques=None):
        self._require_positions()
        if dt <= 0:
            raise _error("[libMobility] dt must be positive")
        u, w = (_host(v) for v in self.Mdot(forces, torques))
        if kbt > 0:
            nu, nw = (_host(v) for v in self.sqrtMdotW(math.sqrt(2.0 * kbt / dt)))
            du, dw = (_host(v) for v in self.divM(kbt))
            u = u + nu.reshape(u.shape) + du.reshape(u.shape)
            if w is not None and nw is not None:
                w = w + nw.reshape(w.shape) + dw.reshape(w.shape)
        return _like(u, self._template), _like(w, self._template)

    def clean(self):
        self._programs = {}
        self._positions = None
        self._initialized = False

    # -- shared helpers -----------------------------------------------------------------

    def _require_initialized(self):
        if not self._initialized:
            raise _error("[Mobility] call initialize before using the solver")

    def _require_positions(self):
        self._require_initialized()
        if self._positions is None:
            raise _error("[Mobility] Positions have 0 particles. Did you call setPositions?")

    def _check_positions(self, x):
        pass

    def _divergence(self):
        """div M: zero where the mobility does not depend on the positions."""
        n = len(self._positions)
        zero = np.zeros((n, 3), np.float32)
        return zero, (zero if self.includeAngular else None)

    def _shaped(self, u, w, shape, torques):
        u = np.asarray(u, np.float32).reshape(shape)
        if not self.includeAngular:
            return _like(u, self._template), None
        wshape = _host(torques).shape if torques is not None else shape
        w = np.asarray(w, np.float32).reshape(wshape)
        return _like(u, self._template), _like(w, self._template)

    def _program(self, key, outputs, **sets):
        """A compiled program of the solver's graph for these outputs, kept between calls
        (new sizes recompile inside `run`)."""
        program = self._programs.get(key)
        if program is None:
            graph = _mesoflow.Graph(self._graph_name, seed=self.seed + len(self._programs), **self._graph_params(), **sets)
            n = len(self._positions)
            shapes = {"positions": (n, 3), "forces": (n, 3)}
            if self.includeAngular and self._torque_input:
                shapes["torques"] = (n, 3)
            program = graph.compile(outputs=outputs, **shapes)
            self._programs[key] = program
        return program

    _torque_input = True

    def _run(self, key, outputs, arrays, **sets):
        # A program keeps its input buffers between runs: the positions go up once per
        # setPositions (or batch), not at every call.
        x = arrays["positions"]
        try:
            program = self._program(key, outputs, **sets)
            sent = self._sent_positions.get(key)
            if sent is not None and sent[0] is program and sent[1] is x:
                arrays = {k: v for k, v in arrays.items() if k != "positions"}
            out = program.run(**arrays)
            # The array itself is kept (not its id, which a freed batch slice can reuse).
            self._sent_positions[key] = (program, x)
            return out
        except (_mesoflow.GraphError, _mesoflow.RunError) as e:
            raise _error(f"[Mobility] {e}") from None


class SelfMobility(_Solver):
    """No hydrodynamic interactions: M = I / (6 pi eta a), rotation I / (8 pi eta a^3)."""

    _allowed = tuple(
        (a, b, c) for a in _PERIODICITIES for b in _PERIODICITIES for c in _PERIODICITIES
    )
    _parameter_names = ("parameter",)
    _supports_angular = True

    def _setup(self):
        self._rng = np.random.default_rng(self.seed)
        a, eta = self.hydrodynamicRadius, self.viscosity
        self._t = 1.0 / (6.0 * math.pi * eta * a)
        self._r = 1.0 / (8.0 * math.pi * eta * a**3)

    def _mdot(self, f, t):
        w = None
        if self.includeAngular:
            w = self._r * (t if t is not None else np.zeros_like(f))
        return self._t * f, w

    def _noise(self):
        n = len(self._positions)
        u = math.sqrt(self._t) * self._rng.standard_normal((n, 3))
        w = math.sqrt(self._r) * self._rng.standard_normal((n, 3)) if self.includeAngular else None
        return u, w



class _GraphSolver(_Solver):
    """A solver running one of mesoflow's mobility graphs."""

    def _setup(self):
        pass

    def _periodic_params(self):
        """The params of the periodic graphs (fcm.json, pse.json) from libMobility's."""
        p = self._parameters
        return {
            "viscosity": self.viscosity,
            "radius": self.hydrodynamicRadius,
            "box": [float(p["Lx"]), float(p["Ly"]), float(p["Lz"])],
            "tolerance": min(max(self.tolerance, 1e-6), 0.1),
        }

    def _arrays(self, f=None, t=None):
        arrays = {"positions": self._positions}
        arrays["forces"] = f if f is not None else np.zeros_like(self._positions)
        if self.includeAngular and self._torque_input:
            arrays["torques"] = t if t is not None else np.zeros_like(self._positions)
        return arrays

    def _mdot(self, f, t):
        outputs = ["velocities"] + (["angular_velocities"] if self.includeAngular else [])
        out = self._run("mdot", outputs, self._arrays(f, t))
        return out["velocities"], out.get("angular_velocities")

    _angular_noise = True

    def _noise(self):
        if self.includeAngular and not self._angular_noise:
            raise _error(
                f"[Mobility] {type(self).__name__} has no angular noise (its graph draws the linear part only)"
            )
        outputs = ["noise"] + (["angular_noise"] if self.includeAngular else [])
        out = self._run("noise", outputs, self._arrays())
        return out["noise"], out.get("angular_noise")



class NBody(_GraphSolver):
    """Every pair: open RPY, or Rotne-Prager-Blake above a wall ("single_wall", at
    ``wallHeight``)."""

    _allowed = (("open", "open", "open"), ("open", "open", "single_wall"))
    _parameter_names = ("algorithm", "Nbatch", "NperBatch", "wallHeight", "delta")
    _supports_angular = True

    def _check_parameters(self, p):
        if p.get("algorithm", "advise") not in ("advise", "naive", "fast", "block"):
            raise _error(f"[Mobility] unknown NBody algorithm {p['algorithm']!r}")
        wall = self.periodicity[2] == "single_wall"
        if wall and p.get("wallHeight") is None:
            raise _error(
                "[Mobility] Wall height parameter is required for a bottom wall. If you want to use a wall, set the wallHeight parameter."
            )
        if not wall and p.get("wallHeight") is not None:
            raise _error(
                "[Mobility] Wall height parameter is only valid for bottom wall. If you want to use a wall, set periodicityZ to single_wall."
            )

    @property
    def _graph_name(self):
        return "rpy_wall" if self.periodicity[2] == "single_wall" else "rpy_open"

    def _setup(self):
        self._check_parameters(self._parameters)
        nbatch = int(self._parameters.get("Nbatch", -1))
        nper = int(self._parameters.get("NperBatch", -1))
        if nbatch == 0 or nper == 0 or nbatch < -1 or nper < -1 or (nbatch > 1 and nper == -1):
            raise _error(
                f"[Mobility] Invalid batch parameters for NBody (Nbatch {nbatch}, NperBatch {nper}). If in doubt, use the defaults."
            )
        self._batches = (nbatch, nper)

    def _graph_params(self):
        params = {
            "viscosity": self.viscosity,
            "radius": self.hydrodynamicRadius,
            "rotation": self.includeAngular,
            "tolerance": min(max(self.tolerance, 1e-7), 0.5),
        }
        if self.periodicity[2] == "single_wall":
            params["wall_height"] = float(self._parameters["wallHeight"])
            params["rfd_delta"] = float(self._parameters.get("delta", 1e-3))
        return params

    def _check_positions(self, x):
        nbatch, nper = self._batches
        n = len(x)
        if (nbatch > 0 and nper > 0 and nbatch * nper != n) or (nbatch == -1 and nper > 0 and nper != n):
            raise _error(
                f"[Mobility] Invalid batch parameters for NBody: {nbatch} batches of {nper} for {n} particles. If in doubt, use the defaults."
            )
        if self.periodicity[2] == "single_wall":
            below = np.nonzero(x[:, 2] < self._parameters["wallHeight"])[0]
            if below.size:
                raise _error(
                    f"[Mobility] The center of a particle has fallen below the wall (particle {below[0]}, "
                    f"z = {x[below[0], 2]} < wallHeight = {self._parameters['wallHeight']}). "
                    "Check your configuration and forces to ensure particle centers stay above the wall."
                )

    def _divergence(self):
        if self.periodicity[2] != "single_wall":
            return super()._divergence()
        return self._batched(lambda: self._drift_one())

    def _drift_one(self):
        outputs = ["drift"] + (["angular_drift"] if self.includeAngular else [])
        out = self._run("drift", outputs, self._arrays(), temperature=1.0)
        return out["drift"], out.get("angular_drift")

    # Batches (libMobility's Nbatch x NperBatch): independent groups of particles that do
    # not see each other, each run through the same program.
    def _batched(self, one, f=None, t=None):
        nbatch = self._batches[0]
        if nbatch <= 1:
            return one() if f is None and t is None else one(f, t)
        x = self._positions
        per = len(x) // nbatch
        us, ws = [], []
        try:
            for b in range(nbatch):
                rows = slice(b * per, (b + 1) * per)
                self._positions = x[rows]
                fb = None if f is None else f[rows]
                tb = None if t is None else t[rows]
                u, w = one() if f is None and t is None else one(fb, tb)
                us.append(u)
                ws.append(w)
        finally:
            self._positions = x
        w = None if ws[0] is None else np.concatenate(ws)
        return np.concatenate(us), w

    def _mdot(self, f, t):
        return self._batched(super()._mdot, f, t if t is not None else np.zeros_like(f) if self.includeAngular else None)

    def _noise(self):
        return self._batched(super()._noise)


class PSE(_GraphSolver):
    """Positively Split Ewald in a periodic box (``psi`` the split, ``Lx``, ``Ly``,
    ``Lz``); no torques, as in libMobility."""

    _allowed = (("periodic", "periodic", "periodic"),)
    _parameter_names = ("psi", "Lx", "Ly", "Lz", "shearStrain")
    _supports_angular = False
    _graph_name = "pse"
    _torque_input = False

    def _setup(self):
        p = self._parameters
        if self._seed_given:
            raise _error("[Mobility] PSE does not take a seed (as in libMobility): leave it at None")
        for name in ("psi", "Lx", "Ly", "Lz"):
            if name not in p:
                raise _error(f"[Mobility] PSE needs the parameter {name}")
        if p.get("shearStrain", 0.0) != 0.0:
            raise _error("[Mobility] mesoflow's PSE takes no shear strain (shearStrain must be 0)")

    def _graph_params(self):
        return dict(self._periodic_params(), split=float(self._parameters["psi"]))


class FCM(_GraphSolver):
    """The Force Coupling Method in a periodic box (``Lx``, ``Ly``, ``Lz``); torques with
    ``includeAngular`` (a finer grid). Not in libMobility: the same interface."""

    _allowed = (("periodic", "periodic", "periodic"),)
    _parameter_names = ("Lx", "Ly", "Lz")
    _supports_angular = True
    _graph_name = "fcm"
    _angular_noise = False

    def _setup(self):
        for name in ("Lx", "Ly", "Lz"):
            if name not in self._parameters:
                raise _error(f"[Mobility] FCM needs the parameter {name}")

    def _graph_params(self):
        return dict(self._periodic_params(), rotation=self.includeAngular)


class DPStokes(_GraphSolver):
    """Doubly periodic Stokes (``dpstokes.json``): periodic in x and y (``Lx``, ``Ly``),
    open in z ("open"), above a wall at ``zmin`` ("single_wall") or between walls at
    ``zmin`` and ``zmax`` ("two_walls"); every particle within [zmin, zmax]. ``delta`` is
    the random finite difference's step over the radius (divM). mesoflow never changes the
    box: ``allowChangingBoxSize`` is accepted and has no effect (the grid follows the box
    as given, FFT-friendly in x and y)."""

    _allowed = (
        ("periodic", "periodic", "open"),
        ("periodic", "periodic", "single_wall"),
        ("periodic", "periodic", "two_walls"),
    )
    _parameter_names = ("Lx", "Ly", "zmin", "zmax", "allowChangingBoxSize", "delta")
    _supports_angular = True
    _graph_name = "dpstokes"
    _walls = {"open": "none", "single_wall": "bottom", "two_walls": "slit"}

    def _check_parameters(self, p):
        for name in ("Lx", "Ly", "zmin", "zmax"):
            if name not in p:
                raise _error(f"[Mobility] DPStokes needs the parameter {name}")
        if not (float(p["Lx"]) > 0 and float(p["Ly"]) > 0):
            raise _error(f"[Mobility] DPStokes: Lx and Ly must be positive, got {p['Lx']}, {p['Ly']}")
        if not float(p["zmax"]) > float(p["zmin"]):
            raise _error(f"[Mobility] DPStokes: zmax ({p['zmax']}) must be above zmin ({p['zmin']})")

    def _setup(self):
        self._check_parameters(self._parameters)

    def _graph_params(self):
        p = self._parameters
        return {
            "viscosity": self.viscosity,
            "radius": self.hydrodynamicRadius,
            "box": [float(p["Lx"]), float(p["Ly"])],
            "zmin": float(p["zmin"]),
            "zmax": float(p["zmax"]),
            "walls": self._walls[self.periodicity[2]],
            "rotation": self.includeAngular,
            "tolerance": min(max(self.tolerance, 1e-6), 0.1),
            "rfd_delta": float(p.get("delta", 1e-3)),
        }

    def _check_positions(self, x):
        p = self._parameters
        zmin, zmax = float(p["zmin"]), float(p["zmax"])
        out = np.nonzero((x[:, 2] < zmin) | (x[:, 2] > zmax))[0]
        if out.size:
            i = out[0]
            raise _error(
                f"[Mobility] DPStokes: particle {i} is at z = {x[i, 2]}, outside [zmin, zmax] = "
                f"[{zmin}, {zmax}] (the walls, or the extent of the grid in open mode)"
            )

    def _divergence(self):
        outputs = ["drift"] + (["angular_drift"] if self.includeAngular else [])
        out = self._run("drift", outputs, self._arrays(), temperature=1.0)
        return out["drift"], out.get("angular_drift")
