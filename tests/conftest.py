"""Shared fixtures. Every random generator in the tests is seeded."""

import numpy as np
import pytest

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
