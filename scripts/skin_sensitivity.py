#!/usr/bin/env python
"""Write the attenuation sensitivity table into docs/skin-model.md.

Recomputes :func:`vibrofocus.demo.sensitivity.attenuation_sensitivity` (about 90 s, most of it the
peak bounds: a minimax design per location and skin) and
replaces the table between the ``sensitivity-table`` markers of ``docs/skin-model.md``
(atomically, through ``vibrofocus.io.write_text``). With ``--check`` it only
compares and exits 1 if the page is out of date.

    .venv/bin/python scripts/skin_sensitivity.py [--check]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from vibrofocus.io import write_text
from vibrofocus.demo.sensitivity import attenuation_sensitivity, sensitivity_markdown

PAGE = Path(__file__).resolve().parent.parent / "docs" / "skin-model.md"
START, END = "<!-- sensitivity-table:start -->", "<!-- sensitivity-table:end -->"


def replace_table(text: str, table: str) -> str:
    head, rest = text.split(START, 1)
    _, tail = rest.split(END, 1)
    return f"{head}{START}\n{table}\n{END}{tail}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="only compare; exit 1 if the page is out of date")
    args = parser.parse_args()
    table = sensitivity_markdown(attenuation_sensitivity())
    text = PAGE.read_text(encoding="utf-8")
    new = replace_table(text, table)
    if args.check:
        print("up to date" if new == text else "docs/skin-model.md is out of date")
        return 0 if new == text else 1
    write_text(PAGE, new)
    print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
