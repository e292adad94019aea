"""The answer rule's parts (perception.select_locations & co.) and scripts/selection_rules.py."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from vibrofocus.simulation.bank import default_bank, simulate_cell_means
from vibrofocus.simulation.perception import (Percepts, TrialPosteriors, location_distances,
                                              posterior_ratio_rule, select_locations)

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def rules():
    import vibrofocus_tools.selection_rules

    return vibrofocus_tools.selection_rules


def test_select_locations_reads_the_density_ratio_analytically():
    locs = np.array([[0.0, 0.0], [0.01, 0.0], [0.02, 0.0]])
    perceived = np.array([[0.003, 0.0]])
    sd = np.array([0.005])
    d2 = location_distances(perceived, locs)
    # Density of location 2 re location 1: exp(-(7^2 - 3^2) / (2 * 5^2)) = exp(-0.8) = 0.449.
    for criterion, expected in ((0.44, [True, True, False]), (0.46, [True, False, False])):
        answer, selected = select_locations(d2, sd, np.array([criterion]))
        assert answer[0] == 0
        assert selected[0].tolist() == expected


def test_select_locations_always_holds_the_answer_and_respects_allowed():
    rng = np.random.default_rng(5)
    locs = rng.uniform(-0.01, 0.01, (9, 2))
    perceived = rng.uniform(-0.015, 0.015, (200, 2))
    allowed = np.array([0, 2, 4, 6, 8])
    d2 = location_distances(perceived, locs, allowed)
    answer, selected = select_locations(d2, rng.uniform(1e-3, 1e-2, 200), rng.uniform(0.0, 1.5, 200))
    assert selected[np.arange(200), answer].all()
    assert np.isin(answer, allowed).all()
    assert not selected[:, [1, 3, 5, 7]].any()
    _, everything = select_locations(d2, np.full(200, 1e-2), np.zeros(200))
    assert everything[:, allowed].all()


def _posteriors(n=300, seed=3):
    rng = np.random.default_rng(seed)
    locs = default_bank().locations_xy
    post = TrialPosteriors(rng.uniform(-0.012, 0.012, (n, 2)), rng.uniform(2e-3, 1.2e-2, n), np.ones(n, bool))
    return post, rng.uniform(0.1, 1.0, n), locs


def test_rules_that_reduce_to_the_shipped_one(rules):
    post, crit, locs = _posteriors()
    idx = np.zeros(crit.size, int)
    ref = posterior_ratio_rule(post, crit, locs, None, None, idx)
    for rule in (rules.fixed_width(1.0, 0.123), rules.hedge_to_centre(0.0), rules.capped(9)):
        a, s = rule(post, crit, locs, None, None, idx)
        np.testing.assert_array_equal(a, ref[0])
        np.testing.assert_array_equal(s, ref[1])


def test_capped_rule_keeps_at_most_k_and_the_answer(rules):
    post, crit, locs = _posteriors()
    idx = np.zeros(crit.size, int)
    _, full = posterior_ratio_rule(post, crit * 0.05, locs, None, None, idx)
    assert full.sum(axis=1).max() > 2  # the cap has something to cut
    a, s = rules.capped(2)(post, crit * 0.05, locs, None, None, idx)
    assert s.sum(axis=1).max() <= 2
    assert s[np.arange(a.size), a].all()


def test_hook_passes_every_selection_through(rules):
    """Cell means rebuilt from the recorded selections equal the ones simulate_cell_means returns."""
    bank = default_bank()
    plain = simulate_cell_means(4, np.random.default_rng([11, 16]), bank=bank)
    rec = rules.Recorder()
    hooked = simulate_cell_means(4, np.random.default_rng([11, 16]), bank=bank, rule=rec)
    np.testing.assert_array_equal(plain.count, hooked.count)
    np.testing.assert_array_equal(plain.error_mm, hooked.error_mm)
    assert len(rec.calls) == 8  # two studies for each of 4 participants
    n_loc = len(bank.locations_xy)
    for p, (selected, index) in enumerate(rec.calls[1::2]):
        k = selected.sum(axis=1)
        for m in range(len(bank.methods)):
            for loc in range(n_loc):
                cell = index == m * n_loc + loc
                np.testing.assert_allclose(hooked.count[p, loc, m], k[cell].mean(), rtol=1e-12)


def test_diffuse_rule_without_jumps_is_the_shipped_one_and_is_seeded(rules):
    bank = default_bank()
    base = simulate_cell_means(3, np.random.default_rng([4, 16]), bank=bank)
    none = simulate_cell_means(3, np.random.default_rng([4, 16]), bank=bank, rule=rules.DiffuseTrials(0.0, 0.02, 1))
    np.testing.assert_array_equal(base.count, none.count)
    a = simulate_cell_means(3, np.random.default_rng([4, 16]), bank=bank, rule=rules.DiffuseTrials(3.0, 0.02, 1))
    b = simulate_cell_means(3, np.random.default_rng([4, 16]), bank=bank, rule=rules.DiffuseTrials(3.0, 0.02, 1))
    np.testing.assert_array_equal(a.count, b.count)
    assert not np.array_equal(a.error_mm, base.error_mm)  # jumps move the answers


def test_script_prints_its_table_and_plot(tmp_path):
    png = tmp_path / "rules.png"
    res = subprocess.run([sys.executable, str(ROOT / "scripts" / "selection_rules.py"), "--seeds", "800", "803",
                          "--n", "8", "--only", "2", "--plot", str(png)],
                         capture_output=True, text=True, timeout=300,
                         env={**os.environ, "MPLBACKEND": "Agg"})
    assert res.returncode == 0, res.stderr
    rows = [line for line in res.stdout.splitlines() if line.startswith("| posterior ratio")]
    assert len(rows) == 2
    header = next(line for line in res.stdout.splitlines() if line.startswith("| rule |"))
    assert "Study 1: inverse below funneling" in header and "Study 1 interaction" in header
    assert all(len(row.split("|")) == len(header.split("|")) for row in rows)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_bars_need_every_finding_at_its_share(rules):
    at_bars = {"s2_headline": rules.HEADLINE_BAR, "s1_inverse_lower": rules.HEADLINE_BAR,
               "s2_hit_method_ns": rules.BASELINE_HIT_METHOD_NS, "s1_interaction": rules.BASELINE_INTERACTION,
               "s2_hit_location_ns": 0.0}
    assert rules.meets_bars(at_bars)
    for key in ("s2_headline", "s1_inverse_lower", "s2_hit_method_ns", "s1_interaction"):
        assert not rules.meets_bars({**at_bars, key: at_bars[key] - 0.01}), key


def test_script_refuses_an_empty_seed_range():
    res = subprocess.run([sys.executable, str(ROOT / "scripts" / "selection_rules.py"), "--seeds", "5", "5"],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 2
    assert "STOP must be above FIRST" in res.stderr


def test_unfuse_moves_exactly_the_unfused_trials_by_the_jump():
    from vibrofocus.simulation.perception import PerceptualModel, unfuse

    rng = np.random.default_rng(21)
    n = 2000
    post = TrialPosteriors(rng.uniform(-0.01, 0.01, (n, 2)), rng.uniform(2e-3, 8e-3, n), rng.random(n) < 0.9)
    conflict = rng.uniform(0.0, 0.01, n)
    model = PerceptualModel().replace(unfused_per_m=50.0, unfused_jump_m=0.02, unfused_width=2.0)
    u, angle = rng.random(n), rng.uniform(0, 2 * np.pi, n)
    moved, unfused = unfuse(post, conflict, model, u, angle)
    # A trial is unfused where u < 50/m * conflict (at most 0.5 here), and only if felt.
    np.testing.assert_array_equal(unfused, (u < 50.0 * conflict) & post.felt)
    step = np.linalg.norm(moved.perceived_m - post.perceived_m, axis=1)
    np.testing.assert_allclose(step[unfused], 0.02, rtol=1e-12)
    assert np.all(step[~unfused] == 0.0)
    np.testing.assert_allclose(moved.sd_m[unfused], 2.0 * post.sd_m[unfused], rtol=1e-12)
    np.testing.assert_array_equal(moved.sd_m[~unfused], post.sd_m[~unfused])
    # The share follows the probability: E[min(1, 50 * c)] over c ~ U(0, 10 mm) is 0.25, times 0.9 felt.
    assert abs(unfused.mean() - 0.25 * 0.9) < 0.03


def test_without_unfused_percepts_the_draws_are_unchanged():
    """unfused_per_m = 0 draws nothing more, so the answers of the other fits stay as they were."""
    bank = default_bank()
    from vibrofocus.simulation.hypotheses import hypothesis

    m = hypothesis(None).model()
    a = simulate_cell_means(3, np.random.default_rng([8, 16]), bank=bank, model=m.replace(unfused_per_m=0.0))
    b = simulate_cell_means(3, np.random.default_rng([8, 16]), bank=bank, model=m.replace(unfused_per_m=0.0,
                                                                                       unfused_width=3.0))
    np.testing.assert_array_equal(a.count, b.count)
    c = simulate_cell_means(3, np.random.default_rng([8, 16]), bank=bank, model=m.replace(unfused_per_m=400.0))
    assert not np.array_equal(a.error_mm, c.error_mm)


def test_felt_at_drive_moves_the_unfused_trials_toward_the_drive_cue(rules):
    rng = np.random.default_rng(33)
    n = 500
    locs = np.array([[x, y] for y in (0.01, 0, -0.01) for x in (-0.01, 0, 0.01)])
    felt_at = rng.uniform(-0.012, 0.012, (n, 2))
    drive_at = rng.uniform(-0.02, 0.02, (n, 2))
    percepts = Percepts(felt_at, np.zeros(n), np.ones(n, bool), np.linalg.norm(drive_at - felt_at, axis=1),
                        drive_position_m=drive_at)
    post = TrialPosteriors(felt_at, np.full(n, 4e-3), np.ones(n, bool))
    index, criterion = np.arange(n), np.full(n, 0.5)
    # Certain to unfuse (probability capped at 1): every answer is the location nearest to
    # the point half-way to the drive cue.
    answer, _ = rules.FeltAtDrive(1e6, 0.5, 1.0, seed=2)(post, criterion, locs, None, percepts, index)
    expected = np.argmin(location_distances(felt_at + 0.5 * (drive_at - felt_at), locs, None), axis=1)
    np.testing.assert_array_equal(answer, expected)
    # Never unfused: the shipped rule's answers and selections.
    a0, s0 = rules.FeltAtDrive(0.0, 0.5, 3.0, seed=2)(post, criterion, locs, None, percepts, index)
    a1, s1 = posterior_ratio_rule(post, criterion, locs, None, percepts, index)
    np.testing.assert_array_equal(a0, a1)
    np.testing.assert_array_equal(s0, s1)
