"""The engine API: graphs by name and path, descriptions, compile and run with numpy,
programs that keep their pipelines and state, seeds, errors."""

import math
import os

import numpy as np
import pytest

import mesoflow


def test_graphs_load_by_name_and_by_path_from_any_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    g = mesoflow.Graph("fcm")
    assert g.path.endswith("fcm.json")
    assert "fcm" in mesoflow.library() and "lib/cell_list" in mesoflow.library()
    again = mesoflow.Graph(g.path, box=[16, 16, 16])
    assert again.params["box"]["value"] == [16.0, 16.0, 16.0]
    assert mesoflow.Graph("examples/colloids").outputs


def test_descriptions_carry_the_docs():
    g = mesoflow.Graph("rpy_open", rotation=True)
    assert g.params["rotation"]["value"] is True
    assert g.params["radius"]["default"] == 1.0
    assert "hydrodynamic radius" in g.params["radius"]["doc"]
    assert g.inputs["positions"]["shape"] == (100, 3)
    assert g.inputs["torques"]["optional"] is True
    assert "angular_velocities" in g.outputs
    assert "Rotne-Prager" in g.doc


def test_bad_graphs_and_params_raise_graph_errors():
    with pytest.raises(mesoflow.GraphError, match="no graph file `nope`"):
        mesoflow.Graph("nope")
    with pytest.raises(mesoflow.GraphError, match="tolerance"):
        mesoflow.Graph("fcm", tolerance=5)
    with pytest.raises(mesoflow.GraphError, match="unknown"):
        mesoflow.Graph("fcm", not_a_param=1)
    g = mesoflow.Graph("rpy_open")
    with pytest.raises(mesoflow.GraphError, match="angular_velocities"):
        g.compile(outputs=["angular_velocities"], positions=(4, 3), forces=(4, 3))
    with pytest.raises(mesoflow.GraphError, match="no input `speed`"):
        g.compile(speed=(4, 3))
    assert issubclass(mesoflow.GraphError, RuntimeError)


def rpy_reference(x, f, a=1.0):
    """Open RPY (eta = 1) in f64, written here."""
    n = len(x)
    u = f / (6 * math.pi * a)
    for i in range(n):
        for j in range(n):
            if i == j:
                continue
            r = x[i] - x[j]
            d = np.linalg.norm(r)
            e = r / d
            if d >= 2 * a:
                c = 1 / (8 * math.pi * d)
                fi, gi = c * (1 + 2 * a * a / (3 * d * d)), c * (1 - 2 * a * a / (d * d))
            else:
                c = 1 / (6 * math.pi * a)
                fi, gi = c * (1 - 9 * d / (32 * a)), c * 3 * d / (32 * a)
            u[i] += fi * f[j] + gi * np.dot(e, f[j]) * e
    return u


def test_run_takes_float64_and_flat_arrays_and_returns_float32():
    rng = np.random.default_rng(1)
    x = rng.uniform(-3, 3, (12, 3))
    f = rng.normal(size=(12, 3))
    g = mesoflow.Graph("rpy_open")
    p = g.compile(outputs=["velocities"], positions=(12, 3), forces=(12, 3))
    out = p.run(positions=x, forces=f.ravel())
    u = out["velocities"]
    assert u.dtype == np.float32 and u.shape == (12, 3)
    want = rpy_reference(x, f)
    assert np.abs(u - want).max() < 2e-6 * np.abs(want).max()
    out32 = p.run(positions=x.astype(np.float32), forces=f.astype(np.float32))
    assert np.array_equal(out32["velocities"], u)
    assert p.outputs == ["velocities"]


def test_repeated_runs_build_no_pipelines_and_new_sizes_build_few():
    g = mesoflow.Graph("rpy_open")
    p = g.compile(outputs=["velocities"], positions=(8, 3), forces=(8, 3))
    first = p.compilations
    assert first > 0
    x = np.random.default_rng(2).uniform(-3, 3, (8, 3))
    for _ in range(3):
        p.run(positions=x, forces=x)
    assert p.compilations == first
    y = np.random.default_rng(3).uniform(-3, 3, (20, 3))
    out = p.run(positions=y, forces=y)
    assert out["velocities"].shape == (20, 3)
    # The same kernels serve the new size: nothing, or far less than the first compile.
    assert p.compilations - first < first


