"""Methods as objects: frozen validated options, design(tm, target), the registry and
methods added from outside the package (register_method, the entry-point group)."""

import dataclasses
from importlib.metadata import EntryPoint

import numpy as np
import pytest
from numpy.testing import assert_allclose

from vibrofocus import ArrayLayout, TransferMatrix, render
from vibrofocus.rendering import render_fitted
from vibrofocus.defaults import METHODS
from vibrofocus.errors import ValidationError
from vibrofocus.rendering import (
    Combination,
    Constrained,
    Contrast,
    Design,
    Funneling,
    Inverse,
    Method,
    Solution,
    TimeReversal,
    available_methods,
    make_method,
    method_class,
    register_method,
    registry,
)

from ._media import FS, layout_medium

N = 2048
REF = ArrayLayout.reference()


@pytest.fixture(scope="module")
def tm():
    return TransferMatrix(layout_medium(REF, N, FS), FS, REF)


@pytest.fixture
def clean_registry(monkeypatch):
    """The registry as the package leaves it, restored after the test."""
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    monkeypatch.setattr(registry, "_entry_points_read", True)
    return registry


@dataclasses.dataclass(frozen=True, kw_only=True)
class Delayed(Method):
    """Every actuator plays the tap ``delay_s`` late, at ``gain_v`` per metre of the tap (a test method).

    Parameters
    ----------
    delay_s : float
        Delay, s.
    gain_v : float
        Drive per metre of asked displacement, V/m.
    """

    delay_s: float = 1e-3
    gain_v: float = 1e6

    def solve(self, p):
        shift = int(round(self.delay_s * p.fs))
        return self.gain_v * np.tile(np.roll(p.reference, shift), (p.tm.n_actuators, 1))


def test_the_six_built_in_methods_are_registered_in_spec_order():
    assert available_methods()[:6] == METHODS
    assert [method_class(m) for m in METHODS] == [Funneling, Inverse, Combination, TimeReversal, Contrast, Constrained]
    assert all(method_class(m).name == m for m in METHODS)


def test_options_are_frozen_and_validated_when_made():
    method = Inverse(regularization="tikhonov", guard_weight=0.5)
    assert method.reg_param == 1e-2 and method.control == "guards" and method.exact_target is False
    assert Combination().exact_target is True and Contrast().control == "all"
    with pytest.raises(dataclasses.FrozenInstanceError):
        method.guard_weight = 2.0
    with pytest.raises(ValidationError, match="guard_weight must be > 0"):
        Inverse(guard_weight=0)
    with pytest.raises(ValidationError, match="regularization must be one of"):
        Inverse(regularization="lasso")
    with pytest.raises(ValidationError, match="control='field' is for the contrast designs"):
        TimeReversal(control="field")
    with pytest.raises(ValidationError, match="both control='field' and field="):
        Contrast(control="field")
    with pytest.raises(ValidationError, match="limit_v must be > 0"):
        Funneling(limit_v=-1)
    with pytest.raises(TypeError):
        Inverse(0.5)  # options by keyword only


