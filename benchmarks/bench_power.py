"""Speed of ``vibrofocus power``: simulated studies per second (issue 16).

Prints, from one run:

- the cost of one simulated study on the fast path, split into simulation (feature bank +
  numpy draws) and analysis (vectorized RM-ANOVA and Friedman tests), and the analysis of
  the same study through the report's pingouin functions, for comparison;
- studies per second of a whole power analysis on Dask with a LocalCluster of 1 worker
  and of all cores, and in one process without Dask; the three give the same numbers
  (asserted).

Run: ``python benchmarks/bench_power.py [--studies 40] [--n 10,20,30]``. One BLAS thread
per process. Timings include the LocalCluster start-up.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from threadpoolctl import threadpool_limits


def _pingouin_analysis(arrays) -> None:
    import pandas as pd

    from vibrofocus.analysis.study1 import study1_anova
    from vibrofocus.analysis.study2 import friedman_tests

    n, nl, nm = arrays.error_mm.shape
    methods = ["funneling", "inverse", "combination"]
    idx = pd.MultiIndex.from_product([[f"p{i}" for i in range(n)], range(1, nl + 1), methods[:nm]],
                                     names=["participant", "location", "method"])
    study1_anova(pd.DataFrame({"error_mm": arrays.error_mm.ravel()}, index=idx).reset_index())
    friedman_tests(pd.DataFrame({"n_selected": arrays.count.ravel()}, index=idx).reset_index())
    keep = np.all(np.isfinite(arrays.count_hit), axis=(1, 2))
    if keep.sum() < 2:  # too few participants with a target-containing trial in every condition
        return
    friedman_tests(pd.DataFrame({"n_selected": arrays.count_hit[keep].ravel()},
                                index=idx[np.repeat(keep, nl * nm)]).reset_index())


def main() -> None:
    from vibrofocus.simulation.bank import default_bank, simulate_cell_means
    from vibrofocus.simulation.power import PowerDesign, run_power, study_statistics

    ap = argparse.ArgumentParser()
    ap.add_argument("--studies", type=int, default=40)
    ap.add_argument("--n", default="10,20,30")
    args = ap.parse_args()
    ns = tuple(int(x) for x in args.n.split(","))
    bank = default_bank()
    with threadpool_limits(1):
        reps = 20
        t = time.perf_counter()
        arrays = [simulate_cell_means(20, np.random.default_rng(k), bank=bank) for k in range(reps)]
        t_sim = (time.perf_counter() - t) / reps
        t = time.perf_counter()
        for a in arrays:
            study_statistics(a)
        t_fast = (time.perf_counter() - t) / reps
        t = time.perf_counter()
        for a in arrays[:5]:
            _pingouin_analysis(a)
        t_pg = (time.perf_counter() - t) / 5
    print(f"one study of 20 participants: simulation {1e3 * t_sim:.1f} ms, analysis {1e3 * t_fast:.1f} ms "
          f"(vectorized) vs {1e3 * t_pg:.0f} ms (pingouin, report path): x{t_pg / t_fast:.1f}")
    design = PowerDesign(n_participants=ns, n_studies=args.studies, seed=1)
    total = len(ns) * args.studies
    rates = {}
    t = time.perf_counter()
    ref = run_power(design, local=True)
    rates["one process, no Dask"] = total / (time.perf_counter() - t)
    cores = os.cpu_count() or 1
    for workers in sorted({1, cores}):
        t = time.perf_counter()
        res = run_power(design, n_workers=workers)
        rates[f"LocalCluster, {workers} worker(s)"] = total / (time.perf_counter() - t)
        np.testing.assert_equal(res["table"], ref["table"], err_msg="Dask and one process disagree")
    print(f"power analysis, N = {ns}, {args.studies} studies per N ({total} studies), {cores} CPU core(s):")
    for k, v in rates.items():
        print(f"  {k:32s} {v:6.1f} studies/s")
    est = 200 * 5 / rates[f"LocalCluster, {cores} worker(s)"]
    print(f"=> 200 studies x 5 values of N: about {est / 60:.1f} min on this machine with all cores")


if __name__ == "__main__":
    main()
