"""The simulated participants' perceptual model: its energy is the skin field's, its
answers are seeded per trial, its percept follows the stimulus."""

import numpy as np
import pytest

from vibrofocus.errors import StudyError
from vibrofocus.rendering import render
from vibrofocus.rigs import make_rig
from vibrofocus.studies import StudyDesign
from vibrofocus.studies.participants import PerceptualModel, SimulatedParticipant

N = 4096


@pytest.fixture(scope="module")
def rig():
    return make_rig("simulated", seed=8)


@pytest.fixture(scope="module")
def participant(rig):
    return SimulatedParticipant(rig, seed=8)


@pytest.fixture(scope="module")
def drives(rig):
    H = rig.transfer(rig.layout.points_xy, np.fft.rfftfreq(N, 1 / rig.fs))
    return {(m, loc): render(m, H, rig.fs, rig.layout, loc).drives
            for m in ("funneling", "inverse") for loc in (4, 5, 6)}


def test_energy_matches_the_skin_field_by_parseval(rig, drives):
    # Independent reference: integrate u(x, t)^2 from SimulatedForearm.field in time.
    model = PerceptualModel(grid_half_width_m=8e-3, grid_step_m=8e-3, band_hz=(0.0, rig.fs / 2), n_fft=16384)
    p = SimulatedParticipant(rig, seed=1, model=model)
    d = drives[("inverse", 5)]
    points = np.concatenate([p.grid_xy, p.locations_xy])
    u = rig.field(d, points, tail_s=0.6)
    expected = np.sum(u**2, axis=1) / rig.fs
    np.testing.assert_allclose(p.energy(d), expected, rtol=2e-3)


def test_percept_follows_the_target_across_the_arm(participant, drives):
    for method in ("funneling", "inverse"):
        xs = [participant.percept(drives[(method, loc)]).centroid_xy[0] for loc in (4, 5, 6)]
        assert xs[0] < xs[1] < xs[2], (method, xs)


def test_answers_are_seeded_per_trial_and_valid(participant, drives):
    d = drives[("inverse", 4)]
    a = participant.answer(d, 1, 17)
    assert participant.answer(d, 1, 17) == a  # same seed, same trial: same answer
    answers = [participant.answer(d, 1, k) for k in range(60)]
    assert len({r.locations for r in answers}) > 1  # per-trial noise
    assert len({r.rt_s for r in answers}) == 60
    assert all(len(r.locations) == 1 and 1 <= r.locations[0] <= 9 for r in answers)
    assert all(0.2 < r.rt_s < 10 for r in answers)
    multi = [participant.answer(d, 2, k) for k in range(60)]
    assert all(len(set(r.locations)) == len(r.locations) >= 1 for r in multi)
    assert max(len(r.locations) for r in multi) > 1  # Study 2 selects several at times


def test_design_limits_the_answers(participant, drives):
    design = StudyDesign(study=1, locations=(4, 5))
    picks = {participant.answer(drives[("funneling", 6)], 1, k, design).locations[0] for k in range(40)}
    assert picks <= {4, 5}


def test_different_participants_differ(rig):
    a, b = SimulatedParticipant(rig, seed=1), SimulatedParticipant(rig, seed=2)
    assert (a.noise_sd_m, a.rt_median_s) != (b.noise_sd_m, b.rt_median_s)
    assert "not data" in a.describe()["model"]


def test_bad_input_is_refused(rig, participant):
    with pytest.raises(StudyError, match="simulated forearm"):
        SimulatedParticipant(object(), seed=1)
    with pytest.raises(StudyError, match="seed"):
        SimulatedParticipant(rig, seed=-3)
    with pytest.raises(StudyError, match="shape"):
        participant.energy(np.zeros((3, 100)))
    with pytest.raises(StudyError, match="no vibration"):
        participant.percept(np.zeros((4, 100)))