def test_design_holds_drives_prediction_metrics_and_bound(tm):
    d = Inverse(limit_v=5.0).design(tm, 5)
    assert isinstance(d, Design) and d.method == "inverse" and d.location == 5 and d.target_index == 4
    assert d.drives.shape == (REF.n_actuators, N) and d.predicted.shape == (REF.n_points, N)
    assert_allclose(np.abs(d.drives).max(), 5.0, rtol=1e-12)
    # The prediction is H applied to the drives, at every calibrated point.
    expected = np.fft.irfft(np.einsum("fpq,qf->pf", tm.H, np.fft.rfft(d.drives, axis=1)), N, axis=1)
    assert_allclose(d.predicted, expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    metrics = d.metrics()
    assert {"fidelity", "energy_contrast_db", "bound_db", "bound_all_db"} <= set(metrics)
    assert metrics["energy_contrast_db"] <= metrics["bound_db"] + 1e-6


def test_render_keeps_the_string_api_and_refuses_an_unknown_option(tm):
    a = render("combination", tm, FS, REF, 3, funneling_law="energy")
    b = make_method("combination", funneling_law="energy").design(tm, 3)
    assert_allclose(a.drives, b.drives, rtol=0, atol=0)
    # An option of the former render that a method does not have is ignored, as it was.
    render("funneling", tm, FS, REF, 3, regularization="tikhonov")
    with pytest.raises(ValidationError, match="method 'inverse' has no option wobble"):
        render("inverse", tm, FS, REF, 3, wobble=1)
    with pytest.raises(ValidationError, match="options of method='constrained'"):
        render("contrast", tm, FS, REF, 3, min_contrast_db=3.0)


def test_render_takes_a_method_object_and_refuses_options_beside_it(tm):
    by_object = render(Inverse(regularization="tikhonov", limit_v=5.0), tm, FS, REF, 3)
    by_name = render("inverse", tm, FS, REF, 3, regularization="tikhonov", limit_v=5.0)
    assert by_object.method == "inverse"
    assert_allclose(by_object.drives, by_name.drives, rtol=0, atol=0)
    with pytest.raises(ValidationError, match=r"render takes no option limit_v beside a method object: give it to "
                                              r"the method \(Inverse\(limit_v=...\)\); its options are .*guard_weight"
                                              r".*; render's own keywords are target_xy, n_samples, calibrated_band"):
        render(Inverse(), tm, FS, REF, 3, limit_v=5.0)
    with pytest.raises(ValidationError, match="method must be a Method object or a registered method's name, got "
                                              "type"):
        render(Inverse, tm, FS, REF, 3)
    # render_fitted takes the object too (its retry with tapered ends is a copy of it).
    fitted = render_fitted(Inverse(regularization="tikhonov", limit_v=5.0), tm, FS, REF, 3)
    assert_allclose(fitted.drives, by_object.drives, rtol=0, atol=0)


def test_a_registered_method_runs_in_render(tm, clean_registry):
    register_method("delayed", Delayed)
    assert "delayed" in available_methods()
    d = render("delayed", tm, FS, REF, 2, delay_s=2e-3, scale_to_limit=False, limit_v=1e3)
    assert d.method == "delayed"
    # Analytic: every drive is the band-limited tap, 20 samples late, times the gain.
    assert_allclose(d.drives, 1e6 * np.tile(np.roll(d.reference, 20), (REF.n_actuators, 1)), rtol=1e-12)


def test_a_registered_method_runs_in_the_demo(clean_registry):
    from vibrofocus.demo import run_demo
    from vibrofocus.rigs import SimulatedForearm

    register_method("delayed", Delayed)
    rig = SimulatedForearm(seed=0, noise_m=0.0, dropout_rate=0.0)
    result = run_demo(rig, methods=["delayed"], locations=[5])
    assert [row["method"] for row in result.rows] == ["delayed"]
    assert result.renderings[(5, "delayed")].method == "delayed"


def test_register_method_refuses_what_is_not_a_method_and_a_second_owner_of_a_name(clean_registry):
    with pytest.raises(ValidationError, match="must be a dataclass subclass"):
        register_method("plain", object)
    with pytest.raises(ValidationError, match="identifier"):
        register_method("two words", Delayed)
    with pytest.raises(ValidationError, match="registered already"):
        register_method("inverse", Delayed)
    @dataclasses.dataclass(frozen=True, kw_only=True)
    class Replacement(Delayed):
        pass

    register_method("inverse", Replacement, replace=True)
    assert method_class("inverse") is Replacement and Replacement.name == "inverse"


def test_solve_may_return_a_solution_or_bare_drives(tm, clean_registry):
    @register_method("halved")
    @dataclasses.dataclass(frozen=True, kw_only=True)
    class Halved(Delayed):
        def solve(self, p):
            return Solution(0.5 * super().solve(p), control_indices=np.array([p.target_index]))

    d = render("halved", tm, FS, REF, 2, scale_to_limit=False, limit_v=1e3)
    full = Delayed(scale_to_limit=False, limit_v=1e3).design(tm, 2)
    assert d.method == "halved"
    assert_allclose(d.drives, 0.5 * full.drives, rtol=1e-12)
    assert d.control_indices.tolist() == [1]


def test_methods_of_installed_packages_come_through_the_entry_point_group(monkeypatch, clean_registry):
    module = __name__
    points = [EntryPoint("delayed_ep", f"{module}:Delayed", registry.ENTRY_POINT_GROUP),
              EntryPoint("broken_ep", f"{module}:NoSuchThing", registry.ENTRY_POINT_GROUP)]
    seen = {}

    def fake_entry_points(*, group):
        seen["group"] = group
        return points

    monkeypatch.setattr(registry, "entry_points", fake_entry_points)
    monkeypatch.setattr(registry, "_entry_points_read", False)
    with pytest.warns(RuntimeWarning, match="broken_ep"):
        names = available_methods()
    assert seen["group"] == "vibrofocus.methods"
    assert "delayed_ep" in names and "broken_ep" not in names and method_class("delayed_ep") is Delayed
    assert isinstance(render("delayed_ep", TransferMatrix(layout_medium(REF, N, FS), FS, REF), FS, REF, 1), Design)
