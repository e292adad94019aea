"""Each front-end calibrates through the one workflow, and the command stays a thin caller."""

from __future__ import annotations

import ast
import inspect
import time
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from typer.testing import CliRunner

import vibrofocus.cli.calibrate
import vibrofocus.workflows
from vibrofocus.cli.main import app as cli_app
from vibrofocus.errors import ValidationError

TOKEN = "t" * 32
#: The most code lines a command function may have: it parses, calls a workflow, prints.
MAX_COMMAND_LINES = 60


@pytest.fixture
def reached(monkeypatch):
    """Replace the calibration workflow by one that records its call and refuses (no measurement)."""
    calls: list[tuple] = []

    def workflow(rig, participant_id, out, **kwargs):
        calls.append((rig.kind, participant_id, Path(out).suffix, sorted(kwargs)))
        raise ValidationError("the workflow was reached")

    monkeypatch.setattr(vibrofocus.workflows, "calibrate_participant", workflow)
    return calls


def test_the_command_line_calibrates_through_the_workflow(reached, tmp_path):
    result = CliRunner().invoke(cli_app, ["calibrate", "--rig", "simulated", "--participant", "P01",
                                          "--out", str(tmp_path / "P01.nc"), "--yes"])
    assert result.exit_code != 0 and "the workflow was reached" in result.output, result.output
    assert [c[:3] for c in reached] == [("simulated", "P01", ".nc")]
    assert {"progress", "aim", "save_with"} <= set(reached[0][3])


def test_the_web_calibration_job_calibrates_through_the_workflow(reached, tmp_path):
    from vibrofocus.web.app import create_app

    web = create_app(tmp_path / "s.sqlite", token=TOKEN, allowed_hosts=("testserver",), resume=False, pace="fast")
    with TestClient(web, headers={"X-Vibrofocus-Token": TOKEN, "Origin": "http://testserver"}) as client:
        assert client.post("/api/participants", json={"participant_id": "P02"}).status_code == 201
        job = client.post("/api/calibrations", json={"participant_id": "P02", "seed": 7}).json()["job_id"]
        deadline = time.monotonic() + 60
        while (j := client.get(f"/api/calibrations/jobs/{job}").json())["status"] in ("running", "waiting"):
            assert time.monotonic() < deadline, j
            time.sleep(0.05)
    assert (j["status"], j["error"]) == ("failed", "the workflow was reached"), j
    assert [c[:3] for c in reached] == [("simulated", "P02", ".nc")]
    assert {"progress", "aim", "before_saving", "store"} <= set(reached[0][3])


def code_lines(function: ast.FunctionDef, source: str) -> int:
    """Non-blank lines of ``function`` that are neither comments nor its docstring."""
    body = function.body
    doc: set[int] = set()
    if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
            and isinstance(body[0].value.value, str):
        doc = set(range(body[0].lineno, body[0].end_lineno + 1))
    lines = source.splitlines()
    return sum(1 for n in range(function.lineno, function.end_lineno + 1)
               if n not in doc and lines[n - 1].strip() and not lines[n - 1].strip().startswith("#"))


def _commands(source: str) -> list[ast.FunctionDef]:
    """The functions marked with ``@command(...)``."""
    return [node for node in ast.walk(ast.parse(source)) if isinstance(node, ast.FunctionDef)
            and any(isinstance(d, ast.Call) and getattr(d.func, "id", None) == "command" for d in node.decorator_list)]


def test_the_calibrate_command_is_a_thin_caller():
    source = inspect.getsource(vibrofocus.cli.calibrate)
    commands = _commands(source)
    assert [f.name for f in commands] == ["calibrate_command"]
    for function in commands:
        n = code_lines(function, source)
        assert n <= MAX_COMMAND_LINES, f"{function.name} has {n} code lines (at most {MAX_COMMAND_LINES})"


def test_the_line_count_sees_code_and_skips_docstrings_comments_and_blanks():
    source = 'def f(a,\n      b):\n    """Doc.\n\n    More.\n    """\n    # note\n\n    return a\n'
    (function,) = [n for n in ast.walk(ast.parse(source)) if isinstance(n, ast.FunctionDef)]
    assert code_lines(function, source) == 3
