"""Tests of the per-participant parameters and their random draw."""

import numpy as np
import pytest

from vibrofocus import ArrayLayout
from vibrofocus.errors import ValidationError
from vibrofocus.skin import ForearmParameters
from vibrofocus.skin import parameters as P


def test_same_seed_same_participant_and_different_seeds_differ(reference_layout):
    a = ForearmParameters.draw(7, reference_layout)
    b = ForearmParameters.draw(7, reference_layout)
    c = ForearmParameters.draw(8, reference_layout)
    assert a.to_dict() == b.to_dict()
    assert a.shear_modulus_pa != c.shear_modulus_pa
    assert not np.array_equal(a.contact, c.contact)


def test_draws_stay_within_and_fill_the_documented_spreads(reference_layout):
    people = [ForearmParameters.draw(s, reference_layout) for s in range(300)]
    stiffness = np.array([p.shear_modulus_pa for p in people]) / P.NOMINAL_LAW.mu0_pa - 1
    viscosity = np.array([p.spring_pot_pa_sn for p in people]) / P.NOMINAL_LAW.eta_pa_sn - 1
    gains = np.array([p.gains for p in people]) - 1
    f0 = np.array([p.f0_hz for p in people]) / 500.0 - 1
    q = np.array([p.q for p in people])
    contact = np.array([p.contact for p in people])
    wrist = reference_layout.actuators_xy[:, 1] > 0
    for values, half in ((stiffness, P.STIFFNESS_SPREAD), (viscosity, P.VISCOSITY_SPREAD), (gains, 0.10),
                         (f0, 0.10)):
        assert np.abs(values).max() <= half
        assert np.abs(values).max() > 0.9 * half  # the spread is used, not collapsed
    assert q.min() >= P.Q_RANGE[0] and q.max() <= P.Q_RANGE[1]
    assert contact[:, wrist].min() >= 0.4 and contact[:, wrist].min() < 0.45
    assert contact[:, ~wrist].min() >= P.ELBOW_CONTACT_RANGE[0]
    assert contact.max() <= 1.0
    # Wrist-side actuators are worse coupled on average (partial contact).
    assert contact[:, wrist].mean() < contact[:, ~wrist].mean() - 0.1


def test_drawn_wave_laws_cover_the_literature_spread_of_speed_and_attenuation(reference_layout):
    people = [ForearmParameters.draw(s, reference_layout) for s in range(300)]
    nominal = ForearmParameters.nominal(4)
    speed = np.array([p.c250_m_s for p in people]) / nominal.c250_m_s - 1
    atten = np.array([p.alpha250_np_m for p in people]) / nominal.alpha250_np_m - 1
    # At most half the modulus spreads (speed goes as a square root of the modulus), and
    # every drawn law lies between the documented ends of the attenuation range.
    assert np.abs(speed).max() < (P.STIFFNESS_SPREAD + P.VISCOSITY_SPREAD) / 2
    ends = P.attenuation_range_laws()
    lo, hi = (ends[k].attenuation(np.array([250.0]))[0] for k in ("low", "high"))
    alpha = np.array([p.alpha250_np_m for p in people])
    assert lo <= alpha.min() and alpha.max() <= hi
    assert alpha.min() < lo + 0.1 * (hi - lo) and alpha.max() > hi - 0.1 * (hi - lo)  # and fills it


def test_nominal_participant_has_identical_actuators():
    p = ForearmParameters.nominal(3, shear_modulus_pa=8e3)
    assert p.shear_modulus_pa == 8e3
    for name in ("contact", "gains", "f0_hz", "q"):
        assert np.ptp(getattr(p, name)) == 0


def test_nominal_law_is_the_fitted_one_and_is_dispersive():
    p = ForearmParameters.nominal(1)
    f = np.array([100.0, 250.0, 500.0])
    np.testing.assert_allclose(p.phase_speed(f), P.NOMINAL_LAW.phase_speed(f), rtol=1e-12)
    np.testing.assert_allclose(p.attenuation(f), P.NOMINAL_LAW.attenuation(f), rtol=1e-12)
    assert p.phase_speed([100.0])[0] < p.phase_speed([500.0])[0]
    assert p.attenuation([100.0])[0] < p.attenuation([500.0])[0]


@pytest.mark.parametrize("seed", [-1, 1.5, "a", True])
def test_bad_seed_is_refused(seed):
    with pytest.raises(ValidationError, match="seed"):
        ForearmParameters.draw(seed, ArrayLayout.reference())


def test_bad_values_are_refused():
    with pytest.raises(ValidationError, match="contact"):
        ForearmParameters(contact=[1.2], gains=[1.0], f0_hz=[500.0], q=[1.0])
    with pytest.raises(ValidationError, match="gains"):
        ForearmParameters(contact=[1.0], gains=[1.0, 1.0], f0_hz=[500.0], q=[1.0])
    with pytest.raises(ValidationError, match="shear_modulus_pa"):
        ForearmParameters.nominal(1, shear_modulus_pa=-3.0)
    with pytest.raises(ValidationError, match="fractional_order"):
        ForearmParameters.nominal(1, fractional_order=1.5)
    with pytest.raises(ValidationError, match="wrist_y_m"):
        ForearmParameters.nominal(1, wrist_y_m=-0.2)
