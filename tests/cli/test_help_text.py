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


def _commands(group, path=()):
    """Every command and sub-command of the click group, with its path of names."""
    yield path, group
    for name, sub in sorted(getattr(group, "commands", {}).items()):
        yield from _commands(sub, (*path, name))


def test_every_bracketed_word_of_every_help_is_shown_as_written():
    """No command's or option's help loses a ``[word]`` to Rich markup or shows a stray backslash."""
    import typer
    from typer.testing import CliRunner

    from vibrofocus.cli.main import app

    runner = CliRunner()
    group = typer.main.get_command(app)
    bracketed = re.compile(r"\\*\[[^\]\s]+\]")
    checked = 0
    for path, cmd in _commands(group):
        out = runner.invoke(app, [*path, "--help"], env={"COLUMNS": "400", "TERM": "dumb"})
        assert out.exit_code == 0, (path, out.output)
        shown = re.sub(r"\s+", " ", out.output.replace("│", " "))
        assert "\\[" not in shown, (path, shown)
        for text in [cmd.help or "", *(getattr(p, "help", None) or "" for p in cmd.params)]:
            for word in bracketed.findall(text):
                plain = word.lstrip("\\")
                assert plain in shown, (path, plain)
                checked += 1
    assert checked >= 2  # the extras' install hints ([lsl], [osc]) at least
