"""The package's floors, in the style of MNE-Python's import tests: every import in src/, at
module level, inside a function or under ``TYPE_CHECKING``, goes to its own unit or down.

tests/test_import_nesting.py checks what a fresh interpreter *loads*; this test reads the
source (tests/_import_graph.py), so an import inside a function cannot hide.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

import vibrofocus

from ._import_graph import circles, floor_of, import_edges, layering_breaks

PACKAGE = Path(vibrofocus.__file__).parent

#: The floors, bottom up. A unit (a subpackage or a top-level module) may import its own
#: unit and any unit on a lower floor; never a unit on its own floor or above. The top
#: package ``vibrofocus`` (``__version__``, the lazy public API) is no floor: at run time it
#: loads only :mod:`vibrofocus.errors`.
FLOORS = (
    ("errors", "defaults", "_docs", "_style", "_templates", "_interrupts",  # constants, messages, signals,
     "_deprecated"),                                          # former names that warn
    ("_oserrors", "_validation", "_safe_folders", "_owners"),  # error wording, the shared checks, shared folders
    ("_db_files",),                                           # where a study database's files go
    ("_output_rules", "_stop_client"),                        # what an output may replace; the terminal stop
    ("_disk_checks", "_atomic_folders", "_confined"),         # free space, whole folders, below a root
    ("_atomic",),                                             # atomic files (re-exports the four above)
    ("io", "layout", "signals"),                              # formats (plain arrays), the array, waveforms
    ("rendering", "analysis"),                                # the designs, the statistics of trials
    ("skin",),                                                # the simulated arm's physics
    ("rigs", "placement"),                                    # hardware, the simulated rig; where to put actuators
    ("calibration",),                                         # measures on a rig, fits the skin, designs
    ("studies", "realtime"),                                  # sessions, storage, export; live taps, latency
    ("simulation",),                                          # simulated participants (a model) on the engine
    ("demo", "participant_models"),                           # the demo's parts; the participants' new name
    ("workflows",),                                           # the lab's workflows, under every front-end
    ("web", "psychopy"),                                      # the web app; taps in PsychoPy
    ("cli",),                                                 # the command line
    ("__main__",),                                            # python -m vibrofocus
)

#: Upward imports that stay, each inside one function and for a stated reason. Each must
#: still exist (test_every_allowed_exception_is_still_needed), so a fixed one leaves the list.
ALLOWED = {
    ("vibrofocus.skin", "vibrofocus.rigs.simulated"):
        "the former name vibrofocus.skin.SimulatedForearm of the rig over the physics, deprecated, loaded on "
        "first use (importing vibrofocus.skin loads no rig: test_import_nesting)",
    ("vibrofocus.studies.bids", "vibrofocus.simulation.perception"):
        "the BIDS sidecars name the perceptual model that answered for simulated participants",
    ("vibrofocus.studies.store_events", "vibrofocus.simulation.perception"):
        "a simulated session stored before sessions named their model is labelled with model v3, its only one then",
    ("vibrofocus.analysis.report", "vibrofocus.simulation.perception"):
        "report.json names the perceptual model (label, version) that answered for simulated participants; "
        "the model's identity lives with the model, in simulation.perception",
}


@pytest.fixture(scope="module")
def edges():
    return import_edges(PACKAGE)


def test_every_unit_of_the_package_is_on_exactly_one_floor():
    units = {p.stem for p in PACKAGE.glob("*.py") if p.stem != "__init__"}
    units |= {p.parent.name for p in PACKAGE.glob("*/__init__.py")}
    listed = [u for floor in FLOORS for u in floor]
    assert len(listed) == len(set(listed)), "a unit is on two floors"
    assert units == set(listed), f"not on a floor: {sorted(units - set(listed))}; gone: {sorted(set(listed) - units)}"


def test_every_import_goes_down_a_floor_or_stays_in_its_unit(edges):
    breaks = [e for e in layering_breaks(edges, FLOORS) if (e.importer, e.imported) not in ALLOWED]
    assert not breaks, "imports against the floors:\n" + "\n".join(map(str, breaks))


def test_every_allowed_exception_is_still_needed(edges):
    found = {(e.importer, e.imported) for e in layering_breaks(edges, FLOORS)}
    assert set(ALLOWED) <= found, f"no longer imported, remove from ALLOWED: {sorted(set(ALLOWED) - found)}"
    for edge in layering_breaks(edges, FLOORS):
        if (edge.importer, edge.imported) in ALLOWED:
            assert edge.in_function and not edge.type_checking, f"{edge}: an allowed exception stays inside a function"


def test_the_package_has_no_import_circle_counting_imports_inside_functions(edges):
    assert circles(edges) == []


def test_io_imports_nothing_but_the_floors_below_it(edges):
    # io is the bottom of the data: formats read and write plain arrays and records.
    below = {u for floor in FLOORS[:FLOORS.index(("io", "layout", "signals"))] for u in floor}
    for edge in edges:
        if edge.importer.startswith("vibrofocus.io"):
            unit = edge.imported.split(".")[1]
            assert unit == "io" or unit in below, str(edge)


# --------------------------------------------------------------------------- the checker can fail
def _write(root: Path, files: dict[str, str]) -> Path:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    return root


def test_the_checker_finds_an_upward_import_inside_a_function_and_a_circle(tmp_path):
    pkg = _write(tmp_path / "toy", {
        "__init__.py": "",
        "low/__init__.py": "from .a import f\n",
        "low/a.py": "def f():\n    from ..high import g\n    return g\n",
        "high/__init__.py": "from ..low import a\nfrom ..low.a import f as g\n",
        "side.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .high import g\n",
    })
    edges = import_edges(pkg)
    floors = (("low",), ("high", "side"))
    breaks = {(e.importer, e.imported, e.in_function, e.type_checking) for e in layering_breaks(edges, floors)}
    assert breaks == {("toy.low.a", "toy.high", True, False), ("toy.side", "toy.high", False, True)}
    assert circles(edges) == [["toy.high", "toy.low.a"]]
    # A circle only under TYPE_CHECKING is none; one at module level is.
    assert circles([e for e in edges if not e.in_function]) == []
    with pytest.raises(KeyError, match="on no floor"):
        floor_of("toy.nowhere", floors)


def test_a_bad_import_in_a_copy_of_the_package_is_caught(tmp_path):
    copy = tmp_path / "vibrofocus"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__", "*.nc", "*.npz", "static"))
    target = copy / "io" / "jsonsafe.py"
    target.write_text(target.read_text(encoding="utf-8")
                      + "\n\ndef _bad():\n    from ..calibration import Calibration\n    return Calibration\n",
                      encoding="utf-8")
    edges = import_edges(copy)
    bad = [e for e in layering_breaks(edges, FLOORS) if (e.importer, e.imported) not in ALLOWED]
    assert [(e.importer, e.imported, e.in_function) for e in bad] == [
        ("vibrofocus.io.jsonsafe", "vibrofocus.calibration", True)]
    # calibration imports io: the bad import also closes a circle.
    assert any("vibrofocus.io.jsonsafe" in group for group in circles(edges))
