"""Peak contrast of the minimax design against the paper's pseudo-inverse on the nominal
simulated arm, at equal peak drive (10 V).

For each seed and location: the pseudo-inverse ("inverse") and the minimax design (default:
fidelity >= the pseudo-inverse's), both rendered through the arm's true H, or (--calibrated)
through a measured calibration and then played through the true H. Peak contrast: the
target's peak |u| over the largest |u| at any other calibrated point at any time, dB.
Prints the mean fidelity, mean peak contrast and the mean energy-contrast bound.

``--minimax`` names the minimax variants compared, each ``label=option:value,...`` (default
``minimax=``: the method's defaults, robust from a calibration); e.g. ``budget=robust:none`` is
the nominal program with the drive budget (1x the pseudo-inverse's peak drive), ``robust=`` the
robust one (the quiet peak bounded over one standard error of the calibration, from its coherence).

Usage: python scripts/minimax_table.py [--seeds 0 1 2 3] [--locations 1 ... 9] [--calibrated]
       [--minimax budget=robust:none robust=]
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from vibrofocus.rendering import focus_metrics, predict_response, render
from vibrofocus.rigs import SimulatedForearm


def row(design, true_tm):
    """Metrics of a design's drives played through the true H."""
    y = predict_response(true_tm.H, design.drives) if true_tm is not None else design.predicted
    m = focus_metrics(y, design.target_index, design.reference, design.fs, sigma=design.sigma, drives=design.drives)
    return (m["fidelity"], m["contrast_all_db"], m["peak_drive_v"], design.bound_all.bound_db,
            design.wraparound_fraction)


def variant(spec: str) -> tuple[str, dict]:
    """``label=option:value,...`` -> (label, options); ``none`` -> None, numbers -> float."""
    label, _, opts = spec.partition("=")
    options = {}
    for item in filter(None, opts.split(",")):
        key, _, value = item.partition(":")
        options[key] = None if value == "none" else float(value)
    return label, options


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    ap.add_argument("--locations", type=int, nargs="+", default=list(range(1, 10)))
    ap.add_argument("--calibrated", action="store_true")
    ap.add_argument("--minimax", nargs="+", default=["minimax="],
                    help="minimax variants, each label=option:value,... (drive_budget, robust; 'none')")
    args = ap.parse_args()
    variants = dict(variant(s) for s in args.minimax)
    rows = {"inverse": [], **{label: [] for label in variants}}
    times = {label: [] for label in variants}
    for seed in args.seeds:
        rig = SimulatedForearm(seed=seed, skin="nominal")
        tm = rig.transfer_matrix()
        source, true_tm = tm, None
        if args.calibrated:
            from vibrofocus.calibration import calibrate
            from vibrofocus.rendering import TransferMatrix

            cal = calibrate(rig, participant_id=f"minimax-{seed}")
            source = TransferMatrix.from_calibration(cal, tm.n_samples)
            true_tm = tm
        for loc in args.locations:
            for name in rows:
                t = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", UserWarning)
                    # From a calibration, the minimax drives hear its noise floor over the whole
                    # window: the wrap-around check warns (reported) instead of refusing.
                    extra = dict(check_wraparound="warn") if args.calibrated else {}
                    d = render("inverse" if name == "inverse" else "minimax", source, tm.fs, tm.layout, loc,
                               **extra, **variants.get(name, {}))
                if name != "inverse":
                    times[name].append(time.perf_counter() - t)
                rows[name].append((seed, loc, *row(d, true_tm)))
            i = rows["inverse"][-1]
            print(f"seed {seed} loc {loc}: inverse fid {i[2]:.3f} peak {i[3]:6.2f} dB | " + " | ".join(
                f"{name} fid {rows[name][-1][2]:.3f} peak {rows[name][-1][3]:6.2f} dB "
                f"({rows[name][-1][3] - i[3]:+.2f}) drive {rows[name][-1][4]:.2f} V {times[name][-1]:.1f} s"
                for name in variants), flush=True)
    src = "measured calibration, played on the true arm" if args.calibrated else "true H"
    print(f"\nNominal arm, designed from {src}, 10 V peak; peak contrast against every other calibrated point; "
          f"minimax variants {variants}:")
    print("| seed | design | mean fidelity | mean peak contrast | mean delta vs pinv | worst focus delta "
          "| energy bound | design time (mean / max) |")
    print("|---|---|---|---|---|---|---|---|")
    inv = np.array(rows["inverse"], float)
    for seed in [*args.seeds, None]:
        sel = np.ones(len(inv), bool) if seed is None else inv[:, 0] == seed
        name = "all" if seed is None else seed
        print(f"| {name} | pinv | {inv[sel, 2].mean():.3f} | {inv[sel, 3].mean():.2f} dB | | | "
              f"{inv[sel, 5].mean():.2f} dB | |")
        for label in variants:
            mm, tt = np.array(rows[label], float), np.array(times[label])
            delta = mm[sel, 3] - inv[sel, 3]
            print(f"| {name} | {label} | {mm[sel, 2].mean():.3f} | {mm[sel, 3].mean():.2f} dB | "
                  f"{delta.mean():+.2f} dB | {delta.min():+.2f} dB | | {tt[sel].mean():.1f} / {tt[sel].max():.1f} s |")


if __name__ == "__main__":
    main()
