#!/usr/bin/env python
"""Fit the perceptual model of the simulated participants to the paper; write its tables.

Simulated participants are a MODEL, not data. The parameters marked *fitted* in
:class:`vibrofocus.simulation.perception.PerceptualModel` are fitted to the statistics of
de Vlam et al. (IEEE ToH 16(4), 2023) kept in ``simulation/data/psychophysics.json``
(``paper_statistics``): a seeded random search, then a local refinement, each candidate
judged on the same simulated 20-participant studies (seeds 1000.., fast path: feature
bank + vectorized statistics; common random numbers make candidates comparable). One
objective covers every statistic of the paper's Sec. III.B-C: squared log ratios of the
model's median F / chi2 / GG epsilon / reduction of selected points to the paper's,
hinge terms that keep the target-containing Study 2 tests at their null size, squared
shortfalls of the share of studies that reproduce each finding (``PATTERNS``: the
significance of each effect, the sphericity violation, the ranking of the locations, the
post hoc patterns, fewer points with the inverse filter, the target-containing tests not
significant), the ranking of the mean errors (4, 5, 7, 8 best; 1 among the worst), and
a hinge that keeps the share of taps felt at 99 % or more (the paper's participants
answered every tap).

    python scripts/fit_participants.py search --hypothesis NAME --out fit.json   # ~13 min (64 fit studies, three side by side on two cores)
    python scripts/fit_participants.py adopt fit-a.json fit-b.json ... [--out FILE]
    python scripts/fit_participants.py report [--fit fit.json] [--hypothesis NAME]
    python scripts/fit_participants.py table [--seeds 20] [--check]

``search`` fits one hypothesis (``vibrofocus.simulation.hypotheses``; default the default
one) on the feature bank (default the shipped one, whose level rule it records) and prints
each improvement, then the paper beside the best model and the residuals. Every
hypothesis is fitted with the same budget (the defaults of ``--n-eval`` and
``--n-refine``), the same weights and the same seeds, along the same random paths (the
``--rng-seed`` of each stage). ``adopt`` rounds the fits to 3 digits, keeps each hypothesis'
path of lowest loss on the fit seeds, evaluates it on the held-out seeds
(``HELD_OUT_SEEDS``) with the objective of the search (its weights; the standard
objective, ``loss`` without weights, every finding weighted alike, is recorded beside it),
and writes them all to ``simulation/data/hypotheses_fit.json`` (atomically; ``--out`` elsewhere),
with the default hypothesis: the one of lowest held-out loss under the search's objective. Every
fit file is checked (keys, types, finite numbers, known parameters), and a set that does not
cover every hypothesis is refused, before anything is computed or written.
``report`` prints the same for the defaults (or a fit file) on the table's seeds.
``table`` writes the parameters of every hypothesis, the fits' budget, the statement of the
posterior-predictive check and the power table between their markers in
``docs/simulated-participants.md`` (atomically); ``--check`` only compares.

The work is done by :mod:`vibrofocus.simulation.fitting` (objective, search, adopt) and
``vibrofocus_tools.participants_docs`` (the docs' tables); this is their command line.
"""

from __future__ import annotations

import argparse
import functools
import sys
from pathlib import Path

from vibrofocus.errors import VibrofocusError
from vibrofocus.simulation.bank import FeatureBank
from vibrofocus.simulation.fitting import (CENTRAL_WEIGHT_RANGE, FIT_SEEDS, FITS_FILE, HELD_OUT_SEEDS, adopt, fit_model,
                                           read_fit, residuals, search, weight_keys)
from vibrofocus.simulation.hypotheses import hypothesis
from vibrofocus.simulation.paper import seed_statistics
from vibrofocus_tools.participants_docs import table

