"""Where to put the actuators: the search's candidates, its ranking and its guarantee against the paper's layout.

The searches here are small (2 targets, 8 candidates) to stay quick; the default search's
numbers are in docs/design-layout.md (scripts/layout_actuator_curve.py).
"""

from __future__ import annotations

import numpy as np
import pytest

from vibrofocus.errors import ValidationError
from vibrofocus.placement import PlacementSettings, Region, paper_layout, score_layout, search_layout
from vibrofocus.rendering import render
from vibrofocus.skin import ForearmParameters, SimulatedArm

PAPER = paper_layout()
#: Locations 1 and 9 of the paper's grid: two targets keep each layout's score to two designs.
TARGETS = PAPER.locations_xy[[0, 8]]


def small_settings(**changes) -> PlacementSettings:
    return PlacementSettings(**{"region": Region.rectangle(0.06, 0.06), "pitch_m": 0.03, "targets_xy": TARGETS,
                                "n_samples": 2048, **changes})


@pytest.fixture(scope="module")
def small_search():
    return search_layout(small_settings())


def test_the_candidates_tile_the_region_and_a_band_wraps():
    rect = Region.rectangle(0.09, 0.06, centre_xy=(0.01, 0.0))
    c = rect.candidates(0.015)
    assert c.shape == (6 * 4, 2) and rect.contains(c).all()
    np.testing.assert_allclose(sorted(set(np.round(c[:, 0], 9))), 0.01 + np.array([-37.5, -22.5, -7.5, 7.5, 22.5, 37.5]) * 1e-3)
    band = Region.band(0.2, 0.05)
    # Two points near the band's seam are 20 mm apart around the arm, not 180 mm.
    d = band.distances(np.array([[-0.09, 0.0]]), np.array([[0.09, 0.0]]))
    np.testing.assert_allclose(d, [[0.02]], rtol=1e-12)
    np.testing.assert_allclose(rect.distances(np.array([[-0.09, 0.0]]), np.array([[0.09, 0.0]])), [[0.18]])


@pytest.mark.parametrize(("changes", "says"), [
    ({"n_actuators": 0}, "n_actuators"), ({"targets_xy": TARGETS[:1]}, "2 to 64 targets"),
    ({"method": "funneling"}, "method must be one of inverse, minimax"), ({"min_fidelity": 1.5}, "min_fidelity"),
])
def test_settings_that_make_no_search_are_refused(changes, says):
    with pytest.raises(ValidationError, match=says):
        small_settings(**changes)


def test_a_region_too_small_for_the_actuators_is_refused_naming_it():
    with pytest.raises(ValidationError, match="holds 1 candidate positions"):
        search_layout(small_settings(region=Region.rectangle(0.02, 0.02, centre_xy=(0.0, 0.06))))


def test_the_score_is_that_of_render_through_the_arm():
    """The paper's layout scored from the arm's own transfer matrix: each target's contrast is render's."""
    s = small_settings()
    layout = paper_layout(TARGETS)
    arm = SimulatedArm(0, layout, s.fs, participant=ForearmParameters.nominal(4, skin="nominal"))
    tm = arm.transfer_matrix(s.n_samples)
    score = score_layout(tm, s)
    for i, loc in enumerate(layout.location_numbers):
        m = render("inverse", tm, s.fs, layout, loc, limit_v=s.limit_v, taper_ends=True).metrics()
        np.testing.assert_allclose(score.contrast_db[i], m["contrast_db"], rtol=1e-9)
    assert score.feasible and score.worst_db == pytest.approx(score.contrast_db.min())


@pytest.mark.slow
def test_the_search_is_never_worse_than_the_papers_layout(small_search):
    r = small_search
    labels = [s["label"] for s in r.starts]
    assert labels == ["greedy", "paper 2x2 at 45 mm"]
    assert r.score.key >= r.paper.key and r.score.feasible
    for s in r.starts:  # refinement only ever improves a start
        assert s["refined"].key >= s["score"].key
    # The paper's layout scored by the search is the one from the arm's own transfer (the pool's
    # columns and the guards toward the targets' centroid are the reference setup's).
    s = small_settings()
    arm = SimulatedArm(0, paper_layout(TARGETS), s.fs, participant=ForearmParameters.nominal(4, skin="nominal"))
    direct = score_layout(arm.transfer_matrix(s.n_samples), s)
    np.testing.assert_allclose(r.paper.contrast_db, direct.contrast_db, atol=1e-6)
    # The layout keeps the least spacing, stays in the region and has the targets as locations.
    d = s.region.distances(r.layout.actuators_xy, r.layout.actuators_xy)
    assert d[np.triu_indices(4, 1)].min() >= s.min_spacing_m - 1e-9
    assert s.region.contains(r.layout.actuators_xy).all()
    np.testing.assert_array_equal(r.layout.locations_xy, TARGETS)


@pytest.mark.slow
def test_dask_gives_the_same_layout_as_one_process(small_search):
    from distributed import Client

    with Client(processes=False, n_workers=1, threads_per_worker=2, dashboard_address=None) as client:
        on_dask = search_layout(small_settings(), client=client)
    np.testing.assert_array_equal(on_dask.layout.actuators_xy, small_search.layout.actuators_xy)
    np.testing.assert_allclose(on_dask.score.contrast_db, small_search.score.contrast_db, rtol=1e-12)
