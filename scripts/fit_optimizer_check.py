#!/usr/bin/env python
"""The hypothesis fit's optimizer on a parameter that acts through the detection threshold.

Prints three measurements (a MODEL, not data; docs/fitting-hypotheses.md, "The fit and
the score"):

1. the change of the Study 1 log-likelihood (N = 6, 8 draws) when each free parameter
   moves by 0.01 % and by 1 % of its range, per hypothesis: a smooth parameter changes
   about 100 times more over the larger step; ``intensity``'s ``sl_ref_db`` does not;
2. ``intensity`` with ``sl_ref_db`` alone free, a study of N = 8 simulated at 12 dB:
   where the fit ends, its log-likelihood and the true value's;
3. ``intensity`` with all its free parameters, a Study 1 study of N = 12 (32 draws,
   3 starts): the log-likelihood reached, the likelihoods it took, the time, and where
   each parameter went.

Run it on the code to compare (``PYTHONPATH=<tree>/src``): the numbers in the docs come
from the commit before the Nelder-Mead fit and from the one after.

    python scripts/fit_optimizer_check.py            # all three (about 5 min on 2 cores)
    python scripts/fit_optimizer_check.py --quick    # 1 and 2 only
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

from vibrofocus.simulation import available_hypotheses, hypothesis
from vibrofocus.simulation.fitting import FitSettings, fit_hypothesis, participant_loglik, simulate_trials
from vibrofocus.simulation.parameters import read_parameters


def _study1(data):
    return data.subset(np.arange(data.n_participants), studies=(1,))


def steps() -> None:
    s = FitSettings(n_draws=8)
    for name in available_hypotheses():
        h = hypothesis(name)
        data = _study1(simulate_trials(h, 6, np.random.default_rng([99, 0])))
        r = h.free_parameters
        lo = np.array([x.lo for x in r])
        span = np.array([x.hi for x in r]) - lo
        u0 = np.clip((np.array(read_parameters(h.model(), r), float) - lo) / span, 0, 1)
        f0 = participant_loglik(h, data, list(lo + span * u0), settings=s).sum()
        for i, x in enumerate(r):
            d = []
            for du in (1e-4, 1e-2):
                u = u0.copy()
                u[i] = u[i] + du if u[i] + du <= 1 else u[i] - du
                d.append(participant_loglik(h, data, list(lo + span * u), settings=s).sum() - f0)
            print(f"{name:18s} {x.key:18s} change at 0.01 %: {d[0]:+.3g}, at 1 %: {d[1]:+.3g}", flush=True)


def one_parameter() -> None:
    h = hypothesis("intensity")
    one = dataclasses.replace(h, name="intensity-sl",
                              free_parameters=tuple(r for r in h.free_parameters if r.key == "sl_ref_db"))
    s = FitSettings(n_draws=8, n_starts=1, maxiter=30)
    data = _study1(simulate_trials(one, 8, np.random.default_rng([5, 5]), values={"sl_ref_db": 12.0}))
    t = time.perf_counter()
    fit = fit_hypothesis(one, data, settings=s)
    at_truth = participant_loglik(one, data, [12.0], settings=s).sum()
    print(f"sl_ref_db alone, truth 12 dB, start 16.3 dB: fitted {fit.params['sl_ref_db']:.2f} dB, log-likelihood "
          f"{fit.loglik:.2f} (truth's {at_truth:.2f}), {fit.n_evaluations} likelihoods, "
          f"{time.perf_counter() - t:.1f} s", flush=True)


def joint() -> None:
    h = hypothesis("intensity")
    data = _study1(simulate_trials(h, 12, np.random.default_rng([777, 1, 0])))
    shipped = dict(zip([r.key for r in h.free_parameters], read_parameters(h.model(), h.free_parameters)))
    t = time.perf_counter()
    fit = fit_hypothesis(h, data, settings=FitSettings(n_draws=32, maxiter=FitSettings().maxiter))
    print(f"intensity, all free parameters, Study 1 N = 12: log-likelihood {fit.loglik:.2f}, "
          f"{fit.n_evaluations} likelihoods, {time.perf_counter() - t:.0f} s")
    for k, v in fit.params.items():
        print(f"  {k:18s} {shipped[k]:.4g} -> {v:.4g}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="skip the joint fit")
    args = ap.parse_args()
    steps()
    one_parameter()
    if not args.quick:
        joint()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
