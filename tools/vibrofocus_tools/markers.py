"""The generated blocks of the docs: a table between ``<!-- name:start -->`` and ``<!-- name:end -->``.

Shared by the tools and scripts that regenerate a table in a page.
"""

from __future__ import annotations

from pathlib import Path

#: The checkout these tools belong to (they read and write its docs and fits).
ROOT = Path(__file__).resolve().parents[2]


def replace_between_markers(text: str, name: str, block: str, page: Path) -> str:
    """``text`` with ``block`` between the ``<!-- name:start -->`` / ``<!-- name:end -->`` markers."""
    start, end = f"<!-- {name}:start -->", f"<!-- {name}:end -->"
    if start not in text or end not in text:
        raise SystemExit(f"{page} has no {start} ... {end} markers")
    head, rest = text.split(start, 1)
    _, tail = rest.split(end, 1)
    return f"{head}{start}\n{block}\n{end}{tail}"


def write_between_markers(page: Path, name: str, block: str) -> None:
    """Put ``block`` between the page's ``name`` markers, written atomically."""
    from vibrofocus.io import write_text

    write_text(page, replace_between_markers(page.read_text(encoding="utf-8"), name, block, page))
