"""Peak contrast of the minimax design against the paper's pseudo-inverse on the nominal
simulated arm (issue 32's done-when), at equal peak drive (10 V).

For each seed and location: the pseudo-inverse ("inverse") and the minimax design (default:
fidelity >= the pseudo-inverse's), both rendered through the arm's true H, or (--calibrated)
through a measured calibration and then played through the true H. Peak contrast: the
target's peak |u| over the largest |u| at any other calibrated point at any time, dB.
Prints the mean fidelity, mean peak contrast and the mean energy-contrast bound.

Usage: python scripts/minimax_table.py [--seeds 0 1 2 3] [--locations 1 ... 9] [--calibrated]
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


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    ap.add_argument("--locations", type=int, nargs="+", default=list(range(1, 10)))
    ap.add_argument("--calibrated", action="store_true")
    ap.add_argument("--drive-budget", default="1", help="minimax drive_budget (times the pseudo-inverse's "
                    "peak drive), or 'none'")
    args = ap.parse_args()
    rows = {"inverse": [], "minimax": []}
    times = []
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
                    if name == "minimax":
                        extra["drive_budget"] = None if args.drive_budget == "none" else float(args.drive_budget)
                    d = render(name, source, tm.fs, tm.layout, loc, **extra)
                if name == "minimax":
                    times.append(time.perf_counter() - t)
                rows[name].append((seed, loc, *row(d, true_tm)))
            i, mm = rows["inverse"][-1], rows["minimax"][-1]
            print(f"seed {seed} loc {loc}: inverse fid {i[2]:.3f} peak {i[3]:6.2f} dB | minimax fid {mm[2]:.3f} "
                  f"peak {mm[3]:6.2f} dB ({mm[3] - i[3]:+.2f}) | drive {mm[4]:.2f} V | energy bound {i[5]:.2f} dB "
                  f"| wrap {mm[6]:.2g} | {times[-1]:.1f} s", flush=True)
    src = "measured calibration, played on the true arm" if args.calibrated else "true H"
    print(f"\nNominal arm, designed from {src}, 10 V peak, minimax drive_budget={args.drive_budget}; "
          "peak contrast against every other calibrated point"
          + ("; designed from the true H with no drive budget, minimax's peak contrast is the peak bound "
             "(the least quiet peak at the pseudo-inverse's fidelity):" if not args.calibrated and
             args.drive_budget == "none" else ":"))
    print("| seed | pinv fidelity | minimax fidelity | pinv peak contrast | minimax peak contrast | mean delta "
          "| worst focus delta | energy bound | minimax design time (mean / max) |")
    print("|---|---|---|---|---|---|---|---|---|")
    inv, mm = np.array(rows["inverse"], float), np.array(rows["minimax"], float)
    tt = np.array(times)
    for seed in [*args.seeds, None]:
        sel = np.ones(len(inv), bool) if seed is None else inv[:, 0] == seed
        delta = mm[sel, 3] - inv[sel, 3]
        print(f"| {'all' if seed is None else seed} | {inv[sel, 2].mean():.3f} | {mm[sel, 2].mean():.3f} | "
              f"{inv[sel, 3].mean():.2f} dB | {mm[sel, 3].mean():.2f} dB | {delta.mean():+.2f} dB | "
              f"{delta.min():+.2f} dB | {inv[sel, 5].mean():.2f} dB | {tt[sel].mean():.1f} / {tt[sel].max():.1f} s |")

if __name__ == "__main__":
    main()