def test_inputs_given_once_are_kept_and_some_may_be_replaced():
    rng = np.random.default_rng(5)
    x, f, g2 = (rng.uniform(-3, 3, (9, 3)) for _ in range(3))
    p = mesoflow.Graph("rpy_open").compile(outputs=["velocities"], positions=(9, 3), forces=(9, 3))
    p.run(positions=x, forces=f)
    only_forces = p.run(forces=g2)["velocities"]
    assert np.array_equal(only_forces, p.run(positions=x, forces=g2)["velocities"])
    assert np.abs(only_forces - rpy_reference(x, g2)).max() < 2e-6 * np.abs(only_forces).max()
    # An upload refused by a node's check is not counted as given.
    w = mesoflow.Graph("rpy_wall", wall_height=1.0).compile(
        outputs=["velocities"], positions=(2, 3), forces=(2, 3)
    )
    with pytest.raises(mesoflow.RunError, match="below the wall"):
        w.run(positions=[[0, 0, 2.0], [0, 0, 0.5]], forces=np.ones((2, 3)))
    with pytest.raises(ValueError, match="`positions` never given"):
        w.run(forces=np.ones((2, 3)))


def test_host_times_count_each_phase_of_run():
    x = np.random.default_rng(6).uniform(-3, 3, (7, 3))
    p = mesoflow.Graph("rpy_open").compile(outputs=["velocities"], positions=(7, 3), forces=(7, 3))
    first = p.host_times
    assert set(first) == {"convert", "upload", "submit", "wait", "read", "to_numpy"}
    assert all(v == 0 for v in first.values())
    p.run(positions=x, forces=x)
    p.run(forces=x)
    later = p.host_times
    assert all(later[k] > 0 for k in later), later


def test_draws_are_fresh_every_run_and_reset_repeats_them():
    g = mesoflow.Graph("rpy_open", seed=7)
    x = np.random.default_rng(4).uniform(-3, 3, (6, 3))
    p = g.compile(outputs=["noise"], positions=(6, 3), forces=(6, 3))
    a = p.run(positions=x, forces=x)["noise"]
    b = p.run()["noise"]
    assert not np.array_equal(a, b)
    assert p.steps_done == 2
    p.reset()
    assert np.array_equal(p.run()["noise"], a)
    other = mesoflow.Graph("rpy_open", seed=7).compile(outputs=["noise"], positions=(6, 3), forces=(6, 3))
    assert np.array_equal(other.run(positions=x, forces=x)["noise"], a)
    third = mesoflow.Graph("rpy_open", seed=8).compile(outputs=["noise"], positions=(6, 3), forces=(6, 3))
    assert not np.array_equal(third.run(positions=x, forces=x)["noise"], a)


def test_stateful_graphs_carry_their_state_between_runs():
    g = mesoflow.Graph("examples/relax", stiffness=2.0, dt=0.1)
    x0 = np.ones((5, 3))
    p = g.compile(outputs=["positions"], positions=(5, 3))
    x1 = p.run(steps=3, positions=x0)["positions"]
    x2 = p.run(steps=2)["positions"]
    assert np.allclose(x1, 0.8**3, rtol=1e-6)
    assert np.allclose(x2, 0.8**5, rtol=1e-6)
    p.reset()
    assert np.allclose(p.run(steps=5)["positions"], x2)


def test_refused_data_and_bad_arrays_raise():
    g = mesoflow.Graph("rpy_wall", wall_height=1.0)
    p = g.compile(outputs=["velocities"], positions=(2, 3), forces=(2, 3))
    with pytest.raises(mesoflow.RunError, match="row 1.*below the wall"):
        p.run(positions=[[0, 0, 2.0], [0, 0, 0.5]], forces=np.zeros((2, 3)))
    with pytest.raises(mesoflow.GraphError, match="neither"):
        p.run(positions=np.zeros(7), forces=np.zeros((2, 3)))
    with pytest.raises(ValueError):
        p.run(steps=0)
    fresh = g.compile(outputs=["velocities"], positions=(2, 3), forces=(2, 3))
    with pytest.raises(ValueError, match="`forces` never given"):
        fresh.run(positions=[[0, 0, 2.0], [1, 0, 3.0]])


def test_every_output_the_inputs_allow_and_the_plan_and_profile():
    g = mesoflow.Graph("rpy_open")
    p = g.compile(positions=(4, 3), forces=(4, 3))
    assert "angular_velocities" in p.left_out
    assert "velocities" in p.outputs
    text = p.inspect()
    assert "all_pairs" in text
    x = np.random.default_rng(5).uniform(-3, 3, (4, 3))
    p.run(positions=x, forces=x)
    rows = p.profile()
    assert rows and all(ms >= 0 for _, ms in rows)
    assert mesoflow.adapters()
    assert "max binding" in mesoflow.device_summary()
