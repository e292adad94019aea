#!/usr/bin/env python
"""Minimax taps at off-grid targets from a fitted skin model, against the true-H design.

The simulated ``nominal`` arm (participant ``--seed``) is calibrated with the default
(mimo, noisy) calibration and fitted with the layered law (its own family). At 8 targets
between the reference grid's locations, the minimax design is made three ways: from the
arm's true H, from the fit with the nominal program (``robust=None``), and from the fit
with the robust program (the default: the fit's standard errors propagated to ``H``),
each through ``render_fitted`` (as ``vibrofocus render`` designs).
Every design is played through the true H; the table gives its peak contrast over all
other calibrated points (``contrast_all_db``), its fidelity, and the loss against the
true-H design.

    python scripts/robust_fit_minimax.py [--seed 0] [--cache /tmp/fit.nc] [--targets 0 1 ...]
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

from vibrofocus.calibration import calibrate, fit_model, load_calibration, save_calibration
from vibrofocus.rendering import Minimax, TransferMatrix, focus_metrics, predict_response, render_fitted
from vibrofocus.rigs import SimulatedForearm

#: Off-grid targets, m: the midpoints between the reference grid's locations (10 mm pitch).
TARGETS = np.array([(-5, 5), (5, 5), (-5, -5), (5, -5), (0, 5), (0, -5), (-5, 0), (5, 0)], float) * 1e-3


def fitted_calibration(seed: int, cache: Path | None):
    """The arm's calibration with its layered fit, from ``cache`` when it holds one."""
    if cache is not None and cache.exists():
        return load_calibration(cache)
    cal = calibrate(SimulatedForearm(seed=seed), participant_id=f"S{seed:02d}")
    cal.fit = fit_model(cal)
    if cache is not None:
        save_calibration(cal, cache)
    return cal


def played(design, arm, n: int) -> tuple[float, float]:
    """(fidelity, peak contrast over all points, dB) of a design played through the true H."""
    true_tm = TransferMatrix.from_model(arm, design.layout, design.fs, n)
    y = predict_response(true_tm.H, design.drives)
    m = focus_metrics(y, design.target_index, design.reference, design.fs, sigma=design.sigma)
    return m["fidelity"], m["contrast_all_db"]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cache", type=Path, help="calibration file with its fit, reused when present")
    ap.add_argument("--targets", type=int, nargs="+", default=list(range(len(TARGETS))),
                    help="indices of the targets to design (default all 8)")
    args = ap.parse_args()
    cal = fitted_calibration(args.seed, args.cache)
    fit = cal.fit
    print(f"fit: {fit!r}; largest residual {np.nanmax(fit.residual):.3g}")
    arm = SimulatedForearm(seed=args.seed, noise_m=0.0, dropout_rate=0.0)
    n = arm.design_window()
    methods = {"true H": (arm, Minimax()), "fit, nominal": (fit, Minimax(robust=None)), "fit, robust": (fit, Minimax())}
    print("| target mm | " + " | ".join(f"{k} dB (fid)" for k in methods) + " | nominal loss dB | robust loss dB |")
    print("|---" * (len(methods) + 3) + "|")
    losses = {k: [] for k in methods}
    for xy in TARGETS[args.targets]:
        cells = {}
        for label, (model, method) in methods.items():
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                d = render_fitted(method, model, cal.fs, cal.layout, target_xy=xy, n_samples=n)
            cells[label] = (*played(d, arm, n), time.perf_counter() - t0)
        ref = cells["true H"][1]
        for k in methods:
            losses[k].append(ref - cells[k][1])
        print(f"| ({xy[0] * 1e3:g}, {xy[1] * 1e3:g}) | " + " | ".join(
            f"{c:.2f} ({f:.3f}, {s:.0f} s)" for f, c, s in cells.values())
              + f" | {losses['fit, nominal'][-1]:+.2f} | {losses['fit, robust'][-1]:+.2f} |", flush=True)
    for k in ("fit, nominal", "fit, robust"):
        loss = np.array(losses[k])
        print(f"{k}: loss against the true-H design, dB: mean {loss.mean():+.2f}, largest {loss.max():+.2f}")


if __name__ == "__main__":
    main()
