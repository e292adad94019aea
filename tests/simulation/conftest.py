"""Fixtures of the simulation tests."""

import importlib
import sys
from pathlib import Path

import pytest

SCRIPTS = Path(__file__).resolve().parents[2] / "scripts"


@pytest.fixture(scope="session")
def import_script():
    """Import a module of ``scripts/`` by name (the scripts import each other by bare name)."""
    def load(name: str):
        sys.path.insert(0, str(SCRIPTS))
        try:
            return importlib.import_module(name)
        finally:
            sys.path.pop(0)
    return load
