#!/usr/bin/env python
"""Print the hypotheses' measured tables: the paper's findings under every hypothesis (a MODEL, not data).

Every registered hypothesis, with its fitted parameters, simulates the same 40 studies of
20 participants (the fit's held-out seeds) on a feature bank (default the shipped one);
the tables are made by ``vibrofocus_tools.hypotheses_tables``, the findings analysed
independently of ``vibrofocus.analysis``. The tables of the fits before issue 51 are in
docs/history-simulated-participants.md; the current comparison with the paper is the
posterior-predictive check (``scripts/ppc_table.py``).

    .venv/bin/python scripts/hypotheses_table.py [--bank B.npz]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from vibrofocus.simulation.bank import FeatureBank, default_bank
from vibrofocus_tools.hypotheses_tables import findings_markdown, markdown


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bank", type=Path, help="feature bank (.npz; default the shipped one)")
    args = ap.parse_args()
    bank = FeatureBank.load(args.bank) if args.bank else default_bank()
    print(markdown(bank) + "\n\n" + findings_markdown(bank))
    return 0


if __name__ == "__main__":
    sys.exit(main())
