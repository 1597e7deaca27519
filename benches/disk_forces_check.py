"""The long-range disk forces on the GPU against an f64 sum (benches/gpu.sh suite disks):
N disks on a jittered square lattice in a periodic box, in row order (compact tiles: the
one-image path) and shuffled (every pair by its own minimum image), through
benches/disk_forces.json; the largest error of 256 sampled particles, relative to the
largest force among them.

  python3 benches/disk_forces_check.py MESOFLOW N
"""

import os
import subprocess
import sys
import tempfile

import numpy as np


def main():
    binary, n = sys.argv[1], int(sys.argv[2])
    side = int(np.ceil(np.sqrt(n)))
    rng = np.random.default_rng(5)
    # The box as the GPU holds it (f32): a pair within rounding of half the box would
    # otherwise take the other image in the reference.
    length = float(np.float32(1.1 * side))
    grid = np.stack(np.meshgrid(np.arange(side), np.arange(side)), -1).reshape(-1, 2)[:n]
    x = (grid + 0.5) * 1.1 - length / 2 + rng.uniform(-0.2, 0.2, (n, 2))
    q = rng.uniform(-2, 2, (n, 2))
    for order in ("rows", "shuffled"):
        if order == "shuffled":
            p = rng.permutation(n)
            x, q = x[p], q[p]
        with tempfile.TemporaryDirectory() as d:
            np.save(os.path.join(d, "x.npy"), x.astype(np.float32))
            np.save(os.path.join(d, "q.npy"), q.astype(np.float32))
            subprocess.run(
                [binary, "run", "benches/disk_forces.json", "--set", f"length={length}",
                 "--input", f"positions={d}/x.npy", "--input", f"charges={d}/q.npy",
                 "--output", f"forces={d}/f.npy"],
                check=True, capture_output=True)
            f = np.load(os.path.join(d, "f.npy")).astype(np.float64)
        xs, qs = x.astype(np.float32).astype(np.float64), q.astype(np.float32).astype(np.float64)
        sample = rng.choice(n, 256, replace=False)
        want = np.empty((256, 2))
        for row, i in enumerate(sample):
            r = xs[i] - xs
            r -= length * np.round(r / length)
            r2 = (r * r).sum(1)
            r2[r2 == 0] = np.inf
            want[row] = qs[i, 1] * (qs[:, 0, None] * r / r2[:, None] ** 1.5).sum(0)
        err = np.abs(f[sample] - want).max() / np.abs(want).max()
        print(f"disk forces N {n} {order}: largest error {err:.2e} of the largest force (f32 sums of {n} terms)")


if __name__ == "__main__":
    main()
