"""Scenes from Python: `mesoflow.Graph(scene)` builds the scene's graph and places its
particles (`scene_inputs`), which a Program runs like any graph's inputs."""

import json

import numpy as np
import pytest

import mesoflow


def write(tmp_path, scene, name="scene.json"):
    path = tmp_path / name
    path.write_text(json.dumps(scene))
    return str(path)


SCENE = {
    "scene": 1,
    "box": [8, 8, 8],
    "species": {"bead": {"radius": 0.5, "mass": 1.0}},
    "particles": [{"species": "bead", "count": 30, "place": "random"}],
    "interactions": {"wca": {"sigma": 1.0}},
    "temperature": 1.0,
    "integrator": {"scheme": "langevin_gjf", "dt": 0.005, "friction": 1.0},
    "run": {"steps": 5, "seed": 2},
}


def test_a_scene_runs_from_python(tmp_path):
    g = mesoflow.Graph(write(tmp_path, SCENE))
    inputs = g.scene_inputs
    assert set(inputs) == {"positions", "velocities", "masses"}
    x = inputs["positions"]
    assert x.shape == (30, 3) and x.dtype == np.float32
    # No two beads closer than a diameter (the periodic images counted).
    d = x[:, None, :] - x[None, :, :]
    d -= 8 * np.round(d / 8)
    r = np.sqrt((d**2).sum(-1)) + np.eye(30) * 10
    assert r.min() >= 1.0 - 1e-5
    assert g.seed == 2
    shapes = {k: v.shape for k, v in inputs.items()}
    prog = g.compile(outputs=["positions", "velocities", "energy"], **shapes)
    out = prog.run(steps=5, **inputs)
    assert out["positions"].shape == (30, 3)
    assert not np.array_equal(out["positions"], x)
    assert np.isfinite(out["energy"]).all()
    # Another seed, other placements.
    other = mesoflow.Graph(write(tmp_path, SCENE), seed=3).scene_inputs["positions"]
    assert not np.array_equal(other, x)


def test_a_bad_scene_raises_with_its_place(tmp_path):
    bad = dict(SCENE, particles=[{"species": "nobody", "count": 3}])
    with pytest.raises(mesoflow.GraphError, match=r"particles\[0\]\.species: no species `nobody`"):
        mesoflow.Graph(write(tmp_path, bad))
