"""torch's device copy of a given number of bytes moved (half read, half written), timed
with CUDA events: the median of single copies (a launch's overhead included) and the mean
of 100 launched back to back. Small copies are bound by the launches either way (about 12
us a copy back to back on an H100, 2026-12-07): below about 30 MB neither is the GPU's
time for the bytes. The floor a kernel that reads and writes that many bytes once is held
against (BENCHMARKS.md, DP Stokes: the solve against the copy at each size).
Usage: python3 benches/torch_copy.py MB [MB ...]"""
import sys

import torch

# CUDA events around each call: 3 warm-up calls, then (median, min) of `reps`.
from torch_primitives import time_ms


def batch_ms(f, reps=100):
    f()
    torch.cuda.synchronize()
    a, b = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
    a.record()
    for _ in range(reps):
        f()
    b.record()
    torch.cuda.synchronize()
    return a.elapsed_time(b) / reps


print(f"torch {torch.__version__} on {torch.cuda.get_device_name()}")
print(f"{'MB moved':>10} {'single ms':>10} {'GB/s':>8} {'batch ms':>10} {'GB/s':>8}")
for arg in sys.argv[1:]:
    moved = float(arg) * 1e6
    n = int(moved / 8)  # f32 words copied: n read, n written
    src = torch.rand(n, device="cuda")
    dst = torch.empty_like(src)
    f = lambda: dst.copy_(src)
    s, b = time_ms(f, 50)[0], batch_ms(f)
    print(f"{float(arg):>10.1f} {s:>10.4f} {moved / s / 1e6:>8.0f} {b:>10.4f} {moved / b / 1e6:>8.0f}")
