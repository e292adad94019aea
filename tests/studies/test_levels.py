"""The level rule of a study protocol: the paper's levels (de Vlam et al. 2023, Sec. II.C)
against equal peak drive, stored with each session and exported with each trial."""

import json
import sqlite3

import numpy as np
import pytest

from vibrofocus.errors import StudyError
from vibrofocus.rigs import make_rig
from vibrofocus.studies import StudyStore
from vibrofocus.studies.engine import Response, StudyEngine, calibration_renderer
from vibrofocus.studies.protocol import StudyDesign, level_options

METHODS = ("funneling", "inverse", "combination")
LOCATIONS = tuple(range(1, 10))


def eq3_peak_v(location, amplitude_v=10.0):
    """The largest eq. 3 amplitude at ``location``, from the paper's geometry alone.

    Exciters 45 mm apart in both directions (Sec. II.B), the nine locations a 3 x 3 grid of
    10 mm pitch centred between them (the reference layout, docs/method.md), numbered row by
    row: A_q = A (1 - d_qx / D) (1 - d_qy / D) with D = 45 mm.
    """
    spacing, pitch = 45.0, 10.0
    exciters = [(sx * spacing / 2, sy * spacing / 2) for sx in (-1, 1) for sy in (-1, 1)]
    row, col = divmod(location - 1, 3)
    x, y = (col - 1) * pitch, (1 - row) * pitch
    return max(amplitude_v * max(0.0, 1 - abs(x - ex) / spacing) * max(0.0, 1 - abs(y - ey) / spacing)
               for ex, ey in exciters)


def test_eq3_by_hand():
    # The paper's numbers (Sec. II.C): 2.5 V on every exciter at the centre, 5.22 V at a corner's nearest.
    assert eq3_peak_v(5) == pytest.approx(2.5)
    assert eq3_peak_v(1) == pytest.approx(10 * (1 - 12.5 / 45) ** 2) == pytest.approx(5.216, abs=1e-3)


@pytest.fixture(scope="module")
def cal(calibration_file):
    from vibrofocus.calibration import load_calibration

    return load_calibration(calibration_file)


@pytest.fixture(scope="module")
def paper(cal):
    renderer = calibration_renderer(cal, levels="paper")
    renderer.prepare(METHODS, LOCATIONS)
    return renderer


def _peak(renderer, method, location):
    return float(np.max(np.abs(renderer(method, location))))


def test_paper_levels_play_funneling_by_eq3_and_the_inverse_filter_above_it_within_the_limit(paper):
    for loc in LOCATIONS:
        funneling = _peak(paper, "funneling", loc)
        assert funneling == pytest.approx(eq3_peak_v(loc), rel=1e-9)  # unscaled: A = limit_v
        inverse = _peak(paper, "inverse", loc)
        assert inverse <= 10.0 * (1 + 1e-12)
        assert inverse > funneling
        assert _peak(paper, "combination", loc) <= 10.0 * (1 + 1e-12)
    assert _peak(paper, "funneling", 5) == pytest.approx(2.5, abs=0.05)
    for corner in (1, 3, 7, 9):
        assert _peak(paper, "funneling", corner) == pytest.approx(5.22, abs=0.1)


def test_the_combination_asks_funnelings_displacement_at_the_target(paper):
    # Same displacement at the target (Sec. II.C), where it is not capped by the limit.
    for loc in LOCATIONS:
        comb, funn = paper.rendering("combination", loc), paper.rendering("funneling", loc)
        if comb.scale == 1.0:
            assert comb.reached_peak_m == pytest.approx(funn.reached_peak_m, rel=0.05)


def test_equal_peak_plays_every_method_at_the_limit(cal):
    renderer = calibration_renderer(cal, levels="equal-peak")
    for method in METHODS:
        for loc in (1, 5):
            assert _peak(renderer, method, loc) == pytest.approx(10.0, rel=1e-12)


def test_a_level_rule_is_checked():
    with pytest.raises(StudyError, match="levels must be one of paper, equal-peak"):
        StudyDesign(levels="loud")
    with pytest.raises(StudyError, match="levels must be one of"):
        level_options("loud", 10.0)
    assert StudyDesign().levels == "paper"


class Answers:
    def respond(self, presentation):
        return Response(presentation.trial.target, 0.5)

    def wait_resume(self):
        return True