report = functools.partial(print, flush=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("search", help="fit (random search, then local refinement)")
    s.add_argument("--n-eval", type=int, default=300, help="random candidates")
    s.add_argument("--n-refine", type=int, default=500, help="refinement candidates")
    s.add_argument("--out", type=Path, default=Path("fit_participants.json"))
    s.add_argument("--start", type=Path, default=None,
                   help="start from this fit (JSON written by search; default PerceptualModel()'s defaults)")
    s.add_argument("--rng-seed", type=int, default=2023)
    s.add_argument("--central-weight", type=float, nargs=2, default=None, metavar=("LO", "HI"),
                   help="search the drive cue's weight in [LO, HI] only (default 0 1)")
    s.add_argument("--bank", type=Path, default=None,
                   help="a feature bank built by scripts/build_feature_bank.py (default: the shipped one)")
    s.add_argument("--integration-ms", type=float, default=None,
                   help="the integration window the --bank was built with (PerceptualModel.integration_s)")
    s.add_argument("--weight", action="append", default=[], metavar="KEY=W",
                   help="weight of one matched statistic's term (e.g. s1_interaction_F=3); repeatable")
    s.add_argument("--hypothesis", default=None, help="the hypothesis to fit (default: the default one)")
    s.add_argument("--fit-studies", type=int, default=len(FIT_SEEDS),
                   help=f"judge candidates on the first N fit seeds (default all {len(FIT_SEEDS)})")
    s.add_argument("--unfused", action="store_true",
                   help="search the unfused percepts too (off in the shipped fits; docs/simulated-participants.md, "
                        "\"Unfused percepts: three fits, not adopted\")")
    s.add_argument("--aware", action="store_true",
                   help="search PerceptualModel.conflict_awareness too (the selection's width reads the trial's own "
                        "cue discrepancy), with the conflict gain drawn in 0-4")
    a = sub.add_parser("adopt", help="ship fits: held-out losses, the default hypothesis, hypotheses_fit.json")
    a.add_argument("fits", type=Path, nargs="+",
                   help="fit files written by search, one or more random paths per hypothesis (the same for each)")
    a.add_argument("--version", action="append", default=[], metavar="NAME=V",
                   help="version of a hypothesis' fitted model (bump it when its answers change); repeatable")
    a.add_argument("--fit-studies", type=int, default=None,
                   help="the fit seeds the paths were judged on: the first N (default: those the fit files record)")
    a.add_argument("--out", type=Path, default=FITS_FILE,
                   help="where to write the fits (default: the shipped simulation/data/hypotheses_fit.json)")
    r = sub.add_parser("report", help="the paper beside the model, with residuals")
    r.add_argument("--fit", type=Path, default=None, help="a fit file (default: the hypothesis' fitted model)")
    r.add_argument("--hypothesis", default=None, help="the hypothesis (default: the default one)")
    r.add_argument("--seeds", type=int, default=20)
    t = sub.add_parser("table", help="write the tables of docs/simulated-participants.md")
    t.add_argument("--seeds", type=int, default=20)
    t.add_argument("--check", action="store_true", help="only compare; exit 1 if a page is out of date")
    args = ap.parse_args()
    try:
        return run(ap, args)
    except VibrofocusError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


def run(ap: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    """The subcommand of ``args``."""
    if args.cmd == "search":
        weights = {}
        for item in args.weight:
            key, _, value = item.partition("=")
            known = weight_keys()
            if key not in known:
                ap.error(f"--weight {item}: unknown statistic (one of {', '.join(known)})")
            weights[key] = float(value)
        central_range = tuple(sorted(args.central_weight)) if args.central_weight else CENTRAL_WEIGHT_RANGE
        bank = FeatureBank.load(args.bank) if args.bank else None
        window = None if args.integration_ms is None else args.integration_ms * 1e-3
        best = search(args.n_eval, args.n_refine, args.out, args.start, args.rng_seed, weights, central_range,
                      bank, window, args.hypothesis, args.unfused, args.aware, report=report,
                      fit_seeds=FIT_SEEDS[:args.fit_studies])
        for title, seeds in ((f"fit seeds {FIT_SEEDS.start}-{FIT_SEEDS.stop - 1}", FIT_SEEDS), ("table seeds 0-19", range(20)),
                             (f"held-out seeds {HELD_OUT_SEEDS.start}-{HELD_OUT_SEEDS.stop - 1}", HELD_OUT_SEEDS)):
            print(f"\n{title}:\n" + residuals(seed_statistics(best, seeds, bank=bank, hypothesis=args.hypothesis)))
        return 0
    if args.cmd == "adopt":
        adopt(args.fits, args.version, out=args.out, report=report,
              fit_seeds=None if args.fit_studies is None else FIT_SEEDS[:args.fit_studies])
        return 0
    if args.cmd == "report":
        model = fit_model(read_fit(args.fit)) if args.fit is not None else hypothesis(args.hypothesis).model()
        print(residuals(seed_statistics(model, range(args.seeds), hypothesis=args.hypothesis)))
        return 0
    return table(args.seeds, args.check)


if __name__ == "__main__":
    sys.exit(main())
