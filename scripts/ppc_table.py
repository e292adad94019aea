#!/usr/bin/env python
"""The posterior-predictive check of every hypothesis against the paper's numbers (a MODEL, not data).

Every registered hypothesis, with its shipped fit, simulates the paper's two studies
(default 200 studies of 20 participants, seeds 3000-3199) on Dask (one LocalCluster, no
dashboard); the table gives the paper's 7 statistics beside each hypothesis' median and
90 % interval, the Study 1 and Study 2 directions and the Study 1 answers beside the
paper's Fig. 6, and the default chosen by the rule of ``vibrofocus.simulation.ppc``.

    python scripts/ppc_table.py                     # print the table (and JSON with --json FILE)
    python scripts/ppc_table.py --docs --record     # also write it into the docs, the default into the fits
    python scripts/ppc_table.py --studies 20 --local

The work is :func:`vibrofocus.simulation.ppc.run_ppc`; this is its command line.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from vibrofocus.simulation.fitting import FITS_FILE
from vibrofocus.simulation.ppc import PPC_SEEDS, ppc_markdown, record_default, run_ppc
from vibrofocus_tools.markers import write_between_markers

PAGE = Path(__file__).resolve().parents[1] / "docs" / "simulated-participants.md"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--studies", type=int, default=len(PPC_SEEDS), help="studies per hypothesis (default 200)")
    ap.add_argument("--first-seed", type=int, default=PPC_SEEDS.start)
    ap.add_argument("--workers", type=int, default=None, help="LocalCluster workers (default the CPU count)")
    ap.add_argument("--local", action="store_true", help="in this process, without Dask (same numbers)")
    ap.add_argument("--json", type=Path, default=None, help="also write the whole check as JSON")
    ap.add_argument("--docs", action="store_true", help="write the table between its markers in the docs")
    ap.add_argument("--record", action="store_true",
                    help="write the default and the check's summary into simulation/data/hypotheses_fit.json")
    args = ap.parse_args()
    seeds = range(args.first_seed, args.first_seed + args.studies)
    result = run_ppc(seeds=seeds, local=args.local, n_workers=args.workers,
                     progress=lambda d, n: print(f"{d}/{n} studies", file=sys.stderr, flush=True))
    table = ppc_markdown(result)
    print(table)
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")
    if args.docs:
        write_between_markers(PAGE, "ppc-table", table)
    if args.record:
        record_default(result, FITS_FILE)
    return 0


if __name__ == "__main__":
    sys.exit(main())
