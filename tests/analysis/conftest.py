"""Fixtures of the analysis tests: seeded synthetic trial files (see ``synthetic.py``)."""

from __future__ import annotations

import pytest

from .synthetic import make_trials


@pytest.fixture
def synthetic():
    """The generator :func:`make_trials`."""
    return make_trials


@pytest.fixture
def planted_csv(tmp_path):
    """A trials CSV with planted effects: funneling less accurate and more locations selected."""
    df = make_trials(
        12,
        seed=11,
        sd_mm={"funneling": 9.0, "inverse": 4.5, "combination": 5.0},
        extra_mean={"funneling": 2.0, "inverse": 0.6, "combination": 0.7},
    )
    path = tmp_path / "trials.csv"
    df.to_csv(path, index=False)
    return path
