"""The Python snippets of docs/usage.md run as written, in order, in a fresh process.

A snippet that names a function that does not exist where it says, or mixes units, fails
here rather than in a reader's notebook (issue 54, item 11)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src"
_PYTHON_BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def python_blocks(page: Path) -> list[str]:
    """The ```python blocks of a Markdown page, in order."""
    return _PYTHON_BLOCK.findall(page.read_text(encoding="utf-8"))


def test_the_block_reader_finds_blocks():
    blocks = python_blocks(ROOT / "docs" / "usage.md")
    assert len(blocks) >= 2 and all(b.strip() for b in blocks)


@pytest.mark.slow
def test_usage_snippets_run_as_written(tmp_path):
    script = tmp_path / "usage_snippets.py"
    script.write_text("\n".join(python_blocks(ROOT / "docs" / "usage.md")), encoding="utf-8")
    env = dict(os.environ, PYTHONPATH=str(SRC), PYTHONDONTWRITEBYTECODE="1", MPLBACKEND="Agg")
    proc = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert (tmp_path / "P03.nc").is_file()
