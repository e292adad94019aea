"""Strap force sensors: calibration curve, verdicts against the 1 N target, storage forms."""

from __future__ import annotations

import json

import numpy as np
import pytest

from vibrofocus.errors import ValidationError
from vibrofocus.rigs import DeviceError, ForceCurve, StrapSensors, check_straps, evaluate_straps


def test_default_curve_follows_the_divider_model():
    curve = ForceCurve.default()
    # F = k V / (R_m (V_s - V)) with k = 10 kOhm N, R_m = 10 kOhm, V_s = 5 V: 1 N reads 2.5 V
    assert curve(np.array(2.5)) == pytest.approx(1.0)
    v = np.array([0.8, 1.7, 3.1])
    model = 10e3 * v / (10e3 * (5.0 - v))
    np.testing.assert_allclose(curve(v), model, rtol=0.1)  # piecewise-linear between table points
    assert curve(np.array(-0.1)) == 0.0
    assert np.isnan(curve(np.array(4.9)))  # beyond the table: out of range, not a guess


def test_bad_curves_are_refused():
    with pytest.raises(ValidationError, match="strictly increasing"):
        ForceCurve([0, 1, 1], [0, 1, 2])
    with pytest.raises(ValidationError, match="non-decreasing"):
        ForceCurve([0, 1, 2], [0, 2, 1])
    with pytest.raises(ValidationError, match="at least 2"):
        ForceCurve([0, 1], [0, 1, 2])


def test_verdicts_against_the_target():
    r = evaluate_straps([1.1, 0.6, 1.4, np.nan], names=("a", "b", "c", "d"))
    assert r.verdicts == ("ok", "too loose", "too tight", "out of range")
    assert not r.ok
    assert "b: too loose (0.60 N)" in r.message and "c: too tight (1.40 N)" in r.message
    good = evaluate_straps([0.9, 1.2])
    assert good.ok and good.names == ("strap 1", "strap 2")
    assert good.message.startswith("all 2 straps within 1 ± 0.25 N")
    with pytest.raises(ValidationError, match="names has 1 entries but there are 2 forces"):
        evaluate_straps([1.0, 1.0], names=("a",))


def test_reading_is_storable():
    r = evaluate_straps([1.0, np.nan], names=("proximal", "distal"))
    d = json.loads(json.dumps(r.to_dict()))
    assert d["forces_n"] == [1.0, None] and d["verdicts"] == ["ok", "out of range"] and d["target_n"] == 1.0
    ds = r.to_dataset()
    assert list(ds["strap"].values) == ["proximal", "distal"]
    assert ds["strap_force"].attrs["units"] == "N"
    assert ds.attrs["ok"] == 0


def test_sensors_turn_volts_into_a_reading():
    sensors = StrapSensors(("p", "d"), ForceCurve([0, 1, 2], [0, 1, 2]), target_n=1.0, tolerance_n=0.1)
    r = sensors.reading(np.array([1.05, 0.5]))
    np.testing.assert_allclose(r.forces_n, [1.05, 0.5])
    assert r.verdicts == ("ok", "too loose")


def test_a_rig_without_sensors_says_so():
    class NoSensors:
        kind = "audio"

    with pytest.raises(DeviceError, match="the audio rig has no strap force sensors"):
        check_straps(NoSensors())


def test_check_straps_uses_the_rig_reader_and_overrides():
    class Simulated:
        kind = "simulated"

        def read_strap_forces(self):
            return np.array([1.0, 1.3])

    r = check_straps(Simulated(), tolerance_n=0.5)
    assert r.ok and r.simulated and r.tolerance_n == 0.5
