"""The simulated participants' perceptual model v3: each component against its cited
curve or law, seeded answers, and the engine responder interface."""

import numpy as np
import pytest

from vibrofocus.errors import StudyError, ValidationError
from vibrofocus.rendering import render
from vibrofocus.rigs import make_rig
from vibrofocus.studies import StudyDesign
from vibrofocus.simulation.participants import MODEL_NOTICE, PerceptualModel, SimulatedParticipant
from vibrofocus.simulation.perception import (
    MODEL_LABEL,
    Percepts,
    actuator_energy,
    band_transfer,
    Traits,
    central_percepts,
    draw_answers,
    felt_energy,
    psychophysics_data,
    reference_felt_energy,
    threshold_db,
    threshold_weight,
)

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


# ---------------------------------------------------------------- components vs sources
def test_threshold_curve_is_verrillos_u_curve():
    # Gescheider & Verrillo 1979 (Verrillo 1963): flat to 40 Hz, then -12 dB/octave to a
    # minimum at 250 Hz; the rise above 250 Hz is an assumption (+12 dB/octave).
    f = np.array([10, 20, 40, 80, 160, 250, 500, 1000.0])
    expected = np.array([12 * np.log2(250 / 40)] * 3 + [12 * np.log2(250 / 80), 12 * np.log2(250 / 160), 0, 12, 24])
    np.testing.assert_allclose(threshold_db(f), expected, atol=0.01)
    fine = np.geomspace(20, 1000, 400)
    assert fine[np.argmin(threshold_db(fine))] == pytest.approx(250, rel=0.01)
    # The data file holds the points to 0.01 dB: 1e-3 relative in power.
    np.testing.assert_allclose(threshold_weight(np.array([250.0, 125.0])), [1.0, 10 ** (-1.2)], rtol=1e-3)


def test_funneling_follows_the_energy_law():
    # Alles 1970 / Israr & Poupyrev 2011: amplitudes sqrt(1 - b) and sqrt(b) put the phantom
    # b of the way from site 1 to site 2. Energies far above threshold, exponent 1.
    model = PerceptualModel(funneling_exponent=1.0, sl_ref_db=80.0)
    traits = Traits.draw(model, 0)
    pts = np.array([[-0.02, 0.0], [0.025, 0.0]])
    for b in (0.1, 0.3, 0.5, 0.8):
        e = np.array([[1.0 - b, b]])  # energy ∝ amplitude²
        p = central_percepts(e, pts, model, traits)
        np.testing.assert_allclose(p.position_m[0], pts[0] + b * (pts[1] - pts[0]), atol=1e-6)


def test_funneling_is_coded_from_what_the_actuators_deliver():
    # The paper's Sec. IV: funneling is coded centrally. With the drive cue's weight 1 the
    # place follows the energy law over the actuators' delivered energies, whatever the
    # skin cue says; with weight 0.5 it lies halfway between the two cues, and the cues'
    # distance is the conflict.
    acts = np.array([[-0.0225, 0.0], [0.0225, 0.0]])
    pts = np.array([[0.0, 0.01], [0.0, 0.02]])
    skin = np.array([[1.0, 1.0]])  # skin cue at (0, 0.015)
    for b in (0.2, 0.5, 0.9):
        delivered = np.array([[1.0 - b, b]])
        drive_cue = acts[0] + b * (acts[1] - acts[0])
        for beta in (1.0, 0.5):
            model = PerceptualModel(funneling_exponent=1.0, sl_ref_db=80.0, central_weight=beta)
            p = central_percepts(skin, pts, model, Traits.draw(model, 0), delivered, acts)
            np.testing.assert_allclose(p.position_m[0], (1 - beta) * np.array([0.0, 0.015]) + beta * drive_cue,
                                       atol=1e-9)
            np.testing.assert_allclose(p.conflict_m[0], np.hypot(drive_cue[0], 0.015), rtol=1e-6)  # threshold: 1e-8
            np.testing.assert_allclose(p.drive_position_m[0], drive_cue, atol=1e-9)


