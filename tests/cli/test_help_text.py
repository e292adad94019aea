"""The help says what its source says (issue 38, bench item): brackets kept, no <bool> after a flag."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest


def _help(*args: str) -> str:
    out = subprocess.run([sys.executable, "-m", "vibrofocus", *args, "--help"], capture_output=True, text=True,
                         timeout=120, env={"COLUMNS": "250", "TERM": "dumb", "PATH": "", "PYTHONPATH": ":".join(sys.path)})
    assert out.returncode == 0, out.stderr
    return re.sub(r"\s+", " ", out.stdout.replace("│", " "))


def test_brackets_in_help_are_shown():
    assert "pip install 'vibrofocus[lsl]'" in _help("serve")
    assert "uses [seed, N, j])" in _help("power")


@pytest.mark.parametrize("command", [(), ("serve",), ("study", "run"), ("stop",)])
def test_no_flag_shows_a_value_placeholder(command):
    text = _help(*command)
    assert "<bool>" not in text, text
