"""mesoflow's streamed trajectories (`mesoflow run --every K --output NAME=FILE.gsd`) read
by the `gsd` package, HOOMD-blue's own reader (OVITO, freud and MDAnalysis read the same
files): the frames, their steps, box, time and values, and the last frame against a
one-shot run of the same steps."""

import json
import os
import pathlib
import subprocess

import numpy as np
import pytest

gsd_hoomd = pytest.importorskip("gsd.hoomd")

ROOT = pathlib.Path(__file__).resolve().parents[2]


def binary():
    """The newest mesoflow binary cargo built (cargo test builds target/debug)."""
    built = [p for p in (ROOT / "target/debug/mesoflow", ROOT / "target/release/mesoflow") if p.exists()]
    if not built:
        pytest.skip("no mesoflow binary: run cargo build first")
    return max(built, key=lambda p: p.stat().st_mtime)


def run(*args):
    done = subprocess.run([str(binary()), "run", *map(str, args)], capture_output=True, text=True, env=os.environ.copy())
    assert done.returncode == 0, done.stderr
    return done


def test_a_streamed_trajectory_reads_back_with_the_gsd_package(tmp_path):
    rng = np.random.default_rng(3)
    x = rng.uniform(-1.0, 1.0, (4, 3)).astype(np.float32)
    np.save(tmp_path / "x.npy", x)
    graph = ROOT / "graphs/examples/relax.json"
    common = [graph, "--input", f"positions={tmp_path / 'x.npy'}", "--steps", "5"]
    run(*common, "--output", f"positions={tmp_path / 'once.npy'}")
    trajectory = tmp_path / "t.gsd"
    run(*common, "--every", "2", "--output", f"positions={trajectory}", "--output", f"force={trajectory}")
    once = np.load(tmp_path / "once.npy")
    with gsd_hoomd.open(trajectory, "r") as frames:
        assert len(frames) == 3
        assert [int(f.configuration.step) for f in frames] == [2, 4, 5]
        last = frames[2]
        assert last.particles.N == 4
        np.testing.assert_array_equal(last.particles.position, once)
        assert not np.array_equal(frames[0].particles.position, once)
        assert last.log["particles/force"].shape == (4, 3)
        assert last.log["time"][0] == pytest.approx(5 * 0.01)
        assert last.configuration.dimensions == 3
    assert not list(tmp_path.glob(".*.tmp"))


def test_a_scene_trajectory_carries_its_species(tmp_path):
    """`mesoflow run SCENE`: the species (types, typeid, diameter, mass, charge) in the
    first frame stand for every frame (GSD's rule), read back by the gsd package, and
    every frame has the scene's box."""
    scene = {
        "scene": 1,
        "box": [12, 12, 12],
        "species": {"big": {"radius": 0.6, "mass": 2.0}, "small": {"radius": 0.6, "mass": 0.5}},
        "particles": [
            {"species": "big", "count": 6, "place": "random"},
            {"species": "small", "count": 9, "place": "lattice"},
        ],
        "interactions": {"wca": {"sigma": 1.2}, "gravity": [0, 0, -1]},
        "temperature": 1.0,
        "integrator": {"scheme": "euler_maruyama", "dt": 0.01},
        "run": {"steps": 6, "seed": 4},
        "output": {"file": "t.gsd", "every": 3, "values": ["positions", "energy"]},
    }
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(scene))
    done = subprocess.run([str(binary()), "run", str(path)], capture_output=True, text=True, cwd=tmp_path, env=os.environ.copy())
    assert done.returncode == 0, done.stderr
    with gsd_hoomd.open(tmp_path / "t.gsd", "r") as frames:
        assert len(frames) == 2
        for f in frames:
            assert f.particles.types == ["big", "small"]
            np.testing.assert_array_equal(f.particles.typeid, [0] * 6 + [1] * 9)
            np.testing.assert_allclose(f.particles.mass, [2.0] * 6 + [0.5] * 9)
            np.testing.assert_allclose(f.particles.diameter, 1.2)
            assert f.particles.position.shape == (15, 3)
            np.testing.assert_array_equal(f.configuration.box, [12, 12, 12, 0, 0, 0])
        assert [int(f.configuration.step) for f in frames] == [3, 6]
        assert "energy" in frames[1].log