def test_cue_conflict_makes_a_less_certain_percept():
    model = PerceptualModel(conflict_gain=1.0)
    traits = Traits(0.0, 6e-3, 12e-3, np.zeros(2), 0.4, 1.0, spread_gain=0.0)
    locs = np.array([[x, y] for y in (0.01, 0, -0.01) for x in (-0.01, 0, 0.01)])
    target = np.array([-0.01, 0.01])
    res = {}
    for conflict in (0.0, 0.02):
        p = Percepts(target[None], np.zeros(1), np.array([True]), np.array([conflict]))
        a, sel, _ = draw_answers(p, np.zeros(4000, int), locs, np.zeros(2), model, traits, np.random.default_rng(1))
        res[conflict] = (np.mean(a == 0), sel.sum(1).mean())
    assert res[0.02][0] < res[0.0][0] - 0.1
    assert res[0.02][1] > res[0.0][1] + 0.3


def test_a_partly_coupled_actuator_delivers_less():
    # The paper's Sec. IV: the wrist-side exciters were only partly in contact. The same
    # participant's forearm with every actuator in full contact: each partly coupled
    # actuator delivers less of the same drive at its contact; the fully coupled ones the same.
    from dataclasses import replace

    from vibrofocus.rigs import SimulatedForearm

    loose = make_rig("simulated", seed=3, skin="nominal")
    contact = np.asarray(loose.participant.contact)
    assert contact.min() < 0.5 and contact.max() < 1.0
    firm = SimulatedForearm(seed=3, skin="nominal", participant=replace(loose.participant, contact=np.ones_like(contact)))
    acts = np.asarray(loose.layout.actuators_xy, dtype=float)
    tap = render("funneling", loose.transfer(loose.layout.points_xy, np.fft.rfftfreq(N, 1 / loose.fs)), loose.fs,
                 loose.layout, 5).drives[None]
    ratio = actuator_energy(loose, acts, tap)[0] / actuator_energy(firm, acts, tap)[0]
    np.testing.assert_array_less(ratio, 1.0)  # every contact of this participant is < 1
    assert np.array_equal(np.argsort(ratio), np.argsort(contact)), (ratio, contact)  # looser delivers less
    assert ratio[np.argmin(contact)] < 0.5


def test_detection_threshold_decides_what_is_felt():
    model = PerceptualModel(sl_ref_db=20.0, threshold_sd_db=0.0)
    traits = Traits.draw(model, 0)
    pts = np.array([[0.0, 0.0], [0.01, 0.0]])
    # The reference tap is felt 20 dB above threshold: -19 dB re it is felt, -21 dB is not.
    e = np.array([[10 ** -1.9, 0.0], [10 ** -2.1, 0.0]])
    p = central_percepts(e, pts, model, traits)
    assert p.felt.tolist() == [True, False]


def _one(position, spread=0.0):
    return Percepts(np.array([position], dtype=float), np.array([spread]), np.array([True]))


def test_central_bias_is_the_bayesian_posterior_mean():
    model = PerceptualModel(bias_mean_m=(0.0, 0.0), bias_sd_m=0.0)
    traits = Traits(0.0, 8e-3, 10e-3, np.zeros(2), 0.5, 1.0, spread_gain=0.0)
    locs = np.array([[x, y] for y in (0.01, 0, -0.01) for x in (-0.01, 0, 0.01)])
    x = np.array([0.01, 0.0])
    n = 20000
    rng = np.random.default_rng(4)
    # Independent reference: posterior mean gain of a Gaussian prior and likelihood.
    g = 10e-3**2 / (10e-3**2 + 8e-3**2)
    a, _, _ = draw_answers(_one(x), np.zeros(n, int), locs, np.zeros(2), model, traits, rng)
    # Re-derive the perceived positions from the same noise stream.
    noise = np.random.default_rng(4).standard_normal((n, 2))
    perceived = g * (x + 8e-3 * noise)
    np.testing.assert_array_equal(a, np.argmin(((locs[None] - perceived[:, None]) ** 2).sum(2), axis=1))
    # And its statistics: mean pulled to g x, SD g * acuity (3 SE tolerances).
    np.testing.assert_allclose(perceived.mean(0), g * x, atol=3 * g * 8e-3 / np.sqrt(n))
    np.testing.assert_allclose(perceived.std(0), g * 8e-3, rtol=0.03)


