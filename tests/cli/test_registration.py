"""The commands are registered one way, in one fixed order, whatever is imported first."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import pytest

from vibrofocus.cli.commands import COMMAND_MODULES

ORDER = ["demo", "calibrate", "render", "serve", "stop", "serve-osc", "analyze", "simulate-study", "export", "power",
         "design-experiment", "design-layout", "play", "latency", "devices", "straps", "study", "psychopy"]

PROBE = """
import json, sys
{first}
from typer.main import get_command
from vibrofocus.cli.main import app
group = get_command(app)
print(json.dumps(list(group.list_commands(None))))
"""


def _listed(first: str) -> list[str]:
    out = subprocess.run([sys.executable, "-c", PROBE.format(first=first)], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("first", ["", "import vibrofocus.cli.play", "import vibrofocus.cli.devices",
                                   "import vibrofocus.cli.study", "from vibrofocus.cli import demo, power"])
def test_commands_are_listed_in_one_order_whatever_is_imported_first(first):
    assert _listed(first) == ORDER


def test_help_lists_the_commands_in_that_order():
    out = subprocess.run([sys.executable, "-m", "vibrofocus", "--help"], capture_output=True, text=True, timeout=120,
                         env={"COLUMNS": "200", "TERM": "dumb", "PATH": "", "PYTHONPATH": ":".join(sys.path)})
    assert out.returncode == 0, out.stderr
    named = [m.group(1) for m in re.finditer(r"^│ (\S+)\s", out.stdout, re.M) if m.group(1) in ORDER]
    assert named == [c for c in ORDER], out.stdout


def test_command_modules_never_import_the_app():
    # The registration is one-way: main imports the command modules, never the reverse.
    from pathlib import Path

    folder = Path(__import__("vibrofocus.cli", fromlist=["x"]).__file__).parent
    for name in COMMAND_MODULES:
        text = (folder / f"{name}.py").read_text()
        assert "from .main import" not in text and "import main" not in text, name


@pytest.mark.parametrize("args", [["--help"], ["devices", "--json"]])
def test_a_closed_pipe_ends_the_command_quietly(args, tmp_path):
    # As `vibrofocus --help | head -0`: the reader is gone before the command writes.
    import subprocess
    import sys

    read, write = os.pipe()
    os.close(read)
    try:
        done = subprocess.run([sys.executable, "-m", "vibrofocus", *args], stdout=write, stderr=subprocess.PIPE,
                              text=True, timeout=120, cwd=tmp_path)
    finally:
        os.close(write)
    assert done.stderr == ""  # no traceback, no "error:", no "Exception ignored"
    assert done.returncode in (1, 141)  # rich's quiet exit, or ours (128 + SIGPIPE)


def _commands(group, prefix=()):
    for name, cmd in group.commands.items():
        if hasattr(cmd, "commands"):
            yield from _commands(cmd, (*prefix, name))
        else:
            yield (*prefix, name)


def test_help_paragraphs_flow_as_one_text_in_every_command():
    # A docstring's source line breaks must not survive into the wrapped help: there, each
    # shows as a short line whose sentence goes on below (".csv has" / "a time column ...").
    from typer.main import get_command
    from typer.testing import CliRunner

    from vibrofocus.cli.main import app

    names = list(_commands(get_command(app)))
    assert len(names) > len(ORDER)  # the study group's commands too
    for name in names:
        result = CliRunner().invoke(app, [*name, "--help"], terminal_width=80)
        assert result.exit_code == 0, result.output
        text = result.output.split("Options")[0].split("Commands")[0]
        lines = [line.strip() for line in text.splitlines()]
        ragged = [f"{a} | {b}" for a, b in zip(lines, lines[1:]) if a and len(a) < 50 and re.match(r"[a-z(]", b)]
        assert not ragged, (name, ragged)
