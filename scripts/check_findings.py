#!/usr/bin/env python
"""Which of the paper's findings simulated 20-participant studies reproduce (a MODEL, not data).

Each study is drawn on the fast path and analysed with pingouin and scipy only,
independently of ``vibrofocus.analysis`` and of the statistics the fit optimizes
(``vibrofocus_tools.findings``). The findings are those of de Vlam et al. (IEEE ToH 16(4),
2023, doi:10.1109/TOH.2023.3270362), Sec. III.B-C:

    python scripts/check_findings.py [--seeds 600 640] [--hypothesis NAME]

prints, per finding, in how many seeds it holds, and the median reduction of selected
points (inverse vs funneling), under one hypothesis of how the participants read the felt
field (default the default one, with its fitted parameters). ``--against-baseline`` adds, per
finding, its count under the issue's baseline (the participants of commit c313a27, the same
seeds: ``scripts/fits/baseline-c313a27.json``) and an exact McNemar test of the paired
difference, so that a shortfall of a few studies can be told from chance. The default seeds are the
fit's held-out seeds (``vibrofocus.simulation.fitting.HELD_OUT_SEEDS``); the fit uses seeds from 1000
(``FIT_SEEDS``). ``scripts/hypotheses_table.py`` prints the same check for every
hypothesis.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from vibrofocus.errors import VibrofocusError
from vibrofocus.simulation.bank import FeatureBank, default_bank
from vibrofocus.simulation.fitting import HELD_OUT_SEEDS, fit_model, read_fit
from vibrofocus.simulation.hypotheses import hypothesis
from vibrofocus.simulation.perception import MODEL_VERSION
from vibrofocus_tools.baseline import baseline_outcomes
from vibrofocus_tools.findings import findings_table, held_out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, nargs=2, default=(HELD_OUT_SEEDS.start, HELD_OUT_SEEDS.stop),
                    metavar=("FIRST", "STOP"), help="seeds FIRST..STOP-1 (default: the fit's held-out seeds)")
    ap.add_argument("--n", type=int, default=20, help="participants per study")
    ap.add_argument("--fit", type=Path, default=None,
                    help="a fit file written by scripts/fit_participants.py search (default: the model's defaults)")
    ap.add_argument("--bank", type=Path, default=None,
                    help="a feature bank built by scripts/build_feature_bank.py (default: the shipped one)")
    ap.add_argument("--hypothesis", default=None,
                    help="how the participants read the felt field (default: the default hypothesis)")
    ap.add_argument("--against-baseline", action="store_true",
                    help="add the issue's baseline (c313a27's participants, the same seeds) and an exact McNemar "
                         "test of the paired difference per finding")
    args = ap.parse_args()
    seeds = range(*args.seeds)
    base = None
    if args.against_baseline:
        try:
            base = baseline_outcomes(seeds)
        except ValueError as exc:
            ap.error(f"--against-baseline: {exc}")
    try:
        model = fit_model(read_fit(args.fit)) if args.fit else None
    except VibrofocusError as exc:
        ap.error(f"--fit: {exc}")
    bank = FeatureBank.load(args.bank) if args.bank else default_bank()
    res = held_out(seeds, args.n, bank, args.hypothesis, model)
    label = hypothesis(args.hypothesis).label()
    if args.fit:  # not the shipped fit: say whose parameters these are
        label = (f"simulated participants: model v{MODEL_VERSION}, hypothesis {hypothesis(args.hypothesis).name} with "
                 f"the parameters of {args.fit.name}, not data")
    print(f"{label}: {len(res)} studies of {args.n}, seeds {seeds.start}-{seeds.stop - 1}")
    print(findings_table(res, args.n, base))


if __name__ == "__main__":
    main()
