"""``vibrofocus stop`` answers before the command line's imports (docs/security.md)."""

from __future__ import annotations

import subprocess
import sys

_HEAVY = ("typer", "rich", "click", "numpy", "fastapi", "starlette", "scipy")

_PROBE = """
import atexit, runpy, sys
heavy = {heavy!r}
atexit.register(lambda: print("loaded:", sorted({{m.split('.')[0] for m in sys.modules}} & set(heavy)), file=sys.stderr))
sys.argv = ["vibrofocus", "stop", "--db", {db!r}]
runpy.run_module("vibrofocus", run_name="__main__")
"""


def test_the_terminal_stop_loads_nothing_heavy_and_says_not_stopped(tmp_path):
    db = str(tmp_path / "studies.sqlite")
    done = subprocess.run([sys.executable, "-c", _PROBE.format(heavy=_HEAVY, db=db)], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert lines[-1] == "loaded: []", done.stderr
    assert lines[0].startswith("error: not stopped: --db ") and lines[0].endswith("switch the amplifier off")


def test_anything_but_a_plain_stop_goes_to_the_command_line():
    from vibrofocus._stop_client import main

    for argv in ([], ["serve"], ["stop", "--help"], ["stop", "--db"], ["stop", "--db", "--help"], ["stop", "x"]):
        assert main(argv) is None, argv
