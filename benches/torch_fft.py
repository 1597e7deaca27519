#!/usr/bin/env python3
"""cuFFT through PyTorch, the reference for `mesoflow bench fft`: torch.fft.rfftn then
irfftn over the last three dims of a (comps, n, n, n) float32 CUDA tensor, timed with CUDA
events (warm-up, then the median of --reps runs), with the columns of mesoflow's table:
"cuFFT ms" compares with its end-to-end "e2e ms". The times include PyTorch's own
per-call overhead, as the issue's figures do.

    python3 benches/torch_fft.py [--sizes 64,96,...] [--comps 3] [--reps 20] [--max-ref 512]
"""
import argparse
import datetime
import statistics

import numpy as np
import torch

DIMS = (-3, -2, -1)


def rel_l2(got, want):
    return float(np.linalg.norm(got - want) / max(np.linalg.norm(want), 1e-300))


def timed(fn, reps):
    """Median milliseconds of fn() over reps runs, each between two CUDA events."""
    out = []
    for _ in range(reps):
        start = torch.cuda.Event(enable_timing=True)
        end = torch.cuda.Event(enable_timing=True)
        start.record()
        fn()
        end.record()
        torch.cuda.synchronize()
        out.append(start.elapsed_time(end))
    return statistics.median(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="64,96,128,162,189,192,216,256,375,384")
    ap.add_argument("--comps", type=int, default=3)
    ap.add_argument("--reps", type=int, default=20)
    ap.add_argument("--max-ref", type=int, default=512,
                    help="largest size whose forward error is checked against numpy in f64")
    a = ap.parse_args()
    sizes = [int(s) for s in a.sizes.split(",") if s]
    dev = torch.device("cuda")
    print(f"adapter: {torch.cuda.get_device_name(dev)} (torch {torch.__version__}, "
          f"CUDA {torch.version.cuda}); date {datetime.date.today().isoformat()}")
    print(f"torch.fft.rfftn + irfftn over the last 3 dims of ({a.comps}, n, n, n) float32, "
          f"median of {a.reps} CUDA-event-timed runs")
    print(f"{'size':>6} {'cuFFT ms':>12} {'rfftn ms':>10} {'irfftn ms':>10} "
          f"{'error vs f64':>14} {'round trip':>12}")
    for n in sizes:
        gen = torch.Generator(device=dev).manual_seed(n)
        x = torch.rand((a.comps, n, n, n), device=dev, generator=gen) * 2 - 1
        spectrum = torch.fft.rfftn(x, dim=DIMS)
        y = torch.fft.irfftn(spectrum, s=(n, n, n), dim=DIMS)
        for _ in range(3):  # warm-up: plans, allocator, clocks
            torch.fft.irfftn(torch.fft.rfftn(x, dim=DIMS), s=(n, n, n), dim=DIMS)
        torch.cuda.synchronize()
        pair = timed(lambda: torch.fft.irfftn(torch.fft.rfftn(x, dim=DIMS), s=(n, n, n), dim=DIMS),
                     a.reps)
        fwd = timed(lambda: torch.fft.rfftn(x, dim=DIMS), a.reps)
        inv = timed(lambda: torch.fft.irfftn(spectrum, s=(n, n, n), dim=DIMS), a.reps)
        if n <= a.max_ref:
            want = np.fft.rfftn(x[0].double().cpu().numpy())
            error = f"{rel_l2(spectrum[0].cpu().numpy().astype(np.complex128), want):.2e}"
        else:
            error = "-"
        round_trip = rel_l2(y.double().cpu().numpy(), x.double().cpu().numpy())
        print(f"{n:>6} {pair:>12.4f} {fwd:>10.4f} {inv:>10.4f} {error:>14} {round_trip:>12.2e}")
        del x, spectrum, y
        torch.cuda.empty_cache()


if __name__ == "__main__":
    main()
