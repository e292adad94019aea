#!/usr/bin/env python
"""Write the hypotheses' tables of docs/simulated-participants.md (Hypotheses).

Every registered hypothesis, with its fitted parameters, simulates the same 40 studies of
20 participants (the fit's held-out seeds) on a feature bank (default the shipped one);
the tables are made by ``vibrofocus_tools.hypotheses_tables`` (a model, not data).

    .venv/bin/python scripts/hypotheses_table.py                 # rewrite both tables in the doc
    .venv/bin/python scripts/hypotheses_table.py --bank B.npz --print
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from vibrofocus.simulation.bank import FeatureBank, default_bank
from vibrofocus_tools.hypotheses_tables import PAGE, findings_markdown, markdown
from vibrofocus_tools.markers import write_between_markers


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bank", type=Path, help="feature bank (.npz; default the shipped one)")
    ap.add_argument("--print", action="store_true", help="only print the table")
    args = ap.parse_args()
    bank = FeatureBank.load(args.bank) if args.bank else default_bank()
    tables = {"hypotheses-measured": markdown(bank), "hypotheses-findings": findings_markdown(bank)}
    print("\n\n".join(tables.values()))
    if not args.print:
        for name, table in tables.items():
            write_between_markers(PAGE, name, table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
