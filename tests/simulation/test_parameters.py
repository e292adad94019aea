"""Tests of vibrofocus.simulation.parameters (a hypothesis' free parameters)."""

import pytest

from vibrofocus.errors import ValidationError
from vibrofocus.simulation import ParameterRange, PerceptualModel
from vibrofocus.simulation.parameters import apply_parameters, read_parameters


def test_apply_then_read_round_trips_scalar_and_pair_element():
    ranges = (ParameterRange("sl_ref_db", 5.0, 30.0, "assumption: test"),
              ParameterRange("acuity_sd_m", 1e-3, 20e-3, "assumption: test", index=1))
    model = apply_parameters(PerceptualModel(), ranges, [12.5, 9e-3])
    assert model.sl_ref_db == 12.5
    assert model.acuity_sd_m == (PerceptualModel().acuity_sd_m[0], 9e-3)
    assert read_parameters(model, ranges) == [12.5, 9e-3]
    by_key = apply_parameters(PerceptualModel(), ranges, {"sl_ref_db": 12.5, "acuity_sd_m[1]": 9e-3})
    assert by_key == model


@pytest.mark.parametrize("kwargs, words", [
    (dict(name="nope", lo=0, hi=1, source="x"), "unknown"),
    (dict(name="acuity_sd_m", lo=0, hi=1, source="x"), "index"),
    (dict(name="sl_ref_db", lo=0, hi=1, source="x", index=0), "index"),
    (dict(name="sl_ref_db", lo=2, hi=1, source="x"), "below"),
    (dict(name="sl_ref_db", lo=0, hi=float("nan"), source="x"), "hi"),
    (dict(name="sl_ref_db", lo=0, hi=1, source=" "), "source"),
])
def test_bad_ranges_are_refused(kwargs, words):
    with pytest.raises(ValidationError, match=words):
        ParameterRange(**kwargs)


def test_value_outside_range_is_refused():
    ranges = (ParameterRange("sl_ref_db", 5.0, 30.0, "assumption: test"),)
    with pytest.raises(ValidationError, match="sl_ref_db"):
        apply_parameters(PerceptualModel(), ranges, [31.0])


def test_the_ends_of_a_population_range_are_kept_in_order():
    ranges = (ParameterRange("acuity_sd_m", 1e-3, 20e-3, "assumption: test", index=0),
              ParameterRange("sl_ref_db", 5.0, 30.0, "assumption: test"),
              ParameterRange("acuity_sd_m", 1e-3, 20e-3, "assumption: test", index=1))
    from vibrofocus.simulation.parameters import ordered_pairs

    assert ordered_pairs(ranges, [9e-3, 10.0, 4e-3]) == [4e-3, 10.0, 9e-3]
    assert ordered_pairs(ranges, [4e-3, 10.0, 9e-3]) == [4e-3, 10.0, 9e-3]
    assert ordered_pairs(ranges[::-1], [9e-3, 10.0, 4e-3]) == [9e-3, 10.0, 4e-3]  # index 1 first: already in order
