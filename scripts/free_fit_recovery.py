#!/usr/bin/env python
"""Model recovery with the free fit of ``analyze --hypotheses`` on a study plan's Study 1 trials.

For each registered hypothesis H and study j, N simulated participants (a MODEL, not
data) answer a plan's Study 1 blocks under H at its shipped parameters (stream
``default_rng([seed, t, j])``, t the index of H): each participant a forearm of the
shipped bank, traits from H's population, answers from
:func:`vibrofocus.simulation.perception.draw_answers` (the sampler of ``simulate-study``)
among each block's locations, at its level. Every hypothesis' default free parameters
are then fitted to those trials and each is scored by leave-one-participant-out ELPD:
:func:`vibrofocus.simulation.fitting.compare_hypotheses`, the fit of ``vibrofocus
analyze TRIALS --hypotheses`` (without its predictive check), in one process.

The plan: ``--plan paper`` (the paper's Study 1, every method x location three times)
or ``--plan DIR/design.json`` (a ``vibrofocus design-experiment --out DIR`` design;
location answers only). Each study is appended to ``--results`` (JSON lines) as soon as
it is scored; a rerun resumes. Studies run round-robin (study 0 of every hypothesis,
then study 1, ...).

    vibrofocus design-experiment --out design/ --studies 0
    python scripts/free_fit_recovery.py --plan design/design.json -n 6 --studies 3 --seed 5501
    python scripts/free_fit_recovery.py --plan paper -n 12 --studies 3 --seed 5102
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from vibrofocus.simulation import available_hypotheses, default_bank, hypothesis
from vibrofocus.simulation.design import PlanBlock, paper_plan
from vibrofocus.simulation.fitting import FitSettings, LabTrials, compare_hypotheses, confusion
from vibrofocus.simulation.fitting.likelihood_fit import SCORE_DRAWS_PER_FIT_DRAW
from vibrofocus.simulation.perception import Traits, draw_answers

ROOT = Path(__file__).resolve().parents[1]


def read_plan(which: str) -> tuple[PlanBlock, ...]:
    if which == "paper":
        return paper_plan()
    blocks = json.loads(Path(which).read_text(encoding="utf-8"))["blocks"]
    if any(b["response"] != "location" for b in blocks):
        raise SystemExit("this script simulates location answers only")
    return tuple(PlanBlock(tuple(b["methods"]), float(b["level_db"]), tuple(b["locations"]), int(b["repetitions"]),
                           b.get("grid", ""), b["response"]) for b in blocks)


def simulate_plan(name: str, plan: tuple[PlanBlock, ...], n: int, rng: np.random.Generator) -> LabTrials:
    """N participants of hypothesis ``name`` answer the plan's blocks (Study 1, location answers)."""
    h = hypothesis(name)
    b = default_bank()
    m = h.model()
    n_loc = len(b.locations_xy)
    levels = sorted({blk.level_db for blk in plan})
    part, stim, ans, lev, allowed = [], [], [], [], []
    forearms = rng.choice(b.n_forearms, size=n, replace=n > b.n_forearms)
    for i in range(n):
        traits = Traits.draw(m, rng)
        per = {}
        for v in levels:
            g = 10.0 ** (v / 10.0)
            e = b.energy[forearms[i]].reshape(len(b.methods) * n_loc, -1) * g
            a = b.actuator_energy[forearms[i]].reshape(len(b.methods) * n_loc, -1) * g
            per[v] = h.percepts(e, b.points_xy, m, traits, a, b.actuators_xy, b.locations_xy)
        for blk in plan:
            ok = np.asarray(blk.locations) - 1
            for meth in blk.methods:
                idx = np.tile(b.methods.index(meth) * n_loc + ok, blk.repetitions)
                a1, _, _ = draw_answers(per[blk.level_db], idx, b.locations_xy, b.centre_xy, m, traits, rng,
                                        allowed=ok)
                mask = np.zeros(n_loc, dtype=bool)
                mask[ok] = True
                part.append(np.full(idx.size, i))
                stim.append(idx)
                ans.append(a1)
                lev.append(np.full(idx.size, blk.level_db))
                allowed.append(np.tile(mask, (idx.size, 1)))
    empty = np.zeros(0, dtype=int)
    return LabTrials(tuple(f"sim-{i + 1:03d}" for i in range(n)), tuple(b.methods), n_loc, np.concatenate(part),
                     np.concatenate(stim), np.concatenate(ans), empty, empty, np.zeros((0, n_loc), dtype=bool),
                     source="<simulated plan>", levels=b.levels, level1=np.concatenate(lev),
                     level2=np.zeros(0), allowed1=np.concatenate(allowed), allowed2=np.zeros((0, n_loc), dtype=bool))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--plan", required=True, help="paper, or a design-experiment design.json")
    ap.add_argument("-n", type=int, default=6, help="participants per study")
    ap.add_argument("--studies", type=int, default=3, help="studies per true hypothesis")
    ap.add_argument("--seed", type=int, required=True, help="a seed the design did not use")
    ap.add_argument("--draws", type=int, default=16, help="population draws per likelihood (analyze: 32)")
    ap.add_argument("--maxiter", type=int, default=FitSettings().maxiter)
    ap.add_argument("--score-draws", type=int, default=None,
                    help="draws that score the left-out participants (default 8 x --draws; 0: the fit's own draws)")
    ap.add_argument("--truths", default="all", help="true hypotheses to simulate, comma separated (default all)")
    ap.add_argument("--results", type=Path)
    args = ap.parse_args()
    names = list(available_hypotheses())
    plan = read_plan(args.plan)
    label = "paper" if args.plan == "paper" else "designed"
    if args.score_draws is None:
        args.score_draws = SCORE_DRAWS_PER_FIT_DRAW * args.draws
    path = args.results or ROOT / "scripts" / "fits" / "recovery" / (
        f"free-{label}-n{args.n}-d{args.draws}-s{args.score_draws}-seed{args.seed}.jsonl")
    key = {"plan": [vars(b) if hasattr(b, "__dict__") else b.__repr__() for b in plan], "n": args.n,
           "seed": args.seed, "draws": args.draws, "score_draws": args.score_draws, "maxiter": args.maxiter,
           "hypotheses": names}
    key = json.loads(json.dumps(key, default=str))
    done = []
    if path.exists():
        lines = path.read_text(encoding="utf-8").splitlines()
        if json.loads(lines[0]).get("settings") != key:
            raise SystemExit(f"{path} holds a run with other settings; give another --results")
        done = [json.loads(x) for x in lines[1:] if x.strip()]
    else:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({"settings": key}) + "\n", encoding="utf-8")
    have = {(d["true"], d["study"]) for d in done}
    settings = FitSettings(n_draws=args.draws, maxiter=args.maxiter, score_draws=args.score_draws)
    truths = names if args.truths == "all" else args.truths.split(",")
    for j in range(args.studies):
        for t, truth in enumerate(names):
            if (truth, j) in have or truth not in truths:
                continue
            t0 = time.perf_counter()
            data = simulate_plan(truth, plan, args.n, np.random.default_rng([args.seed, t, j]))
            res = compare_hypotheses(data, names, settings=settings, local=True)
            row = {"true": truth, "study": j, "chosen": res["chosen"],
                   "elpd": {k: v["elpd"] for k, v in res["hypotheses"].items()},
                   "params": {k: v["params"] for k, v in res["hypotheses"].items()},
                   "difference": res["difference"], "difference_se": res["difference_se"],
                   "elapsed_s": round(time.perf_counter() - t0, 1)}
            with path.open("a", encoding="utf-8") as f:
                f.write(json.dumps(row) + "\n")
            done.append(row)
            print(f"{truth} study {j}: chosen {row['chosen']} (ELPD difference {row['difference']:.1f} "
                  f"+- {row['difference_se']:.1f}; {row['elapsed_s']} s)", flush=True)
    counts = confusion(names, done)
    print("| true \\ chosen | " + " | ".join(names) + " |\n|---" * 1 + "|---" * len(names) + "|")
    for name, row in zip(names, counts):
        print(f"| {name} | " + " | ".join(map(str, row)) + " |")
    print(f"{sum(d['elapsed_s'] for d in done) / 60:.0f} min; results in {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
