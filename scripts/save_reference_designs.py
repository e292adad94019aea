#!/usr/bin/env python
"""Save the drives of every built-in rendering method, for a regression test of ``render``.

The cases and the file are those of ``vibrofocus_tools.reference_designs`` (its docstring
says when to run this); this is its command line:

    python scripts/save_reference_designs.py [--out PATH]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from vibrofocus_tools.reference_designs import OUT, save


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    print(save(args.out))


if __name__ == "__main__":
    main()
