#!/usr/bin/env python
"""Model recovery (and parameter recovery) of the simulated participants' hypotheses.

Simulates K studies of N participants on the paper's design under each registered
hypothesis, fits every hypothesis to each by maximum marginal likelihood, chooses by
leave-one-participant-out ELPD, and prints the confusion matrix (rows: the true
hypothesis, columns: the chosen one) as markdown; with --write, into
docs/fitting-hypotheses.md. --parameters adds the recovery of each fitted parameter.
Package functions: vibrofocus.simulation.fitting.model_recovery / parameter_recovery.

    .venv/bin/python scripts/model_recovery.py --studies 30            # the docs' table
    .venv/bin/python scripts/model_recovery.py --studies 2 --study1-only --no-dask
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from vibrofocus.simulation import available_hypotheses, hypothesis
from vibrofocus.simulation.fitting import FitSettings, model_recovery, parameter_recovery
from vibrofocus_tools.markers import ROOT, write_between_markers


def confusion_markdown(rec: dict, note: str) -> str:
    names = rec["names"]
    rows = ["| true \\ chosen | " + " | ".join(names) + " | correct |", "|---" * (len(names) + 2) + "|"]
    for name, counts in zip(names, rec["confusion"]):
        total = sum(counts)
        share = counts[names.index(name)] / total if total else float("nan")
        rows.append(f"| {name} | " + " | ".join(str(c) for c in counts) + f" | {share:.0%} |")
    return "\n".join(rows) + f"\n\n{note}"


def parameters_markdown(results: dict) -> str:
    rows = ["| hypothesis | parameter | range | bias | RMSE | correlation | recovered |", "|---" * 7 + "|"]
    for name, params in results.items():
        for key, r in params.items():
            rows.append(f"| {name} | {key} | {r['range'][0]:.4g} to {r['range'][1]:.4g} | {r['bias']:.3g} | "
                        f"{r['rmse']:.3g} | {r['correlation']:.2f} | {'yes' if r['recovered'] else 'NO'} |")
    return "\n".join(rows)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--studies", type=int, default=30, help="studies per true hypothesis (default 30)")
    ap.add_argument("--participants", type=int, default=12, help="participants per study (default 12)")
    ap.add_argument("--hypotheses", default="all", help="comma separated, or all (default)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--draws", type=int, default=32, help="population draws per likelihood (default 32)")
    ap.add_argument("--study1-only", action="store_true", help="fit Study 1's answers only (fast)")
    ap.add_argument("--parameters", type=int, default=0, metavar="K",
                    help="also recover each free parameter from K studies per hypothesis")
    ap.add_argument("--scheduler", help="Dask scheduler address (default a LocalCluster)")
    ap.add_argument("--workers", type=int, help="LocalCluster workers")
    ap.add_argument("--no-dask", action="store_true", help="run in this process")
    ap.add_argument("--write", action="store_true", help="write the tables into docs/fitting-hypotheses.md")
    args = ap.parse_args()
    names = available_hypotheses() if args.hypotheses == "all" else tuple(args.hypotheses.split(","))
    settings = FitSettings(n_draws=args.draws, seed=args.seed)
    cluster = {"local": args.no_dask, "scheduler": args.scheduler, "n_workers": args.workers}
    t0 = time.perf_counter()
    rec = model_recovery(names, n_studies=args.studies, n_participants=args.participants, seed=args.seed,
                         settings=settings, study1_only=args.study1_only, **cluster)
    elapsed = time.perf_counter() - t0
    note = (f"{args.studies} simulated studies of N = {args.participants} per true hypothesis (a MODEL, not data), "
            f"{'Study 1 only' if args.study1_only else 'Study 1 and Study 2'}, {args.draws} population draws, "
            f"seed {args.seed}; {elapsed:.0f} s. Command: `python scripts/model_recovery.py --studies {args.studies}"
            f"{' --study1-only' if args.study1_only else ''} --draws {args.draws} --seed {args.seed}`.")
    block = confusion_markdown(rec, note)
    print(block)
    blocks = {"model-recovery": block}
    if args.parameters:
        free = {n: parameter_recovery(n, n_studies=args.parameters, n_participants=args.participants, seed=args.seed,
                                      settings=settings) for n in names if hypothesis(n).free_parameters}
        blocks["parameter-recovery"] = parameters_markdown(free) if free else "No hypothesis has free parameters."
        print("\n" + blocks["parameter-recovery"])
        unrecovered = [f"{n}: {k}" for n, p in free.items() for k, r in p.items() if not r["recovered"]]
        if unrecovered:
            print("NOT RECOVERED (fix as assumptions): " + "; ".join(unrecovered))
    if args.write:
        for name, text in blocks.items():
            write_between_markers(ROOT / "docs" / "fitting-hypotheses.md", name, text)
    correct = np.trace(np.array(rec["confusion"])) / np.sum(rec["confusion"])
    print(f"true hypothesis chosen in {correct:.0%} of studies")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