def test_a_diffuse_percept_is_localized_worse_and_selects_more():
    # Park & Choi 2018: phantoms are perceived over distributed positions -> more noise,
    # stronger central pull, and (Study 2) more locations selected.
    model = PerceptualModel()
    traits = Traits(0.0, 6e-3, 12e-3, np.zeros(2), 0.4, 1.0, spread_gain=1.0)
    locs = np.array([[x, y] for y in (0.01, 0, -0.01) for x in (-0.01, 0, 0.01)])
    target = np.array([-0.01, 0.01])
    res = {}
    for spread in (0.0, 0.02):
        a, sel, _ = draw_answers(_one(target, spread), np.zeros(4000, int), locs, np.zeros(2), model, traits,
                                 np.random.default_rng(1))
        res[spread] = (np.mean(a == 0), sel.sum(1).mean())
    assert res[0.02][0] < res[0.0][0] - 0.1
    assert res[0.02][1] > res[0.0][1] + 0.3


def test_study2_selects_by_posterior_density_ratio():
    # The selection rule: every location whose posterior density (Gaussian, mean the
    # percept, variance g * sigma_s^2) reaches kappa * jitter of the best location's.
    # Independent reference with scipy's normal density, from the same noise stream.
    from scipy.stats import norm

    model = PerceptualModel(select_log_sd=0.4)
    traits = Traits(0.0, 7e-3, 11e-3, np.zeros(2), 0.35, 1.0, spread_gain=0.0)
    locs = np.array([[x, y] for y in (0.01, 0, -0.01) for x in (-0.01, 0, 0.01)])
    x = np.array([-0.004, 0.006])
    n = 3000
    a, sel, _ = draw_answers(_one(x), np.zeros(n, int), locs, np.zeros(2), model, traits, np.random.default_rng(9))
    ref = np.random.default_rng(9)
    noise, jitter = ref.standard_normal((n, 2)), ref.lognormal(0.0, 0.4, size=n)
    g = 11e-3**2 / (11e-3**2 + 7e-3**2)
    post = g * (x + 7e-3 * noise)
    sd = np.sqrt(g) * 7e-3
    dens = norm.pdf(locs[None, :, 0], post[:, None, 0], sd) * norm.pdf(locs[None, :, 1], post[:, None, 1], sd)
    expected = dens / dens.max(axis=1, keepdims=True) >= np.clip(0.35 * jitter, 0, 1)[:, None]
    np.testing.assert_array_equal(a, dens.argmax(axis=1))
    np.testing.assert_array_equal(sel, expected)
    assert 1.2 < sel.sum(1).mean() < 8  # several locations at times, not all


def _conflicted(position, conflict_m):
    return Percepts(np.array([position], dtype=float), np.array([0.0]), np.array([True]), np.array([conflict_m]))


@pytest.mark.parametrize("awareness", [0.6, 1.0])
def test_conflict_awareness_leaves_the_place_and_widens_with_the_trials_own_discrepancy(awareness):
    from scipy.stats import spearmanr

    from vibrofocus.simulation.perception import trial_posteriors

    acuity, prior, gain, conflict = 5e-3, 12e-3, 2.0, 4e-3
    traits = Traits(0.0, acuity, prior, np.zeros(2), 0.5, 1.0, spread_gain=0.0)
    x = np.array([0.006, -0.004])
    n = 40000
    rng = np.random.default_rng(31)
    noise, by_conflict = rng.standard_normal((n, 2)), rng.standard_normal((n, 2))
    percepts, index = _conflicted(x, conflict), np.zeros(n, int)
    fused = trial_posteriors(percepts, index, np.zeros(2), PerceptualModel(conflict_gain=gain), traits, noise)
    aware = trial_posteriors(percepts, index, np.zeros(2),
                             PerceptualModel(conflict_gain=gain, conflict_awareness=awareness), traits, noise,
                             by_conflict)
    # The place, in law: mean g x and SD g * sqrt(acuity^2 + (gain * conflict)^2) per axis
    # (Gaussian prior and likelihood), as without awareness; 3 SE tolerances.
    sig2 = acuity**2 + (gain * conflict) ** 2
    g = prior**2 / (prior**2 + sig2)
    np.testing.assert_allclose(aware.perceived_m.mean(0), g * x, atol=3 * g * np.sqrt(sig2 / n))
    np.testing.assert_allclose(aware.perceived_m.std(0), g * np.sqrt(sig2), rtol=0.02)
    np.testing.assert_allclose(fused.sd_m, np.sqrt(g * sig2), rtol=1e-12)  # v3: one width per stimulus
    # The width: sd^2 = w p^2 / (p^2 + w) with w = acuity^2 + awareness^2 |v|^2 / 2, and
    # E[|v|^2 / 2] = (gain * conflict)^2, so E[w] = acuity^2 + awareness^2 (gain * conflict)^2.
    w = prior**2 * aware.sd_m**2 / (prior**2 - aware.sd_m**2)
    expected = acuity**2 + awareness**2 * (gain * conflict) ** 2
    np.testing.assert_allclose(w.mean(), expected, rtol=0.02)
    assert w.min() >= acuity**2 * (1 - 1e-9)  # never narrower than the other noise alone
    # Wider on the trials the conflict displaced more: the width follows this trial's error.
    error = np.linalg.norm(aware.perceived_m - g * x, axis=1)
    assert spearmanr(aware.sd_m, error).statistic > 0.5


