#!/usr/bin/env python
"""Write the "measured, no refit" table of docs/simulated-participants.md (Hypotheses).

Every registered hypothesis simulates the same 20 studies of 20 participants (held-out
seeds 500-519, the seeds of scripts/check_findings.py) on a feature bank (default the
shipped one), with the fast path and the vectorized statistics, and the table gives per
hypothesis the mean Study 1 error per method, the share of studies in which the inverse
filter's mean error is below funneling's, and the shares in which the method tests and the
paper's directional claims are significant. A model, not data.

    .venv/bin/python scripts/hypotheses_table.py                 # rewrite the table in the doc
    .venv/bin/python scripts/hypotheses_table.py --bank B.npz --print
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from vibrofocus.simulation.bank import FeatureBank, default_bank, simulate_cell_means
from vibrofocus.simulation.hypotheses import available_hypotheses, hypothesis
from vibrofocus.simulation.power import study_statistics

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "docs" / "simulated-participants.md"
SEEDS = range(500, 520)
N = 20


def row(name: str, bank: FeatureBank) -> str:
    stats = []
    for seed in SEEDS:
        st = study_statistics(simulate_cell_means(N, np.random.default_rng([seed, N]), bank=bank, hypothesis=name))
        stats.append(st)
    err = np.array([s["s1_error_by_method"] for s in stats])
    share = lambda key: f"{np.mean([s[key] < 0.05 for s in stats]):.0%}"  # noqa: E731
    lower = f"{np.mean(err[:, 1] < err[:, 0]):.0%}"
    red = np.median([s["s2_reduction"] for s in stats])
    return (f"| `{name}` | {' / '.join(f'{v:.2f}' for v in err.mean(axis=0))} | {lower} | {share('s1_method_p')} | "
            f"{share('s1_inverse_below_p')} | {share('s2_method_p')} | {share('s2_inverse_fewer_p')} | {red:.0%} |")


def markdown(bank: FeatureBank) -> str:
    lines = [f"{len(SEEDS)} studies of {N} participants (seeds {SEEDS[0]}-{SEEDS[-1]}), feature bank of "
             f"{bank.n_forearms} forearms at {bank.levels} levels; `scripts/hypotheses_table.py`. Labels: "
             + "; ".join(f"{hypothesis(h).label()}" for h in available_hypotheses()) + ".", "",
             "| hypothesis | Study 1 error, funneling / inverse / combination (mm) | inverse below funneling "
             "| Study 1 method (RM-ANOVA) | inverse below funneling (Bonferroni) | Study 2 method (Friedman) "
             "| fewer points with the inverse (Bonferroni) | Study 2 reduction (median) |",
             "|---|---|---:|---:|---:|---:|---:|---:|"]
    lines += [row(name, bank) for name in available_hypotheses()]
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bank", type=Path, help="feature bank (.npz; default the shipped one)")
    ap.add_argument("--print", action="store_true", help="only print the table")
    args = ap.parse_args()
    bank = FeatureBank.load(args.bank) if args.bank else default_bank()
    table = markdown(bank)
    print(table)
    if not args.print:
        from _markers import write_between_markers

        write_between_markers(PAGE, "hypotheses-measured", table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
