"""The stimulus-level table the CLI prints (``analyze``, ``simulate-study``)."""

from __future__ import annotations

from typing import Any


def levels_table(table: Any, title: str = "Stimulus levels (main trials)") -> Any:
    """A rich Table of :func:`vibrofocus.analysis.levels.stimulus_levels`: per location (rows)
    and method (columns), the median peak drive (V) / predicted peak at the target (µm)."""
    from rich.table import Table

    rules = sorted({r for r in table["levels"].dropna() for r in str(r).split("/")})
    out = Table(title=f"{title}, {'/'.join(rules) or 'unknown'} levels: peak drive V / predicted at the target µm")
    methods = list(dict.fromkeys(table["method"]))
    out.add_column("location", justify="right")
    for m in methods:
        out.add_column(m, justify="right")
    for target in sorted(set(table["target"])):
        cells = []
        for m in methods:
            row = table[(table["method"] == m) & (table["target"] == target)]
            if row.empty or row["drive_peak_v"].isna().all():
                cells.append("—")
                continue
            r = row.iloc[0]
            um = "—" if r["target_peak_um"] != r["target_peak_um"] else f"{r['target_peak_um']:.2f}"
            cells.append(f"{r['drive_peak_v']:.2f} / {um}")
        out.add_row(str(target), *cells)
    return out
