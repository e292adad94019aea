"""Compare the rendering candidates at equal peak drive on simulated participants.

For each SimulatedForearm seed and each location, design every candidate from the
participant's true transfer, scale it to the drive limit (every method plays at the same
peak drive), and report the medians over locations and participants of: fidelity (to the
band-limited Ricker tap), peak contrast against the other locations, peak contrast
against every calibrated point, energy contrast against the other locations beside its
exact-tap bound, the peak bound (the most peak contrast against every calibrated point any
drive reaches at the pseudo-inverse's fidelity: a minimax design per participant and
location), peak contrast against a dense skin grid (model-predicted), the target's peak
displacement and the peak drive. Prints a markdown table.

Usage: python scripts/compare_render_defaults.py [--seeds 0 1 2 3] [--n 4096] [--write]

``--write`` also writes the table into docs/design-choices.md between its ``compare-table`` markers
(atomically).
"""

from __future__ import annotations

import argparse
import time
import warnings

from pathlib import Path

import numpy as np

from vibrofocus import SimulatedForearm, render
from vibrofocus.io import write_text
from vibrofocus.demo import peak_bound
from vibrofocus.rendering.inverse import predict_response
from vibrofocus.rendering.transfer import as_transfer_matrix

CANDIDATES = [
    ("inverse, guard_weight 0.1", "inverse", {"guard_weight": 0.1}),
    ("inverse, guard_weight 1 (paper; default)", "inverse", {"guard_weight": 1.0}),
    ("contrast (ACC, all points)", "contrast", {}),
    ("contrast (ACC, locations)", "contrast", {"control": "locations"}),
    ("constrained, weight 0.3", "constrained", {"contrast_weight": 0.3}),
    ("constrained, weight 1", "constrained", {"contrast_weight": 1.0}),
    ("constrained, weight 10", "constrained", {"contrast_weight": 10.0}),
    ("funneling", "funneling", {}),
    ("combination", "combination", {}),
    ("time reversal", "time_reversal", {}),
]
START, END = "<!-- compare-table:start -->", "<!-- compare-table:end -->"
COLUMNS = ("fidelity", "contrast_db", "contrast_all_db", "energy_contrast_db", "bound_db", "contrast_field_db",
           "target_peak_m", "peak_drive_v")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument("--n", type=int, default=4096, help="design window, samples")
    parser.add_argument("--grid-mm", type=float, default=4.0, help="pitch of the dense skin grid, mm")
    parser.add_argument("--write", action="store_true", help="write the table into docs/design-choices.md")
    args = parser.parse_args()
    start = time.perf_counter()
    results: dict[str, list[dict]] = {label: [] for label, _, _ in CANDIDATES}
    peak_bounds = []
    for seed in args.seeds:
        rig = SimulatedForearm(seed=seed, noise_m=0.0, dropout_rate=0.0)
        layout, fs = rig.layout, rig.fs
        freqs = np.fft.rfftfreq(args.n, 1 / fs)
        H = rig.transfer(layout.points_xy, freqs)
        # Dense grid over the skin under and around the array (actuator footprints included).
        half = np.abs(layout.actuators_xy).max() + 0.01
        axis = np.arange(-half, half + 1e-9, args.grid_mm * 1e-3)
        grid = np.stack(np.meshgrid(axis, axis), -1).reshape(-1, 2)
        H_grid = rig.transfer(grid, freqs)
        tm = as_transfer_matrix(H, fs, layout, n_samples=args.n)
        for loc in layout.location_numbers:
            peak_bounds.append(peak_bound(tm, loc))
            target_xy = layout.locations_xy[layout.location_index(loc)]
            far = np.linalg.norm(grid - target_xy, axis=1) > 5e-3  # the tap's own spot is not "elsewhere"
            for label, method, options in CANDIDATES:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    r = render(method, H, fs, layout, loc, limit_v=rig.limits.peak_v, scale_to_limit=True, **options)
                field = predict_response(H_grid[:, far], r.drives)
                m = r.metrics(against="reference", field=field)
                results[label].append(m)
    elapsed = time.perf_counter() - start
    print(f"Medians over {len(args.seeds)} simulated participants (seeds {', '.join(map(str, args.seeds))}) x "
          f"9 locations; designs from each participant's true transfer, all scaled to the same peak drive "
          f"({SimulatedForearm().limits.peak_v:g} V). Contrasts in dB: peak |u| at the target over the largest "
          f"peak at the other locations / at every calibrated point / on a {args.grid_mm:g} mm skin grid (points "
          "farther than 5 mm from the target); energy contrast against the other locations beside its exact-tap "
          "bound (no drive that puts the tap at the target does better; designs that give up fidelity change the "
          "target's waveform and may pass it). Fidelity is against the tap at t0 (funneling and combination "
          "arrive late and score near 0 there). Peak bound: the most peak contrast against every calibrated point "
          "that any drive reaches at the pseudo-inverse's fidelity (minimax), beside the contrast vs all points.\n")
    header = ["candidate", "fidelity to the tap at t0", "contrast vs locations dB", "contrast vs all points dB", "energy contrast dB",
              "bound dB", "peak bound dB", "contrast vs skin grid dB", "target peak µm", "peak drive V"]
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(["---"] + ["---:"] * (len(header) - 1)) + "|"]
    for label, rows in results.items():
        med = {k: float(np.median([row[k] for row in rows])) for k in COLUMNS}
        lines.append(f"| {label} | {med['fidelity']:.2f} | {med['contrast_db']:.1f} | {med['contrast_all_db']:.1f} | "
                     f"{med['energy_contrast_db']:.1f} | {med['bound_db']:.1f} | {np.median(peak_bounds):.1f} | "
                     f"{med['contrast_field_db']:.1f} | "
                     f"{med['target_peak_m'] * 1e6:.3f} | {med['peak_drive_v']:.1f} |")
    table = "\n".join(lines)
    print(table)
    if args.write:
        readme = Path(__file__).resolve().parent.parent / "docs" / "design-choices.md"
        text = readme.read_text(encoding="utf-8")
        head, rest = text.split(START, 1)
        tail = rest.split(END, 1)[1]
        write_text(readme, f"{head}{START}\n{table}\n{END}{tail}")
        print(f"wrote the table into {readme}")
    print(f"\n({elapsed:.0f} s)")


if __name__ == "__main__":
    main()
