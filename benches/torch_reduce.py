"""torch.sum / dot / max of 1e8 float32 on the GPU (CUB behind torch), timed with CUDA
events: warm-up, then the median of 20. Run beside `mesoflow bench reduce`."""
import torch

n = 100_000_000
x = (torch.rand(n, device="cuda", dtype=torch.float64) * 6 - 3)
x = (torch.sign(torch.rand(n, device="cuda") - 0.5) * torch.pow(10.0, x)).float()


def median_ms(f, reps=20):
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
    return times[len(times) // 2]


print(f"torch {torch.__version__} on {torch.cuda.get_device_name()}")
print(f"{'op':<10} {'ms':>10} {'GB/s':>10}")
for name, f, nbytes in [
    ("sum", lambda: x.sum(), 4 * n),
    ("dot", lambda: torch.dot(x, x), 8 * n),
    ("max", lambda: x.max(), 4 * n),
    ("copy", lambda: x.clone(), 8 * n),
]:
    ms = median_ms(f)
    print(f"{name:<10} {ms:>10.4f} {nbytes / ms / 1e6:>10.1f}")
