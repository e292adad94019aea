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
