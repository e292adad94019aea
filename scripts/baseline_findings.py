#!/usr/bin/env python
"""Measure the issue's baseline: the paper's findings under the participants of commit c313a27.

Issue 42 asks that no finding of the paper fall below the share of studies in which it
held under the simulated participants of c313a27 (perceptual model v3, every method at
equal peak drive), on the same seeds. That model is no longer in the code, so this script
runs that commit's own ``scripts/check_findings.py`` (its ``findings``, model and feature
bank) from a checkout of it and writes the counts, with their provenance, to
``scripts/fits/baseline-c313a27.json``, which ``scripts/hypotheses_table.py`` prints beside
every hypothesis (a MODEL, not data):

    git worktree add /tmp/c313a27 c313a27
    .venv/bin/python scripts/baseline_findings.py --checkout /tmp/c313a27      # ~10 s

The Study 2 headline row (fewer points with a 10-30 % reduction) and the rows of each study
as a whole did not exist then; they are counted here from that commit's own findings
(``vibrofocus_tools.joint``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from vibrofocus.io import write_text
from vibrofocus_tools.joint import JOINT, add_joint, headline

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "scripts" / "fits" / "baseline-c313a27.json"
COMMIT = "c313a27"
SEED_RANGES = ((700, 740), (800, 1000))  # the held-out seeds, then those the weights were chosen on

#: Run in that commit's code (its src and scripts first on the path): the findings of each
#: study of each seed range, and that commit's rows, as JSON on stdout.
_MEASURE = """
import json, sys, warnings
import numpy as np
from check_findings import ROWS, findings
from vibrofocus.simulation.bank import default_bank, simulate_cell_means
from vibrofocus.simulation.perception import PerceptualModel
warnings.simplefilter("ignore")
bank = default_bank()
studies = []
for first, stop in json.loads(sys.argv[1]):
    res = []
    for s in range(first, stop):
        arrays = simulate_cell_means(20, np.random.default_rng([s, 16]), bank=bank, model=PerceptualModel())
        r = findings(arrays.error_mm, arrays.count, arrays.count_hit)
        res.append({k: (bool(v) if isinstance(v, (bool, np.bool_)) else int(v) if isinstance(v, (int, np.integer))
                        else float(v)) for k, v in r.items()})
    studies.append(res)
json.dump({"rows": [k for _, k in ROWS], "studies": studies}, sys.stdout)
"""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--checkout", type=Path, required=True, help=f"a checkout (worktree) of commit {COMMIT}")
    ap.add_argument("--out", type=Path, default=OUT, help="where to write the counts (JSON)")
    args = ap.parse_args()
    head = subprocess.run(["git", "-C", str(args.checkout), "rev-parse", "HEAD"], capture_output=True, text=True)
    if head.returncode != 0 or not head.stdout.startswith(COMMIT):
        ap.error(f"--checkout {args.checkout}: not a checkout of {COMMIT} ({head.stdout.strip() or head.stderr.strip()})")
    # That commit's code, not this checkout's: its package and its check_findings, in a child
    # process of their own; this one adds the findings made of others and writes the file.
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(args.checkout / "src"), str(args.checkout / "scripts")]),
           "PYTHONDONTWRITEBYTECODE": "1"}
    child = subprocess.run([sys.executable, "-c", _MEASURE, json.dumps(SEED_RANGES)], capture_output=True,
                           text=True, env=env, cwd=args.checkout)
    if child.returncode != 0:
        ap.error(f"--checkout {args.checkout}: its check_findings failed: {child.stderr.strip()[-2000:]}")
    measured = json.loads(child.stdout)
    out = {"about": f"The paper's findings under commit {COMMIT}'s simulated participants (model v3, every method at "
                    "equal peak drive; issue 42's baseline), by that commit's scripts/check_findings.py; written by "
                    "scripts/baseline_findings.py. A model, not data.",
           "commit": head.stdout.strip(), "participants": 20, "seeds": {}}
    keys = list(dict.fromkeys(measured["rows"] + ["s2_headline", *JOINT]))
    for (first, stop), found in zip(SEED_RANGES, measured["studies"]):
        res = []
        for r in found:
            r["s2_headline"] = headline(r["s2_method"], r["s2_reduction"])
            res.append(add_joint(r))
        red = np.array([r["s2_reduction"] for r in res])
        out["seeds"][f"{first}-{stop - 1}"] = {
            "studies": len(res),
            "holds": {k: int(sum(bool(r[k]) for r in res)) for k in keys},
            # Each study's outcome, in seed order ("1": the finding held), for paired comparisons.
            "per_seed": {k: "".join("1" if r[k] else "0" for r in res) for k in keys},
            "s2_reduction": {"median": float(np.median(red)), "p5": float(np.percentile(red, 5)),
                             "p95": float(np.percentile(red, 95))},
        }
    write_text(args.out, json.dumps(out, indent=1) + "\n", what="baseline")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
