"""PyTorch (CUB) counterparts of `mesoflow bench sort` and `mesoflow bench scan`, in the
same table format: torch.sort of 1e7 int32 keys (stable, with the sorting indices),
torch.cumsum of 1e8 int32, and torch.sum of 1e8 float32, on CUDA, timed with CUDA events
around each call (3 warm-up calls, then the median of 20): what mesoflow's end-to-end
"ms" and "min ms" columns measure.

GB/s counts each operation's own input and output once: sort reads 4 bytes per key and
writes the sorted key (4) and its int64 index (8); cumsum of int32 writes int64 by default
(4 in, 8 out), or int32 with dtype=int32 (4 in, 4 out, as mesoflow's scan); sum reads 4.
Compare G/s (elements per second) across libraries, since the output widths differ.

    python3 benches/torch_primitives.py [--sort-n N] [--scan-n N] [--reps R]
"""
import argparse

import torch


def time_ms(f, reps):
    for _ in range(3):
        f()
    torch.cuda.synchronize()
    times = []
    for _ in range(reps):
        a, b = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
        a.record()
        f()
        b.record()
        torch.cuda.synchronize()
        times.append(a.elapsed_time(b))
    times.sort()
    return times[len(times) // 2], times[0]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sort-n", type=int, default=10_000_000)
    ap.add_argument("--scan-n", type=int, default=100_000_000)
    ap.add_argument("--reps", type=int, default=20)
    args = ap.parse_args()
    gen = torch.Generator(device="cuda").manual_seed(1)
    keys = torch.randint(-(2**31), 2**31, (args.sort_n,), dtype=torch.int32, device="cuda", generator=gen)
    x = torch.randint(0, 2**31, (args.scan_n,), dtype=torch.int32, device="cuda", generator=gen)
    y = torch.rand(args.scan_n, dtype=torch.float32, device="cuda", generator=gen)

    # Check the sort and the scan once, so that a wrong fast call cannot pass.
    v, i = torch.sort(keys, stable=True)
    assert torch.equal(keys[i], v) and bool((v[1:] >= v[:-1]).all())
    assert int(torch.cumsum(x, 0)[-1]) == int(x.sum(dtype=torch.int64))

    rows = [
        ("torch.sort int32 stable + idx", args.sort_n, lambda: torch.sort(keys, stable=True), 16),
        ("torch.cumsum int32 -> int64", args.scan_n, lambda: torch.cumsum(x, 0), 12),
        ("torch.cumsum int32 -> int32", args.scan_n, lambda: torch.cumsum(x, 0, dtype=torch.int32), 8),
        ("torch.sum float32", args.scan_n, lambda: torch.sum(y), 4),
    ]
    print(f"adapter: {torch.cuda.get_device_name()} (torch {torch.__version__}, CUDA {torch.version.cuda})")
    print(f"{'op':<30} {'n':>11} {'ms':>9} {'min ms':>9} {'G/s':>9} {'GB/s':>9}")
    for name, n, f, bytes_per_elem in rows:
        ms, lo = time_ms(f, args.reps)
        s = ms / 1e3
        print(f"{name:<30} {n:>11} {ms:>9.4f} {lo:>9.4f} {n / s / 1e9:>9.2f} {bytes_per_elem * n / s / 1e9:>9.1f}")


if __name__ == "__main__":
    main()