def test_without_conflict_awareness_the_draws_are_unchanged():
    """conflict_awareness = 0 draws nothing more, so the answers of the shipped fits stay as they were."""
    model = PerceptualModel(conflict_gain=2.0)
    traits = Traits(0.0, 5e-3, 12e-3, np.zeros(2), 0.5, 1.0, spread_gain=0.0)
    locs = np.array([[x, y] for y in (0.01, 0, -0.01) for x in (-0.01, 0, 0.01)])
    percepts = _conflicted([0.004, 0.002], 4e-3)
    runs = [draw_answers(percepts, np.zeros(500, int), locs, np.zeros(2), m, traits, np.random.default_rng(5))
            for m in (model, model.replace(conflict_awareness=0.0), model.replace(conflict_awareness=1.0))]
    for x, y in zip(runs[0], runs[1]):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(runs[0][1], runs[2][1])  # the selection reads the discrepancy


def test_population_bias_points_toward_the_elbow():
    # Cholewiak et al. 2020: the forearm's perceived midpoint lies toward the elbow (-y).
    model = PerceptualModel()
    assert model.bias_mean_m[1] < 0
    biases = np.array([Traits.draw(model, k).bias_m for k in range(400)])
    assert biases[:, 1].mean() < 0
    assert abs(biases[:, 1].mean() - model.bias_mean_m[1]) < 3 * model.bias_sd_m / np.sqrt(400)


def test_selection_always_contains_the_single_answer():
    model = PerceptualModel()
    traits = Traits.draw(model, 3)
    locs = np.array([[x, y] for y in (0.01, 0, -0.01) for x in (-0.01, 0, 0.01)])
    a, sel, rt = draw_answers(_one([0.004, -0.002], 0.01), np.zeros(500, int), locs, np.zeros(2), model, traits,
                              np.random.default_rng(2))
    assert sel[np.arange(500), a].all() and (rt > 0).all()


def test_felt_energy_matches_the_skin_field(rig, drives):
    # Independent reference: the time-domain field of SimulatedForearm.field, weighted by the
    # threshold curve in frequency and integrated (Parseval), over the reference tap's.
    model = PerceptualModel(band_hz=(10.0, 1000.0))
    p = SimulatedParticipant(rig, seed=1, model=model)
    d = drives[("inverse", 5)]
    pts = p.grid_xy[::17]
    n = 16384
    u = rig.field(d, pts, tail_s=(n - d.shape[1]) / rig.fs)[:, :n]
    U = np.fft.rfft(u, n, axis=1)
    f = np.fft.rfftfreq(n, 1 / rig.fs)
    band = (f >= 10) & (f <= 1000)
    e = 2 * np.sum(np.abs(U[:, band]) ** 2 * threshold_weight(f[band]), axis=1) / (n * rig.fs)
    got = p.energy(d)[::17] * reference_felt_energy(rig.fs, d.shape[1], model)
    np.testing.assert_allclose(got, e, rtol=0.03)


def test_data_file_has_the_paper_statistics():
    paper = psychophysics_data()["paper_statistics"]
    # As printed in the paper (Sec. III.B-C).
    assert paper["study1_location"]["F"] == 10.958 and paper["study2_location"]["chi2"] == 30.749
    assert paper["study2_method"]["chi2"] == 15.797 and paper["study2_method"]["reduction"] == 0.20


