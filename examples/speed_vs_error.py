"""Speed against error from the tables of BENCHMARKS.md: FCM (Gaussian kernel) and
Poisson at 10^5 particles on the GPU the tables were measured on, GPU time of one call
against the worst error measured at that tolerance (FCM: self-mobility at the worst
placement; Poisson: the field).

    python examples/speed_vs_error.py [BENCHMARKS.md]    # writes speed_vs_error.png with matplotlib
"""

import pathlib
import sys


def table(text, heading):
    """The rows of the first markdown table after `heading`, as lists of cells."""
    start = text.index(heading)
    rows = []
    for line in text[start:].splitlines()[1:]:
        if line.startswith("|"):
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if not set(cells[0]) <= set("-: "):
                rows.append(cells)
        elif rows:
            break
    return rows[0], rows[1:]


def number(cell):
    return float(cell.split()[0].replace("**", ""))


def series(path):
    """{solver: [(tolerance, ms at 10^5, error)]} from the benchmark tables."""
    text = pathlib.Path(path).read_text()
    out = {}
    head, rows = table(text, "### Gaussian kernel against UAMMD")
    tol, n, ms, err = (head.index(c) for c in ("tol", "N", "e2e ms", "self err worst / mean"))
    errors = {r[tol]: number(r[err]) for r in rows if r[err]}
    out["FCM (Gaussian)"] = [
        (number(r[tol]), number(r[ms]), errors[r[tol]]) for r in rows if r[n] == "10^5" and r[tol] in errors
    ]
    head, rows = table(text, "## Poisson: speed against error")
    tol, n, ms, err = (head.index(c) for c in ("tol", "N", "e2e ms", "E err"))
    out["Poisson (fields and potentials)"] = [
        (number(r[tol]), number(r[ms]), number(r[err])) for r in rows if r[n] == "10^5"
    ]
    return out


def main(path=None, plot="speed_vs_error.png"):
    path = path or pathlib.Path(__file__).resolve().parents[1] / "BENCHMARKS.md"
    data = series(path)
    for name, points in data.items():
        for tol, ms, err in sorted(points, reverse=True):
            print(f"{name:32} tolerance {tol:7.0e}: {ms:8.4f} ms, error {err:.2e}")
    if plot:
        try:
            import matplotlib

            matplotlib.use("Agg")
            import matplotlib.pyplot as plt
        except ImportError:
            print("matplotlib is not installed: no plot")
            return data
        for name, points in data.items():
            points = sorted(points, key=lambda p: p[2])
            plt.loglog([p[2] for p in points], [p[1] for p in points], "o-", label=name)
        plt.xlabel("worst error")
        plt.ylabel("GPU ms per call, 10^5 particles")
        plt.legend()
        plt.savefig(plot, dpi=120)
        print(f"wrote {plot}")
    return data


if __name__ == "__main__":
    main(*sys.argv[1:2])
