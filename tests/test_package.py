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
    # The public API: importable from the top-level package (the design functions still, deprecated).
    from vibrofocus import focus_metrics, ricker  # noqa: F401
    with pytest.warns(DeprecationWarning):
        from vibrofocus import funneling_gains, inverse_filter  # noqa: F401


@pytest.mark.parametrize("name, new", [
    ("Rendering", "vibrofocus.Design"),
    ("inverse_filter", r"vibrofocus.render\(vibrofocus.Inverse\(...\)"),
    ("InverseOperator", r"vibrofocus.render\(vibrofocus.Inverse\(...\)"),
    ("funneling_gains", r"vibrofocus.render\(vibrofocus.Funneling\(...\)"),
    ("minimax_filter", r"vibrofocus.render\(vibrofocus.Minimax\(...\)"),
])
def test_the_other_routes_to_a_tap_are_deprecated_at_the_top(name, new):
    import vibrofocus.rendering

    assert name not in vibrofocus.__all__
    with pytest.warns(DeprecationWarning, match=rf"vibrofocus.{name} is deprecated and will be removed in "
                                                rf"vibrofocus 0.3; use {new}"):
        value = getattr(vibrofocus, name)
    # The same object, kept for one release; each use warns again.
    assert value is getattr(vibrofocus.rendering, "Design" if name == "Rendering" else name)
    with pytest.warns(DeprecationWarning):
        getattr(vibrofocus, name)


def test_rendering_the_former_name_of_design_warns_where_it_was():
    from vibrofocus import rendering
    from vibrofocus.rendering import design

    assert "Rendering" not in rendering.__all__ and "Rendering" not in design.__all__
    for module in (rendering, design):
        with pytest.warns(DeprecationWarning, match=r"Rendering is deprecated .*; use vibrofocus.rendering.Design"):
            assert getattr(module, "Rendering") is rendering.Design
    with pytest.raises(AttributeError, match="has no attribute 'Renderings'"):
        design.Renderings  # noqa: B018


def test_the_primary_route_warns_nothing():
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        for name in ("render", "Design", "Inverse", "Funneling", "Combination", "TimeReversal", "Contrast",
                     "Constrained", "Minimax", "Method"):
            assert name in vibrofocus.__all__ and getattr(vibrofocus, name) is not None


def test_the_renamed_packages_keep_their_former_names_with_a_warning():
    # In a fresh interpreter: a module warns at its first import, at the importer's line. The
    # participant models' new name gives the same objects and warns nothing; vibrofocus's own
    # modules may still import the former name without a warning (their files move later).
    code = """
import warnings
with warnings.catch_warnings(record=True) as first:
    warnings.simplefilter("always", DeprecationWarning)
    import vibrofocus.simulation
print([(w.filename, str(w.message)) for w in first])
warnings.simplefilter("error", DeprecationWarning)
import vibrofocus.participant_models as pm
from vibrofocus.participant_models.perception import PerceptualModel
from vibrofocus.participant_models import fitting
import vibrofocus.studies.bids, vibrofocus.simulation.perception as real
import vibrofocus.simulation.participants as participants
assert PerceptualModel is real.PerceptualModel and pm.SimulatedParticipant is participants.SimulatedParticipant
import vibrofocus.simulation.fitting as real_fitting
assert fitting.__doc__ == real_fitting.__doc__ and fitting.adopt is real_fitting.adopt
from vibrofocus.rigs import SimulatedForearm
warnings.simplefilter("always", DeprecationWarning)
with warnings.catch_warnings(record=True) as caught:
    import vibrofocus.skin as skin
    assert skin.SimulatedForearm is SimulatedForearm and "SimulatedForearm" not in skin.__all__
print(sorted({str(w.message) for w in caught}))
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.splitlines() == [
        "[('<string>', 'vibrofocus.simulation is deprecated and will be removed in vibrofocus 0.3; use "
        "vibrofocus.participant_models')]",
        "['vibrofocus.skin.SimulatedForearm is deprecated and will be removed in vibrofocus 0.3; use "
        "vibrofocus.rigs.SimulatedForearm']"]
    # The former name as an attribute of the package (not yet imported there) warns too.
    with pytest.warns(DeprecationWarning, match="use vibrofocus.participant_models"):
        assert vibrofocus.__getattr__("simulation") is vibrofocus.participant_models
