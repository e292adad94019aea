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


def _is_command(decorator: ast.expr) -> bool:
    """``@command(...)`` or a sub-app's ``@study_app.command(...)``."""
    func = decorator.func if isinstance(decorator, ast.Call) else None
    return getattr(func, "id", None) == "command" or getattr(func, "attr", None) == "command"


def _commands(source: str) -> list[ast.FunctionDef]:
    """The command functions: those marked with ``@command(...)`` or ``@<app>.command(...)``."""
    return [node for node in ast.walk(ast.parse(source)) if isinstance(node, ast.FunctionDef)
            and any(_is_command(d) for d in node.decorator_list)]


CLI = Path(vibrofocus.cli.calibrate.__file__).parent
SRC = CLI.parent
#: Commands still over the limit, with their code lines now: each may only shrink (one that
#: reaches the limit leaves the list). Every other command has at most the limit.
STILL_LONG: dict[str, int] = {}


def _every_command() -> list[tuple[str, int]]:
    found = []
    for path in sorted(CLI.glob("*.py")):
        source = path.read_text(encoding="utf-8")
        found += [(f.name, code_lines(f, source)) for f in _commands(source)]
    return found


def test_every_command_is_a_thin_caller():
    found = _every_command()
    assert {"calibrate_command", "simulate_study", "power_command", "run", "export"} <= {n for n, _ in found}
    too_long = {name: n for name, n in found if n > MAX_COMMAND_LINES and STILL_LONG.get(name, -1) < n}
    assert not too_long, f"command functions over {MAX_COMMAND_LINES} code lines (or grown): {too_long}"
    short_now = [name for name, n in found if name in STILL_LONG and n <= MAX_COMMAND_LINES]
    assert not short_now, f"within the limit now: remove from STILL_LONG: {short_now}"


#: Per step, the one workflow function each front-end calls (module under src/vibrofocus).
#: The terminal's study run plans and runs through the workflows' own plan_session and
#: run_session; the PsychoPy component asks a running ``serve-osc`` for taps and runs none
#: of these steps.
FRONT_ENDS = {
    "calibrate": {"cli/calibrate.py": "calibrate_participant", "web/routes_experimenter.py": "calibrate_participant"},
    "plan": {"cli/study.py": "run_study_at_terminal", "workflows/session.py": "plan_session",
             "web/routes_experimenter.py": "plan_session"},
    "run": {"cli/study.py": "run_study_at_terminal", "workflows/session.py": "run_session",
            "web/session_runner.py": "run_session"},
    "simulate": {"cli/simulate_study.py": "simulate_study"},
    "power": {"cli/power.py": "study_power"},
    "render": {"cli/render.py": "render_tap"},
    "design layout": {"cli/design_layout.py": "design_layout"},
}
#: What the steps do below the workflows: no front-end calls these itself.
STEP_CALLS = {"calibrate", "create_session", "open_session", "simulate_studies", "run_power", "search_layout"}


def _called(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Call):
            names.add(getattr(node.func, "id", None) or getattr(node.func, "attr", None))
    return names


def test_each_front_end_calls_the_one_workflow_of_each_step():
    for step, callers in FRONT_ENDS.items():
        for module, function in callers.items():
            assert function in vibrofocus.workflows.__all__, (step, function)
            assert function in _called(SRC / module), f"{module} does not call {function} ({step})"


def test_no_front_end_wires_a_step_of_its_own():
    for unit in ("cli", "web", "psychopy"):
        for path in sorted((SRC / unit).glob("*.py")):
            wired = _called(path) & STEP_CALLS
            assert not wired, f"{path.relative_to(SRC)} calls {sorted(wired)} itself: call the workflow"
            # The study loop: a StudyEngine's run only through run_session.
            assert "engine.run(" not in path.read_text(encoding="utf-8"), path


def test_the_step_check_can_fail(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("def f(store):\n    return store.create_session('P01', 1, seed=0)\n", encoding="utf-8")
    assert _called(bad) & STEP_CALLS == {"create_session"}


def test_the_line_count_sees_code_and_skips_docstrings_comments_and_blanks():
    source = 'def f(a,\n      b):\n    """Doc.\n\n    More.\n    """\n    # note\n\n    return a\n'
    (function,) = [n for n in ast.walk(ast.parse(source)) if isinstance(n, ast.FunctionDef)]
    assert code_lines(function, source) == 3
