"""Calibrating fewer points: designs from a calibration of K points against the full one.

For each simulated participant (seed, ``nominal`` skin) and each K, calibrate the
reference array with the default (``mimo``) method, the simulator's vibrometer noise
and dropouts on, measuring K points (``calibrate(..., measure=K)``; K = 13 is the full
calibration) and predicting H at the others from the fitted skin model. At each of the
nine locations, design the inverse filter and the minimax (peak-contrast) drives from
that calibration on the arm's design window (doubled where a calibration's H rings longer) and play them on the noise-free arm
(``play_and_record``): fidelity and peak contrast against the other locations
(``focus_metrics``) of the recordings. Medians over the nine locations and the
participants, per K, beside the full calibration's; the aiming count and the sweep
time saved are those of a single-spot vibrometer (one aim per point, each aim the
plan's takes).

``--write`` puts the table between the ``subset-calibration`` markers of
docs/method.md. Run: ``python scripts/subset_calibration.py [--seeds 0 1 2 3]
[--points 13 9 7 5] [--write]`` (about 20 minutes on one core).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from vibrofocus import ArrayLayout
from vibrofocus.calibration import calibrate, plan_calibration
from vibrofocus.errors import CausalityError
from vibrofocus.rendering import focus_metrics, render
from vibrofocus.rigs import SimulatedForearm

from vibrofocus_tools.markers import write_between_markers

METHODS = ("inverse", "minimax")
PAGE = Path(__file__).resolve().parent.parent / "docs" / "method.md"
MARKER = "subset-calibration"


def played(rendering, arm: SimulatedForearm, layout: ArrayLayout) -> dict[str, float]:
    """Fidelity and peak contrast of a rendering's drives played on the noise-free arm."""
    rec = arm.play_and_record(rendering.drives, layout.points_xy, tail_s=0.0)
    m = focus_metrics(rec, rendering.target_index, rendering.desired, arm.fs, sigma=rendering.sigma,
                      drives=rendering.drives, compare_indices=np.arange(layout.n_locations))
    return {"fidelity": float(m["fidelity"]), "contrast_db": float(m["contrast_db"])}


def design(method: str, cal, arm: SimulatedForearm, layout: ArrayLayout, location: int, n: int):
    """``render`` on window ``n``, doubled (up to twice) when a measured H rings longer than
    the arm's own window allows (the render's CausalityError says so)."""
    for attempt in range(3):
        try:
            return render(method, cal, arm.fs, layout, location, n_samples=n * 2**attempt)
        except CausalityError:
            if attempt == 2:
                raise


def participant_rows(seed: int, ks, methods=METHODS, locations=None) -> list[dict]:
    """One row per K, location and method."""
    layout = ArrayLayout.reference()
    arm = SimulatedForearm(seed=seed, layout=layout, noise_m=0.0, dropout_rate=0.0)
    n = arm.design_window()
    locations = range(1, layout.n_locations + 1) if locations is None else locations
    rows = []
    for k in ks:
        rig = SimulatedForearm(seed=seed, layout=layout)
        cal = calibrate(rig, participant_id=f"S{seed:02d}", measure=None if k == layout.n_points else k)
        for loc in locations:
            for method in methods:
                rows.append({"seed": seed, "k": k, "location": loc, "method": method,
                             **played(design(method, cal, arm, layout, loc, n), arm, layout)})
        print(f"seed {seed} K={k} done", file=sys.stderr, flush=True)
    return rows


def table(rows: list[dict], full_k: int = 13) -> str:
    """Markdown table: per K and method the medians, and the gaps to the full calibration."""
    layout = ArrayLayout.reference()
    plan = plan_calibration(SimulatedForearm(seed=0, layout=layout))
    per_aim_s = plan.takes_per_position * plan.settings.take_s
    out = ["| measured points K | aims (single-spot) | sweep time saved | method | fidelity, median | "
           "fidelity gap to K = 13 | peak contrast dB, median | contrast gap to K = 13, dB |",
           "|---|---|---|---|---|---|---|---|"]
    key = ("seed", "location", "method")
    full = {tuple(r[c] for c in key): r for r in rows if r["k"] == full_k}
    for k in sorted({r["k"] for r in rows}, reverse=True):
        for method in dict.fromkeys(r["method"] for r in rows):
            sel = [r for r in rows if r["k"] == k and r["method"] == method]
            ref = [full[tuple(r[c] for c in key)] for r in sel]
            fid = np.median([r["fidelity"] for r in sel])
            con = np.median([r["contrast_db"] for r in sel])
            d_fid = fid - np.median([r["fidelity"] for r in ref])
            d_con = con - np.median([r["contrast_db"] for r in ref])
            saved = (full_k - k) * per_aim_s
            out.append(f"| {k} | {k} of {full_k} | {saved:.0f} s | {method} | {fid:.3f} | {d_fid:+.3f} | "
                       f"{con:.1f} | {d_con:+.2f} |")
    return "\n".join(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument("--points", type=int, nargs="+", default=[13, 9, 7, 5])
    parser.add_argument("--write", action="store_true", help="write the table into docs/method.md")
    args = parser.parse_args()
    if 13 not in args.points:
        parser.error("--points must include 13 (the full calibration every K is compared with)")
    t0 = time.perf_counter()
    rows = []
    for seed in args.seeds:
        rows += participant_rows(seed, args.points)
        print(table(rows), file=sys.stderr, flush=True)  # what is done so far, should a later seed fail
    block = table(rows)
    print(block)
    print(f"\n{len(args.seeds)} participants x {len(args.points)} calibrations in {time.perf_counter() - t0:.0f} s")
    if args.write:
        write_between_markers(PAGE, MARKER, block)


if __name__ == "__main__":
    main()