def test_the_rule_is_stored_with_the_session_and_every_trial_row_carries_its_stimulus(
        tmp_path, cal, calibration_file):
    from vibrofocus.rendering import predict_response
    from vibrofocus.studies.export import read_trials_csv

    rig = make_rig("simulated", seed=5)
    with StudyStore(tmp_path / "s.db") as store:
        store.add_participant("p1")
        cid = store.add_calibration("p1", calibration_file)
        config = {"repetitions": 1, "n_training": 0, "methods": ["funneling", "inverse"], "locations": [1, 5]}
        sid = store.create_session("p1", 1, seed=3, calibration_id=cid, config=config)
        assert store.session(sid).config["levels"] == "paper"
        engine = StudyEngine(store, sid, rig, cal)
        engine.run(Answers())
        store.export_trials_csv(tmp_path / "t.csv")
        rows = read_trials_csv(tmp_path / "t.csv")
    assert len(rows) == 4
    for row in rows:
        assert row["levels"] == "paper"
        drives = engine.stimulus(row["method"], row["target"]).drives  # what was played
        assert row["drive_peak_v"] == pytest.approx(float(np.max(np.abs(drives))), rel=1e-12)
        # Predicted at the target through the calibration, independently of the renderer's own number.
        H = cal.transfer_for(drives.shape[1])
        target = cal.layout.location_index(row["target"])
        expected_um = np.max(np.abs(predict_response(H, drives)[target])) * 1e6
        assert row["target_peak_um"] == pytest.approx(expected_um, rel=1e-6)
    funneling = {r["target"]: r["drive_peak_v"] for r in rows if r["method"] == "funneling"}
    assert funneling == {1: pytest.approx(eq3_peak_v(1)), 5: pytest.approx(2.5)}


def test_a_session_stored_before_the_rule_reads_as_equal_peak_and_a_renderer_must_match(tmp_path):
    with StudyStore(tmp_path / "s.db") as store:
        store.add_participant("p1")
        sid = store.create_session("p1", 1, seed=3, config={"repetitions": 1, "n_training": 0})
    with sqlite3.connect(tmp_path / "s.db") as conn:  # as vibrofocus wrote it before sessions kept the rule
        config = json.loads(conn.execute("SELECT config FROM sessions WHERE session_id = ?", (sid,)).fetchone()[0])
        del config["levels"]
        conn.execute("UPDATE sessions SET config = ? WHERE session_id = ?", (json.dumps(config), sid))
    with StudyStore(tmp_path / "s.db") as store:
        assert store.session(sid).design.levels == "equal-peak"

        class PaperRenderer:
            levels = "paper"

            def __call__(self, method, target):
                raise AssertionError("never rendered")

        with pytest.raises(StudyError, match="planned with the 'equal-peak' level rule, but its renderer plays 'paper'"):
            StudyEngine(store, sid, None, renderer=PaperRenderer())


@pytest.fixture(scope="module")
def arm_7103(tmp_path_factory):
    """Participant 11 of ``simulate-study --seed 7103``: an inverse design of this arm's
    calibration rang past every window up to 65536 samples (issue 42)."""
    from vibrofocus.calibration import calibrate
    from vibrofocus.simulation.simulate import participant_seeds

    rig = make_rig("simulated", seed=participant_seeds(7103, 11)[0], skin="nominal")
    return calibrate(rig, participant_id="sim-011")


def test_every_stimulus_of_the_7103_arm_fits_one_window_from_its_calibration(arm_7103):
    renderer = calibration_renderer(arm_7103)  # the study's: paper levels, the window it picks
    assert renderer.prepare(METHODS, LOCATIONS) == arm_7103.n_fft  # the calibration's own resolution
    for method in METHODS:
        for loc in LOCATIONS:
            r = renderer.rendering(method, loc)
            assert r.drives.shape == (4, arm_7103.n_fft)
            assert r.wraparound_fraction <= 1e-3
    # The inverse filter still focuses where its window's ends are tapered.
    assert renderer.rendering("inverse", 4).metrics()["fidelity"] > 0.8


def test_a_design_that_cannot_fit_is_refused_when_the_session_is_planned(tmp_path, arm_7103):
    from vibrofocus.calibration import save_calibration

    path = tmp_path / "sim-011.nc"
    save_calibration(arm_7103, path)
    with StudyStore(tmp_path / "s.db") as store:
        store.add_participant("p1")
        cid = store.add_calibration("p1", path)
        sid = store.create_session("p1", 1, seed=1, calibration_id=cid, config={"methods": ["inverse"]})
        with pytest.raises(StudyError, match=r"stimuli do not fit a 256-sample design window .*the inverse design"):
            StudyEngine(store, sid, make_rig("simulated", seed=1), arm_7103, n_samples=256)
        assert [e.kind for e in store.events(sid)] == ["created"]  # nothing cued, nothing played
