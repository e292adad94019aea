"""One-way imports between the subpackages, checked in fresh interpreters (as MNE-Python's
test_import_nesting does): lower layers never load upper ones."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

# Subpackage -> the vibrofocus subpackages it must NOT load when imported.
UPPER = {"rendering", "skin", "calibration", "rigs", "studies", "analysis", "workflows", "demo", "web", "cli"}
FORBIDDEN = {
    "layout": UPPER | {"signals", "io"},
    # The file formats sit just above layout: every layer may read and write files.
    "io": UPPER | {"signals"},
    **{f"io.{m}": UPPER | {"signals"}
       for m in ("calibration_nc", "drives", "trials_csv", "responses", "report_json", "jsonsafe", "feature_bank",
                 "bids", "lsl", "sofa")},
    "signals": UPPER | {"io"},
    "rendering": UPPER - {"rendering"},
    # The simulated rig is an adapter over the arm's physics (skin), which sits below rigs.
    "rigs": UPPER - {"rigs", "skin"},
    # The arm's physics knows nothing of rigs (the simulated rig is an adapter in rigs/).
    "skin": {"rigs", "calibration", "studies", "analysis", "workflows", "demo", "web", "cli"},
    "calibration": {"studies", "analysis", "workflows", "demo", "web", "cli"},
    "analysis": {"rendering", "skin", "calibration", "rigs", "studies", "workflows", "demo", "web", "cli"},
    "studies": {"analysis", "workflows", "demo", "web", "cli"},
    # The workflows sit under every front-end: importing them loads none.
    "workflows": {"demo", "web", "cli", "psychopy"},
    "web": {"cli", "demo"},
}

PROBE = """
import json, sys
{statement}
print(json.dumps(sorted({modules})))
"""


def _probe(statement: str, modules: str) -> list:
    """Run ``statement`` in a fresh interpreter; the sorted ``modules`` (an expression over
    ``sys.modules``) it leaves loaded."""
    out = subprocess.run([sys.executable, "-c", PROBE.format(statement=statement, modules=modules)],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def _loaded(name: str) -> set[str]:
    """The vibrofocus subpackages that importing ``vibrofocus.name`` loads."""
    return set(_probe(f"import vibrofocus.{name}",
                      "{m.split('.')[1] for m in sys.modules if m.startswith('vibrofocus.')}"))


@pytest.mark.parametrize("name", sorted(FORBIDDEN))
def test_a_subpackage_does_not_load_the_layers_above_it(name):
    assert not (_loaded(name) & FORBIDDEN[name]), f"vibrofocus.{name} loads {sorted(_loaded(name) & FORBIDDEN[name])}"


def test_importing_the_package_loads_almost_nothing():
    # The public API is lazy (PEP 562): `import vibrofocus` loads only the error classes.
    assert _loaded("errors") <= {"errors"}


# Libraries that take most of an interpreter's start when imported (scipy.signal and
# pandas alone took 1.1 s of the 3.3 s `vibrofocus serve` needed to answer): the web
# server, the command line, the rigs and the arm load them when a job needs them, not to start.
HEAVY = ("pandas", "scipy.signal", "scipy.optimize", "scipy.stats", "matplotlib", "xarray", "cvxopt", "cvxpy")


@pytest.mark.parametrize("statement", [
    "import vibrofocus.web.app", "import vibrofocus.cli.main", "import vibrofocus.skin",
    # What `vibrofocus serve` makes before it answers: the simulated rig.
    "from vibrofocus.rigs import SimulatedForearm; SimulatedForearm()",
])
def test_starting_a_server_or_a_command_loads_no_heavy_library(statement):
    assert _probe(statement, f"h for h in {HEAVY!r} if h in sys.modules") == [], f"{statement!r} loads them"


def test_the_web_app_does_not_shell_out_to_the_cli():
    # The analysis calls vibrofocus.analysis.report_trials_file (in a spawned worker, so
    # that it cannot hold the GIL of the thread that times stimuli), never the command
    # line (`python -m vibrofocus ...` through subprocess).
    import ast
    from pathlib import Path

    import vibrofocus.web

    for path in sorted(Path(vibrofocus.web.__file__).parent.glob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        imported = {alias.name.split(".")[0] for node in ast.walk(tree) if isinstance(node, (ast.Import, ast.ImportFrom))
                    for alias in node.names} | {node.module.split(".")[0] for node in ast.walk(tree)
                                                if isinstance(node, ast.ImportFrom) and node.module and node.level == 0}
        assert "subprocess" not in imported, f"{path.name} runs commands"
        assert "sys.executable" not in ast.unparse(tree), f"{path.name} runs a Python interpreter"
    assert "cli" not in _loaded("web")


def test_the_web_routers_do_not_import_the_app_factory():
    # app -> routes_* -> state: a router importing app would close the cycle again.
    import ast
    from pathlib import Path

    import vibrofocus.web

    folder = Path(vibrofocus.web.__file__).parent
    routers = sorted(folder.glob("routes_*.py"))
    assert routers, "no router modules found"
    for path in routers + [folder / "state.py"]:
        tree = ast.parse(path.read_text(encoding="utf-8"))
        relative = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) and node.level == 1}
        assert "app" not in relative, f"{path.name} imports the app factory"


# Imports inside functions are checked against the package's floors by tests/test_layering.py,
# which reads every import in the source (this file checks what a fresh interpreter loads).
