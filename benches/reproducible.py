"""Run-to-run reproducibility of a graph on the GPU machine (benches/gpu.sh determinism).

    python3 benches/reproducible.py inputs DIR N L     # positions and forces, seeded
    python3 benches/reproducible.py compare A.npy B.npy [LABEL]

`compare` prints how many float32 words differ between two outputs of identical runs and
the largest relative difference among them.
"""
import sys

import numpy as np


def inputs(folder, n, side):
    rng = np.random.default_rng(12345)
    pos = rng.uniform(-side / 2, side / 2, size=(n, 3)).astype(np.float32)
    forces = rng.normal(size=(n, 3)).astype(np.float32)
    np.save(f"{folder}/positions.npy", pos)
    np.save(f"{folder}/forces.npy", forces)


def compare(a_path, b_path, label):
    a, b = np.load(a_path), np.load(b_path)
    differ = a.view(np.uint32) != b.view(np.uint32)
    n = int(differ.sum())
    if n:
        rel = np.abs(a[differ] - b[differ]) / np.maximum(np.abs(a[differ]), 1e-30)
        worst = float(rel.max())
    else:
        worst = 0.0
    print(f"{label}: {n} of {a.size} words differ between two identical runs "
          f"({100.0 * n / a.size:.1f}%), largest relative difference {worst:.2e}")


if __name__ == "__main__":
    if sys.argv[1] == "inputs":
        inputs(sys.argv[2], int(sys.argv[3]), float(sys.argv[4]))
    else:
        compare(sys.argv[2], sys.argv[3], sys.argv[4] if len(sys.argv) > 4 else "")
