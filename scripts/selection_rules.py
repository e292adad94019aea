#!/usr/bin/env python
"""How Study 2's selection rule trades the paper's headline against its target-containing tests (a MODEL).

The rules, their settings and the table are in ``vibrofocus_tools.selection_rules`` (its
docstring says what is compared and how); this is their command line:

    python scripts/selection_rules.py [--seeds 800 840] [--plot FILE]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from vibrofocus.simulation.bank import default_bank
from vibrofocus.simulation.hypotheses import hypothesis
from vibrofocus_tools.selection_rules import markdown, plot, points_by_outcome, run, settings


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, nargs=2, default=(800, 840), metavar=("FIRST", "STOP"),
                    help="seeds FIRST..STOP-1 (default 800 840: not the held-out seeds)")
    ap.add_argument("--n", type=int, default=20, help="participants per study")
    ap.add_argument("--plot", type=Path, default=None, help="write the comparison as a PNG here")
    ap.add_argument("--diagnose", action="store_true",
                    help="print the points selected on the trials that hold the target and on the others, and stop")
    ap.add_argument("--only", type=int, default=None, help="run only the first ONLY settings (a quick check)")
    args = ap.parse_args()
    if args.seeds[1] <= args.seeds[0]:
        ap.error(f"--seeds: STOP must be above FIRST, got {args.seeds[0]} {args.seeds[1]}")
    seeds = range(*args.seeds)
    bank = default_bank()
    if args.diagnose:
        print(points_by_outcome(seeds, args.n, bank))
        return
    chosen = settings(hypothesis(None).model())[:args.only]
    rows = []
    for i, s in enumerate(chosen, 1):
        rows.append((s, run(s, seeds, args.n, bank)))
        print(f"[{i}/{len(chosen)}] {s.family}: {s.label}", flush=True)
    print(markdown(rows, seeds, args.n))
    if args.plot:
        plot(rows, args.plot, seeds)
        print(f"wrote {args.plot}")


if __name__ == "__main__":
    main()
