"""Shared fixtures. Every random generator in the tests is seeded.

The suite writes only to temporary folders: :func:`pytest_sessionfinish` fails the run if
the checkout gained any file (``git status --porcelain --ignored``), apart from Python's
and pytest's own caches (the README's test command turns those off too).
"""

import os
import subprocess
import tempfile
from pathlib import Path

# Hypothesis keeps what it learns (examples, constants) in a folder: a temporary one, never
# the checkout's .hypothesis/ (read when hypothesis first stores something).
os.environ.setdefault("HYPOTHESIS_STORAGE_DIRECTORY", tempfile.mkdtemp(prefix="vibrofocus-hypothesis-"))

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from hypothesis import settings  # noqa: E402

# Property tests draw the same examples on every run (seeded, like every RNG here) and keep
# no example database in the checkout.
settings.register_profile("vibrofocus", database=None, derandomize=True)
settings.load_profile("vibrofocus")

from vibrofocus import ArrayLayout


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261122)


@pytest.fixture
def reference_layout() -> ArrayLayout:
    return ArrayLayout.reference()


@pytest.fixture(autouse=True, scope="session")
def _private_device_locks(tmp_path_factory):
    """Device lock files of the test run in a folder of its own (never a lab's real locks)."""
    import os

    folder = tmp_path_factory.mktemp("device-locks")
    before = os.environ.get("VIBROFOCUS_LOCK_DIR")
    os.environ["VIBROFOCUS_LOCK_DIR"] = str(folder)
    yield folder
    if before is None:
        os.environ.pop("VIBROFOCUS_LOCK_DIR", None)
    else:
        os.environ["VIBROFOCUS_LOCK_DIR"] = before


# ------------------------------------------------------------ one shared simulated calibration
@pytest.fixture(scope="session")
def simulated_calibration_of():
    """``get(skin="nominal") -> (rig, cal)``: simulated participant 0's default (mimo)
    calibration, noise and dropouts on, on the simulated forearm with that skin preset, and
    the rig. Each is made once per test process (seconds each) for the tests that only read
    it: never change the calibration or play on the rig (copy a saved file to edit it)."""
    from vibrofocus.calibration import calibrate
    from vibrofocus.rigs import SimulatedForearm

    made = {}

    def get(skin: str = "nominal"):
        if skin not in made:
            rig = SimulatedForearm(seed=0, skin=skin)
            made[skin] = rig, calibrate(rig, participant_id="S00")
        return made[skin]

    return get


@pytest.fixture(scope="session")
def simulated_calibration(simulated_calibration_of):
    """``(rig, cal)`` on the default (nominal) skin: :func:`simulated_calibration_of`."""
    return simulated_calibration_of("nominal")


ROOT = Path(__file__).resolve().parents[1]

#: Debian's chromium, driven by Playwright (the web pages, the docs' navigation bar).
CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--autoplay-policy=no-user-gesture-required",
]


@pytest.fixture
def lsl_config(tmp_path_factory, monkeypatch):
    """liblsl on this machine only (ResolveScope = machine: resolve and stream over the
    loopback), as in a sandbox without multicast. liblsl reads its configuration
    (LSLAPICFG, its lsl_api.cfg) once per process, at its first use."""
    cfg = tmp_path_factory.getbasetemp() / "lsl_api.cfg"
    if not cfg.exists():
        cfg.write_text("[multicast]\nResolveScope = machine\n[log]\nlevel = -3\n", encoding="utf-8")
    monkeypatch.setenv("LSLAPICFG", str(cfg))
    return cfg


@pytest.fixture(scope="session")
def chromium():
    """One headless chromium per test process (a second Playwright in one thread cannot start)."""
    if not CHROMIUM.exists():
        pytest.skip("Debian's chromium is not installed (apt-get install chromium)")
    sync_api = pytest.importorskip("playwright.sync_api")
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        try:
            yield browser
        finally:
            browser.close()
# Python's bytecode cache, pytest's cache and the install's own files: not written by a test.
_NOT_FROM_TESTS = ("__pycache__/", ".pytest_cache/", ".venv/", ".egg-info/")


def _checkout_state() -> set[str] | None:
    try:
        out = subprocess.run(["git", "status", "--porcelain", "--ignored", "--untracked-files=all"], cwd=ROOT,
                             capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.SubprocessError):
        return None
    if out.returncode != 0:
        return None  # not a git checkout (an sdist): nothing to compare
    return {line for line in out.stdout.splitlines() if not any(part in line for part in _NOT_FROM_TESTS)}


def pytest_sessionstart(session):
    if not hasattr(session.config, "workerinput"):  # once, in the controller of an xdist run
        session.config._checkout_before = _checkout_state()


def pytest_sessionfinish(session, exitstatus):
    before = getattr(session.config, "_checkout_before", None)
    if before is None:
        return
    new = sorted((_checkout_state() or set()) - before)
    if new:
        session.config.get_terminal_writer().line(
            "the test suite wrote into the checkout (tests must write to tmp_path):\n  " + "\n  ".join(new[:20]),
            red=True)
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


#: Fixtures that make a test need a real outside part, and the marker that says so. A test
#: needs one when the fixture is in its closure (tests/web's ``page`` requests ``chromium``),
#: never because an argument has a fixture's name: a docs check parametrized over a ``page``
#: of the docs needs no browser.
_MARK_BY_FIXTURE = {"jack_server": "jack", "chromium": "browser"}


def _uses_fixture(item, name: str) -> bool:
    """Whether ``item`` requests the fixture ``name`` (itself or through another fixture)."""
    info = getattr(item, "_fixtureinfo", None)
    if info is None:
        return False
    return bool(info.name2fixturedefs.get(name)) and name in item.fixturenames


def pytest_collection_modifyitems(config, items):
    # Marked by what they use, so `-m "not jack"` or `-m "not browser"` cannot miss one.
    for item in items:
        for fixture, marker in _MARK_BY_FIXTURE.items():
            if _uses_fixture(item, fixture):
                item.add_marker(getattr(pytest.mark, marker))
