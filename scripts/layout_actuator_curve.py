"""How the worst target's peak contrast grows with the number of actuators, from ``design-layout``'s search.

For each number of actuators (default 4, 6, 8), search their positions in the default region
(90 x 90 mm around the paper's grid, 15 mm candidate pitch, 20 mm least spacing) for the
paper's nine targets on the nominal skin at the 10 V limit with the inverse filter
(:func:`vibrofocus.workflows.design_layout`), and print the worst and mean peak contrast
against the other targets, the worst fidelity and tap, beside the paper's 2 x 2 at 45 mm.

``--write`` puts the table between the ``layout-actuators`` markers of docs/design-layout.md.
Run: ``python scripts/layout_actuator_curve.py [--actuators 4 6 8] [--workers 2] [--write]``
(about 10 minutes on one core; ``--workers`` fans the designs out on a LocalCluster).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from vibrofocus.placement import PlacementSettings
from vibrofocus.workflows import design_layout

from vibrofocus_tools.markers import write_between_markers

PAGE = Path(__file__).resolve().parent.parent / "docs" / "design-layout.md"
MARKER = "layout-actuators"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--actuators", type=int, nargs="+", default=[4, 6, 8])
    ap.add_argument("--workers", type=int, default=None, help="LocalCluster workers (default: this process)")
    ap.add_argument("--write", action="store_true", help="write the table into docs/design-layout.md")
    args = ap.parse_args()
    rows = ["| actuators | worst target, dB | mean, dB | worst fidelity | smallest tap at 10 V, µm | "
            "layouts scored | search s |", "|---|---|---|---|---|---|---|"]
    paper = None
    for n in args.actuators:
        t = time.perf_counter()
        done = design_layout(PlacementSettings(n_actuators=n), local=args.workers is None, workers=args.workers)
        s, paper = done.result.score, done.result.paper
        rows.append(f"| {n} | {s.worst_db:+.2f} | {s.mean_db:+.2f} | {s.fidelity.min():.3f} | "
                    f"{s.target_peak_um.min():.2f} | {done.result.n_layouts} | {time.perf_counter() - t:.0f} |")
        print(rows[-1], flush=True)
    rows.append(f"| paper's 2x2 at 45 mm | {paper.worst_db:+.2f} | {paper.mean_db:+.2f} | {paper.fidelity.min():.3f} "
                f"| {paper.target_peak_um.min():.2f} | | |")
    block = "\n".join(rows)
    print(block)
    if args.write:
        write_between_markers(PAGE, MARKER, block)


if __name__ == "__main__":
    main()