# ---------------------------------------------------------------- responder
def test_percept_follows_the_target_across_the_arm(participant, drives):
    for method in ("funneling", "inverse"):
        xs = [participant.percept(drives[(method, loc)]).position_m[0, 0] for loc in (4, 5, 6)]
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
    design2 = StudyDesign(study=2, locations=(4, 5))
    sels = {x for k in range(40) for x in participant.answer(drives[("funneling", 6)], 2, k, design2).locations}
    assert sels <= {4, 5}


def test_different_participants_differ_and_are_labelled(rig):
    a, b = SimulatedParticipant(rig, seed=1), SimulatedParticipant(rig, seed=2)
    assert a.traits.to_dict() != b.traits.to_dict()
    assert a.describe()["model"] == MODEL_LABEL and "not data" in MODEL_LABEL and "v3" in MODEL_LABEL
    assert "not data" in MODEL_NOTICE or "not from people" in MODEL_NOTICE


def test_bad_input_is_refused(rig, participant):
    with pytest.raises(StudyError, match="simulated forearm"):
        SimulatedParticipant(object(), seed=1)
    with pytest.raises(StudyError, match="seed"):
        SimulatedParticipant(rig, seed=-3)
    with pytest.raises(StudyError, match="shape"):
        participant.energy(np.zeros((3, 100)))
    with pytest.raises(StudyError, match="no vibration"):
        participant.percept(np.zeros((4, 100)))
    with pytest.raises(ValidationError):
        threshold_db(np.array([0.0]))
    with pytest.raises(ValidationError):
        PerceptualModel().replace(nonsense=1)


def test_short_integration_window_takes_the_largest_windowed_energy(rig, drives):
    # Independent reference: the time-domain field, threshold-weighted in frequency, then a
    # moving sum by np.convolve on a zero-padded (non-circular) record and its maximum.
    fs, win = rig.fs, 2e-3
    model = PerceptualModel(band_hz=(10.0, 1000.0), integration_s=win)
    p = SimulatedParticipant(rig, seed=1, model=model)
    d = drives[("inverse", 5)]
    pts = p.grid_xy[::17]
    n = 16384
    u = rig.field(d, pts, tail_s=(n - d.shape[1]) / fs)[:, :n]
    f = np.fft.rfftfreq(n, 1 / fs)
    band = (f >= 10) & (f <= 1000)
    U = np.fft.rfft(u, n, axis=1) * np.where(band, np.sqrt(threshold_weight(np.where(band, f, 1.0))), 0.0)
    power = np.fft.irfft(U, n, axis=1) ** 2
    k = int(round(win * fs))
    want = np.array([np.convolve(row, np.ones(k), mode="valid").max() for row in power]) / fs
    got = p.energy(d)[::17] * reference_felt_energy(fs, d.shape[1], model)
    np.testing.assert_allclose(got, want, rtol=0.03)
    # A window that spans the stimulus gives the whole energy; shorter ones never more.
    whole = felt_energy(band_transfer(rig, pts, d.shape[1]), d, fs)
    assert np.all(got <= whole * reference_felt_energy(fs, d.shape[1]) * (1 + 1e-9))


def test_integration_window_must_be_positive():
    with pytest.raises(ValidationError, match="integration_s"):
        reference_felt_energy(10_000.0, 1024, PerceptualModel(integration_s=0.0))



def test_every_trial_of_a_multi_block_protocol_has_its_own_noise(participant, drives):
    """Trial k of block 0 and of block 1 (same stimulus) draw their own noise; block 0 keeps
    the streams of before, (seed, study, trial index), so the paper's studies keep their answers."""
    from vibrofocus.studies.engine import Presentation
    from vibrofocus.studies.protocol import PlannedTrial, StudyDesign

    d = drives[("inverse", 4)]
    design = StudyDesign(study=1)

    def shown(k, block):
        trial = PlannedTrial(1, k, "main", k, "inverse", 4)
        return Presentation(1, 1, trial, type("S", (), {"drives": d})(), 0.0, design, block=block)

    first = [participant.respond(shown(k, 0)) for k in range(12)]
    second = [participant.respond(shown(k, 1)) for k in range(12)]
    assert all(a.rt_s != b.rt_s for a, b in zip(first, second))  # a continuous draw: equal only from one stream
    assert first == [participant.answer(d, 1, k, design) for k in range(12)]
    with pytest.raises(StudyError, match="block"):
        participant.answer(d, 1, 0, design, block=-1)
