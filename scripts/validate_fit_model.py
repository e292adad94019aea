"""Leave-one-point-out validation of the fitted skin model on simulated forearms.

For each simulated participant (seed) of a skin (default ``nominal``, the layered arm),
calibrate the reference array with the default (``mimo``) method, the simulator's
vibrometer noise and dropouts on. For each location in turn, fit the skin model to the
other twelve points (``fit_model(cal, law=..., points=...)``; the layered law by
default) and predict H at the left-out one:

- ``H error``: relative error of the predicted H at the held-out point against the
  arm's true H, ``||H_pred - H_true|| / ||H_true||`` over the actuators and the tap's
  band (where the base tap's spectrum is within 20 dB of its peak, 44-497 Hz for the
  1 ms Ricker); beside it the same error of the calibration's own measurement there
  (what the fit would have had);
- a tap designed from the fitted model at the held-out point (``render(method, fit,
  ...)``) and one designed from the true H (``render(method, forearm, ...)``), both on
  the true arm's design window and played on the noise-free arm
  (``play_and_record``): fidelity and peak contrast against the other locations of
  the recordings.

Prints a Markdown table: per participant the median over the nine held-out locations,
and the median over all; ``--write`` puts it between the ``fit-model-loo`` markers of
docs/usage.md and docs/method.md. Run: ``python scripts/validate_fit_model.py [--seeds 0 1 2]
[--skin nominal] [--law layered] [--write]`` (about 15 minutes on one core).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from vibrofocus import ArrayLayout
from vibrofocus.calibration import calibrate, fit_model
from vibrofocus.demo.trust import tap_band
from vibrofocus.rendering import focus_metrics, render
from vibrofocus.rigs import SimulatedForearm

from vibrofocus_tools.markers import write_between_markers

METHODS = ("inverse", "contrast")
ROOT = Path(__file__).resolve().parent.parent
PAGES = (ROOT / "docs" / "usage.md", ROOT / "docs" / "method.md")
MARKER = "fit-model-loo"


def relative_error(estimate: np.ndarray, truth: np.ndarray) -> float:
    """``||estimate - truth|| / ||truth||`` (Frobenius over every axis)."""
    return float(np.linalg.norm(estimate - truth) / np.linalg.norm(truth))


def played_metrics(rendering, arm: SimulatedForearm, layout: ArrayLayout) -> dict[str, float]:
    """Focus metrics of a rendering's drives played on the (noise-free) arm."""
    rec = arm.play_and_record(rendering.drives, layout.points_xy, tail_s=0.0)
    return focus_metrics(rec, rendering.target_index, rendering.desired, arm.fs, sigma=rendering.sigma,
                         drives=rendering.drives, compare_indices=np.arange(layout.n_locations))


def validate_participant(seed: int, skin: str = "nominal", law: str = "layered", methods=METHODS,
                         locations=None) -> list[dict]:
    """One row per held-out location and method (see the module docstring)."""
    layout = ArrayLayout.reference()
    cal = calibrate(SimulatedForearm(seed=seed, layout=layout, skin=skin), participant_id=f"S{seed:02d}")
    arm = SimulatedForearm(seed=seed, layout=layout, noise_m=0.0, dropout_rate=0.0, skin=skin)
    n = arm.design_window()
    lo, hi = tap_band()
    band = (cal.freqs >= lo) & (cal.freqs <= hi)
    f = cal.freqs[band]
    locations = range(layout.n_locations) if locations is None else locations
    rows = []
    for p in locations:
        fit = fit_model(cal, law=law, points=np.delete(np.arange(layout.n_points), p))
        truth = arm.transfer(layout.points_xy[p:p + 1], f)
        h_err = relative_error(fit.transfer(layout.points_xy[p:p + 1], f), truth)
        h_meas = relative_error(cal.H[band][:, p:p + 1], truth)
        for method in methods:
            from_fit = played_metrics(render(method, fit, arm.fs, layout, p + 1, n_samples=n), arm, layout)
            from_true = played_metrics(render(method, arm, arm.fs, layout, p + 1, n_samples=n), arm, layout)
            rows.append({"seed": seed, "location": p + 1, "method": method, "h_error": h_err,
                         "h_error_measured": h_meas,
                         **{f"{k}_fit": from_fit[k] for k in ("fidelity", "contrast_db")},
                         **{f"{k}_true": from_true[k] for k in ("fidelity", "contrast_db")}})
        print(f"seed {seed} location {p + 1}: H error {h_err:.3%}", file=sys.stderr, flush=True)
    return rows


def table(rows: list[dict]) -> str:
    """Markdown table of medians per participant and method, then over all."""
    head = ("| participant | method | H error, held-out point (fit) | H error there (measured) | "
            "fidelity fit / true | contrast dB fit / true |")
    out = [head, "|---|---|---|---|---|---|"]
    seeds = sorted({r["seed"] for r in rows})
    for seed in [*seeds, None]:
        for method in dict.fromkeys(r["method"] for r in rows):
            sel = [r for r in rows if r["method"] == method and (seed is None or r["seed"] == seed)]
            med = {k: float(np.median([r[k] for r in sel])) for k in sel[0] if k not in ("seed", "location", "method")}
            who = "all (median)" if seed is None else f"seed {seed}"
            out.append(f"| {who} | {method} | {med['h_error']:.2%} | {med['h_error_measured']:.2%} | "
                       f"{med['fidelity_fit']:.3f} / {med['fidelity_true']:.3f} | "
                       f"{med['contrast_db_fit']:.1f} / {med['contrast_db_true']:.1f} |")
    return "\n".join(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--skin", default="nominal")
    parser.add_argument("--law", default="layered")
    parser.add_argument("--write", action="store_true", help="write the table into docs/usage.md and docs/method.md")
    args = parser.parse_args()
    t0 = time.perf_counter()
    rows = [row for seed in args.seeds for row in validate_participant(seed, args.skin, args.law)]
    block = table(rows)
    print(block)
    worst = max(rows, key=lambda r: r["h_error"])
    gap = [r["contrast_db_fit"] - r["contrast_db_true"] for r in rows]
    print(f"\nlargest held-out H error {worst['h_error']:.2%} (seed {worst['seed']}, location {worst['location']}); "
          f"contrast fit - true: median {np.median(gap):+.2f} dB, range {min(gap):+.2f} to {max(gap):+.2f} dB; "
          f"{len(rows) // len(METHODS)} fits in {time.perf_counter() - t0:.0f} s")
    if args.write:
        for page in PAGES:
            write_between_markers(page, MARKER, block)


if __name__ == "__main__":
    main()
