#!/usr/bin/env python
"""Model recovery with the free fit of ``analyze --hypotheses`` on a study plan's Study 1 trials.

For each registered hypothesis H and study j, N simulated participants (a MODEL, not
data) answer a plan's Study 1 blocks under H at its shipped parameters (stream
``default_rng([seed, t, j])``, t the index of H;
:func:`vibrofocus.participant_models.fitting.simulate_plan_trials`). Every hypothesis' default free parameters
are then fitted to those trials and each is scored by leave-one-participant-out ELPD:
:func:`vibrofocus.participant_models.fitting.compare_hypotheses`, the fit of ``vibrofocus
analyze TRIALS --hypotheses`` (without its predictive check), in one process.

The plan: ``--plan paper`` (the paper's Study 1, every method x location three times)
or ``--plan DIR/design.json`` (a ``vibrofocus design-experiment --out DIR`` design;
location answers only). Each study is appended to ``--results`` (JSON lines) as soon as
it is scored; a rerun resumes. Studies run round-robin (study 0 of every hypothesis,
then study 1, ...). The table (confusion matrix, each rate with its exact 95 % interval)
is printed; ``--write`` puts it into docs/fitting-hypotheses.md between the markers
named after the results file.

    vibrofocus design-experiment --out design/ --studies 0
    # studies 25-29 in a second process, their lines then appended to the first file's:
    python scripts/free_fit_recovery.py --plan paper -n 12 --studies 30 --first-study 25 --seed 7301 \
        --results part.jsonl
    python scripts/free_fit_recovery.py --plan design/design.json -n 6 --studies 3 --seed 5501
    python scripts/free_fit_recovery.py --plan paper -n 12 --studies 3 --seed 5102
    # intensity fitted with the parameters level-reliability keeps fixed fixed too:
    python scripts/free_fit_recovery.py --plan design/design.json -n 6 --studies 10 --seed 5501 \
        --fix intensity:sl_ref_db,funneling_exponent,bias_mean_m[1],bias_sd_m
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from vibrofocus.errors import ValidationError
from vibrofocus.participant_models import available_hypotheses, hypotheses_with_fixed, hypothesis
from vibrofocus.participant_models.design import PlanBlock, paper_plan
from vibrofocus.participant_models.fitting import FitSettings, compare_hypotheses, simulate_plan_trials
from vibrofocus.participant_models.fitting.likelihood_fit import SCORE_DRAWS_PER_FIT_DRAW
from vibrofocus_tools.markers import ROOT, write_between_markers
from vibrofocus_tools.recovery_tables import RESULTS, free_fit_block, resumed_studies

DOCS = ROOT / "docs" / "fitting-hypotheses.md"


def read_plan(which: str) -> tuple[PlanBlock, ...]:
    if which == "paper":
        return paper_plan()
    blocks = json.loads(Path(which).read_text(encoding="utf-8"))["blocks"]
    if any(b["response"] != "location" for b in blocks):
        raise SystemExit("this script simulates location answers only")
    return tuple(PlanBlock(tuple(b["methods"]), float(b["level_db"]), tuple(b["locations"]), int(b["repetitions"]),
                           b.get("grid", ""), b["response"]) for b in blocks)


FIXED_WHY = "fixed at the shipped value for this recovery (scripts/free_fit_recovery.py --fix)"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--plan", required=True, help="paper, or a design-experiment design.json")
    ap.add_argument("-n", type=int, default=6, help="participants per study")
    ap.add_argument("--studies", type=int, default=3, help="studies per true hypothesis")
    ap.add_argument("--first-study", type=int, default=0,
                    help="run studies from this index on only (a share of a run for another process or machine; "
                         "its results file's lines after the first join the main one's)")
    ap.add_argument("--seed", type=int, required=True, help="a seed the design did not use")
    ap.add_argument("--draws", type=int, default=16, help="population draws per likelihood (analyze: 32)")
    ap.add_argument("--maxiter", type=int, default=FitSettings().maxiter)
    ap.add_argument("--score-draws", type=int, default=None,
                    help="draws that score the left-out participants (default 8 x --draws; 0: the fit's own draws)")
    ap.add_argument("--truths", default="all", help="true hypotheses to simulate, comma separated (default all)")
    ap.add_argument("--fix", action="append", default=[], metavar="NAME:KEY[,KEY...]",
                    help="fit hypothesis NAME with these free parameters fixed at its shipped values (switching "
                         "part of a hypothesis' freedom off, to see what it does; repeatable)")
    ap.add_argument("--results", type=Path)
    ap.add_argument("--write", action="store_true",
                    help="put the table into docs/fitting-hypotheses.md (between markers named after the results file)")
    args = ap.parse_args()
    names = list(available_hypotheses())
    try:  # a bad --fix fails here, before any study
        hs = hypotheses_with_fixed(args.fix, FIXED_WHY)
    except ValidationError as exc:
        raise SystemExit(str(exc)) from None
    # What --fix took out of each fit: the registered free parameters the fitted one lacks.
    fixed = {h.name: keys for h in hs if (keys := [r.key for r in hypothesis(h.name).free_parameters
                                                   if r not in h.free_parameters])}
    plan = read_plan(args.plan)
    label = "paper" if args.plan == "paper" else "designed"
    if args.score_draws is None:
        args.score_draws = SCORE_DRAWS_PER_FIT_DRAW * args.draws
    path = args.results or RESULTS / (
        f"free-{label}{'-fixed' if fixed else ''}-n{args.n}-d{args.draws}-s{args.score_draws}-seed{args.seed}.jsonl")
    key = {"plan": [vars(b) if hasattr(b, "__dict__") else b.__repr__() for b in plan], "n": args.n,
           "seed": args.seed, "draws": args.draws, "score_draws": args.score_draws, "maxiter": args.maxiter,
           "hypotheses": names, **({"fixed": fixed} if fixed else {})}
    key = json.loads(json.dumps(key, default=str))
    have = {(d["true"], d["study"]) for d in resumed_studies(path, key, create=True)}
    settings = FitSettings(n_draws=args.draws, maxiter=args.maxiter, score_draws=args.score_draws)
    truths = names if args.truths == "all" else args.truths.split(",")
    for j in range(args.first_study, args.studies):
        for t, truth in enumerate(names):
            if (truth, j) in have or truth not in truths:
                continue
            t0 = time.perf_counter()
            data = simulate_plan_trials(truth, plan, args.n, np.random.default_rng([args.seed, t, j]))
            res = compare_hypotheses(data, hs, settings=settings, local=True)
            row = {"true": truth, "study": j, "chosen": res["chosen"],
                   "elpd": {k: v["elpd"] for k, v in res["hypotheses"].items()},
                   "params": {k: v["params"] for k, v in res["hypotheses"].items()},
                   "difference": res["difference"], "difference_se": res["difference_se"],
                   "elapsed_s": round(time.perf_counter() - t0, 1)}
            with path.open("a", encoding="utf-8") as f:
                f.write(json.dumps(row) + "\n")
            print(f"{truth} study {j}: chosen {row['chosen']} (ELPD difference {row['difference']:.1f} "
                  f"+- {row['difference_se']:.1f}; {row['elapsed_s']} s)", flush=True)
    block = free_fit_block(path)
    print(block)
    if args.write:
        # The block's marker is the results file's name: each run has its own table.
        write_between_markers(DOCS, path.stem, block)
        print(f"wrote the {path.stem} table of {DOCS}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
