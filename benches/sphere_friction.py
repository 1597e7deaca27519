"""Friction of an MPCD sphere from the time series that `mesoflow run graphs/mpcd_spheres.json
--every K` streams (S2 §5.6.2), for benches/gpu.sh suite spheres:

  acf IMPULSE.npy   a fixed sphere at rest: the fluid's momentum is P(t) = P(0) - I(t), with
                    I the momentum the fluid gave the sphere since step 0 (`sphere_impulse`,
                    exact 64-bit sums), so its autocorrelation gives
                    -ln[<P(t).P(0)> / (3 N m kT)] = xi t / (N m): xi from the slope
  instant IMPULSE.npy  every step's impulse dI of a fixed sphere: the instantaneous friction
                    xi_I = <|dI|^2> / (3 kT dt) (the tau = 0 term of the force ACF, integrated
                    over one collision interval)
  vacf VELOCITY.npy a moving sphere's velocities (`sphere_velocities`): D = (1/3) int <V(t).V(0)>
                    dt (Green-Kubo), and kT / D, the friction it implies

Options: --every K (steps between frames), --dt, --n (solvent particles), --mass, --kt.
"""

import argparse

import numpy as np


def impulse_series(path, vth, mass):
    """(frames, 3) cumulative impulse of sphere 0 from the (lo, hi) u32 word pairs, in m v."""
    words = np.load(path).astype(np.uint64)
    frames = words.reshape(len(words), -1)
    sums = np.empty((len(frames), 3))
    for a in range(3):
        raw = frames[:, 2 * a] | (frames[:, 2 * a + 1] << np.uint64(32))
        sums[:, a] = raw.astype(np.int64).astype(np.float64)
    return sums * mass * vth / 2.0**24


def autocorrelation(x, lags):
    """<x(t + lag) . x(t)> over t (x: frames x 3), by FFT, for lags 0..lags-1."""
    n = len(x)
    size = 1 << int(np.ceil(np.log2(2 * n)))
    total = np.zeros(lags)
    for a in range(x.shape[1]):
        f = np.fft.rfft(x[:, a], size)
        total += np.fft.irfft(f * np.conj(f), size)[:lags]
    return total / (n - np.arange(lags))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("mode", choices=["acf", "instant", "vacf"])
    ap.add_argument("file")
    ap.add_argument("--every", type=int, default=1)
    ap.add_argument("--dt", type=float, required=True)
    ap.add_argument("--n", type=float, default=0.0)
    ap.add_argument("--mass", type=float, default=1.0)
    ap.add_argument("--kt", type=float, default=1.0)
    ap.add_argument("--skip", type=int, default=0, help="frames dropped at the start (relaxation)")
    a = ap.parse_args()
    vth = np.sqrt(a.kt / a.mass)
    frame_dt = a.every * a.dt
    if a.mode == "instant":
        impulse = impulse_series(a.file, vth, a.mass)[a.skip :]
        if a.every != 1:
            raise SystemExit("instant: needs a frame every step (--every 1)")
        steps = np.diff(impulse, axis=0)
        xi = np.mean(np.sum(steps**2, axis=1)) / (3 * a.kt * a.dt)
        print(f"instantaneous friction from {len(steps)} steps: xi_I = <|dI|^2> / (3 kT dt) = {xi:.4g}")
        return
    if a.mode == "acf":
        p = -impulse_series(a.file, vth, a.mass)[a.skip :]
        p -= p.mean(axis=0)
        nm = a.n * a.mass
        lags = len(p) // 8
        c = autocorrelation(p, lags)
        norm = c / (3 * nm * a.kt)
        t = np.arange(lags) * frame_dt
        # Fit -ln(C / C0) = xi t / (N m) over C from 1 down to 1/e (the clean exponential part),
        # through the origin.
        below = np.nonzero(norm < norm[0] / np.e)[0]
        end = below[0] if len(below) else lags
        y = -np.log(norm[1:end] / norm[0])
        slope = np.sum(y * t[1:end]) / np.sum(t[1:end] ** 2)
        # The same with the source's normalisation 3 N m kT instead of C(0).
        y3 = -np.log(np.clip(norm[1:end], 1e-12, None))
        slope3 = np.sum(y3 * t[1:end]) / np.sum(t[1:end] ** 2)
        span = len(p) * frame_dt
        print(
            f"fluid momentum ACF over {span:.0f} time units ({span * slope:.0f} decay times): "
            f"C(0) / (3 N m kT) = {norm[0]:.4f}; fit to C(t) > C(0)/e (t < {t[end - 1]:.0f}): "
            f"xi = N m slope = {slope * nm:.4g} (normalised by 3 N m kT instead of C(0): {slope3 * nm:.4g}); "
            f"standard error about {100 * np.sqrt(2 / (3 * span * slope)):.0f}% (sqrt(2 tau / 3 T))"
        )
        return
    v = np.load(a.file).astype(np.float64)
    v = v.reshape(len(v), -1)[a.skip :, :3]
    lags = len(v) // 4
    # No mean subtracted: the total momentum is zero, so the sphere's mean velocity is 0, and
    # subtracting the sample mean would pull the Green-Kubo integral back to 0 at long lags.
    c = autocorrelation(v, lags)
    t = np.arange(lags) * frame_dt
    running = np.concatenate([[0.0], np.cumsum(0.5 * (c[1:] + c[:-1]) * frame_dt)]) / 3.0
    # The velocity's decay time tau_v = D / (<V^2>/3) (M / xi for a Langevin sphere) from the
    # integral up to the first zero of C; D read as the running integral's mean over
    # [5, 50] tau_v (the plateau; the hydrodynamic tail adds slowly after it).
    first_zero = np.nonzero(c <= 0)[0]
    d0 = running[first_zero[0]] if len(first_zero) else running[-1]
    tau_v = d0 / (c[0] / 3)
    lo, hi = int(5 * tau_v / frame_dt), int(50 * tau_v / frame_dt) + 1
    d = running[lo:hi].mean()
    report = [x for x in (0.3, 1, 3, 10, 30, 100, 300) if x < t[-1]]
    parts = ", ".join(f"t {x}: {running[int(x / frame_dt)]:.4g}" for x in report)
    print(
        f"sphere VACF over {len(v) * frame_dt:.0f} time units: <V^2>/3 = {c[0] / 3:.4g} (kT/M by "
        f"equipartition), tau_v = {tau_v:.3g}; running Green-Kubo D: {parts}; D on [5, 50] tau_v = "
        f"{d:.4g}, kT / D = {a.kt / d:.4g}"
    )

if __name__ == "__main__":
    main()
