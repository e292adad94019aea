"""The top-level package: its public names, its version, and what importing it loads."""

import subprocess
import sys

import pytest

import vibrofocus


@pytest.mark.parametrize("name", [n for n in vibrofocus.__all__ if n != "__version__"])
def test_every_public_name_resolves(name):
    assert getattr(vibrofocus, name) is not None
    assert name in dir(vibrofocus)


def test_unknown_attribute_is_an_attribute_error():
    with pytest.raises(AttributeError, match="has no attribute 'not_a_thing'"):
        vibrofocus.not_a_thing  # noqa: B018


def test_importing_the_package_loads_no_heavy_dependency():
    # In a fresh interpreter: the CLI's --help and light scripts must not pay for SciPy's
    # signal stack, the skin model, xarray or pingouin until they use them.
    code = (
        "import sys, vibrofocus, vibrofocus.cli.main; "
        "print(sorted(m for m in ('scipy.signal', 'vibrofocus.skin', 'xarray', 'pingouin', 'matplotlib', "
        "'fastapi') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_spec_contract_names_are_top_level():
    # The public API: importable from the top-level package.
    from vibrofocus import focus_metrics, funneling_gains, inverse_filter, ricker  # noqa: F401
