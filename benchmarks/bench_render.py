"""Speed of ``render`` per method on the reference setup, by what it is given as ``H``.

Prints, from one run, the best time of one ``render`` call for every built-in method
(reference setup, simulated participant 3, 4096 samples), given:

- a bare transfer matrix (``cal.transfer_for(n)``), which the CLI, the study engine,
  the web app and the demo passed before issue 28;
- the ``Calibration`` itself (its kept wrap-around check);
- a ``TransferMatrix`` kept across the calls (its kept check and inverse operators), the
  default path of the consumers since issue 28 (skipped where the installed vibrofocus
  has none).

Run: ``python benchmarks/bench_render.py [--repeats 5]``. Timings are the best of
``repeats`` runs (of more where those take under half a second in all); compare only
timings of one machine.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import vibrofocus
from vibrofocus import render
from vibrofocus.calibration import calibrate
from vibrofocus.defaults import METHODS
from vibrofocus.rigs import SimulatedForearm

N = 4096
LOCATION = 5
MIN_TOTAL_S = 0.5


def best_of(repeats: int, fn) -> float:
    """Best wall time of ``repeats`` calls of ``fn``, or of as many as fill MIN_TOTAL_S, ms."""
    best, runs, spent = np.inf, 0, 0.0
    while runs < repeats or spent < MIN_TOTAL_S:
        start = time.perf_counter()
        fn()
        elapsed = time.perf_counter() - start
        best, runs, spent = min(best, elapsed), runs + 1, spent + elapsed
    return 1e3 * best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    cal = calibrate(SimulatedForearm(seed=3), participant_id="BENCH", method="h1", sweep_s=1.0, repeats=2)
    H = cal.transfer_for(N)
    sources = {"bare array": H, "Calibration": cal}
    if hasattr(vibrofocus, "TransferMatrix"):
        sources["kept TransferMatrix"] = vibrofocus.TransferMatrix.from_calibration(cal, N)
    print(f"vibrofocus {vibrofocus.__version__}: render, reference setup, {N} samples, location {LOCATION}, ms")
    print(f"  {'method':14s}" + "".join(f"{name:>22s}" for name in sources))
    for method in METHODS:
        times = [best_of(args.repeats, lambda s=source: render(method, s, cal.fs, cal.layout, LOCATION, n_samples=N))
                 for source in sources.values()]
        print(f"  {method:14s}" + "".join(f"{t:22.2f}" for t in times))


if __name__ == "__main__":
    main()
