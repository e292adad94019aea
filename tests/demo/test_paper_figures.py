"""The paper's figure layouts, checked on what they plot (the artists' data), not only
that a file appears."""

import numpy as np
import pytest

from vibrofocus import SimulatedForearm
from vibrofocus.demo import model_transfer, run_demo
from vibrofocus.demo.paper_figures import fig4_focusing_along_a_line, fig5_focus_at_a_location

matplotlib = pytest.importorskip("matplotlib")


@pytest.fixture()
def keep_figures(monkeypatch):
    """Keep the figures the code closes, to read their artists."""
    import matplotlib.pyplot as plt

    kept = []
    monkeypatch.setattr(plt, "close", lambda fig=None: kept.append(fig))
    return kept


def _lines(fig, prefix):
    return {line.get_gid(): line for ax in fig.axes for line in ax.get_lines()
            if (line.get_gid() or "").startswith(prefix)}


def test_fig4_one_drive_focuses_the_tap_at_the_farthest_point(tmp_path, keep_figures):
    rig = SimulatedForearm(seed=1, noise_m=0.0, dropout_rate=0.0)
    fig4_focusing_along_a_line(rig, tmp_path / "fig4.png")
    fig = keep_figures[-1]
    plain_ax, drive_ax, focused_ax = fig.axes[:3]
    far = len(plain_ax.get_yticks()) - 1

    def peak_time(ax):
        line = next(li for li in ax.get_lines() if li.get_gid() == f"trace:{far}")
        t, y = line.get_data()
        return t[np.argmax(np.abs(y - far))]

    # The plain tap reaches 16 mm late (a few m/s); the focused one at the asked instant.
    assert peak_time(plain_ax) > 2.0
    assert abs(peak_time(focused_ax)) < 0.5
    # The drive leaves ahead of the instant the tap is asked (the travel time): most of its
    # energy comes before t = 0, and the title states the lead of its peak.
    t, drive = next(li for li in drive_ax.get_lines() if li.get_gid() == "drive").get_data()
    assert np.sum(drive[t < 0] ** 2) > np.sum(drive[t > 0] ** 2)
    lead = -t[np.argmax(np.abs(drive))]
    assert lead > 0 and f"{lead:.1f} ms early" in drive_ax.get_title()
    assert "low frequencies first" not in drive_ax.get_title()
    # The asked Ricker is drawn dashed above the recorded trace, so both show.
    asked = next(li for li in focused_ax.get_lines() if li.get_gid() == "asked")
    trace = next(li for li in focused_ax.get_lines() if li.get_gid() == f"trace:{far}")
    assert asked.get_zorder() > trace.get_zorder() and asked.get_linestyle() == "--"
    assert fig.texts[-1].get_gid() == "caption" and "not a measurement" in fig.texts[-1].get_text()


def test_fig5_shares_one_time_axis_so_funneling_shows_late(tmp_path, keep_figures):
    rig = SimulatedForearm(seed=0, noise_m=0.0, dropout_rate=0.0)
    result = run_demo(rig, methods=("funneling", "inverse"), locations=(5,), transfer=model_transfer)
    fig5_focus_at_a_location(result, tmp_path / "fig5.png", methods=("funneling", "inverse"), n_grid=9)
    fig = keep_figures[-1]
    lines = _lines(fig, "time:")

    def target_peak_ms(method):
        t, y = lines[f"time:{method}:5"].get_data()
        return t[np.argmax(np.abs(y))]

    assert abs(target_peak_ms("inverse")) < 1.0
    assert target_peak_ms("funneling") > 3.0  # the phantom tap arrives late on the same axis
    # One colour scale for every snapshot.
    limits = {im.get_clim() for ax in fig.axes for im in ax.get_images()}
    assert len(limits) == 1


def test_fig5_says_why_the_combination_looks_like_funneling_at_the_centre(tmp_path, keep_figures):
    rig = SimulatedForearm(seed=0, noise_m=0.0, dropout_rate=0.0)
    methods = ("funneling", "combination")
    result = run_demo(rig, methods=methods, locations=(5, 1), transfer=model_transfer)
    fig5_focus_at_a_location(result, tmp_path / "fig5.png", location=5, methods=methods, n_grid=5, offsets_ms=(0.0,))
    caption = keep_figures[-1].texts[-1].get_text()
    assert "by symmetry" in caption and "location 5" in caption
    # Location 1 is not symmetric: its combination differs from funneling and no note is added.
    fig5_focus_at_a_location(result, tmp_path / "fig5_1.png", location=1, methods=methods, n_grid=5, offsets_ms=(0.0,))
    assert "symmetry" not in keep_figures[-1].texts[-1].get_text()
    assert "not a measurement" in keep_figures[-1].texts[-1].get_text()


def test_fig4_names_the_drive_by_its_lobes(tmp_path, keep_figures):
    """The drive's title is measured from it: a Ricker has 3 lobes; the lossy voigt-fit
    path asks a ringing burst, which the title must not call one wavelet."""
    from vibrofocus.demo.paper_figures import _lobes
    from vibrofocus.signals.ricker import ricker

    assert _lobes(ricker(10_000.0, 1e-3, 0.2, 0.1)) == 3
    fig4_focusing_along_a_line(SimulatedForearm(seed=0, skin="voigt-fit", noise_m=0.0, dropout_rate=0.0),
                               tmp_path / "fig4.png")
    title = keep_figures[-1].axes[1].get_title()
    assert "burst of" in title and "one wavelet" not in title


@pytest.mark.slow
def test_figs_6_and_7_name_the_simulated_participants_model_and_hypothesis(tmp_path, monkeypatch):
    from vibrofocus.demo import paper_figures
    from vibrofocus.simulation.hypotheses import hypothesis

    saved = []  # every figure the module saves (Figs. 6-7 are not pyplot's, so nothing closes them)
    original = paper_figures.save_figure
    monkeypatch.setattr(paper_figures, "save_figure", lambda fig, path, **kw: saved.append(fig) or original(fig, path, **kw))
    paths = paper_figures.write_paper_figures(tmp_path, participants=1)
    assert [p.name for p in paths][-2:] == ["paper_fig6.png", "paper_fig7.png"]
    label = hypothesis().label()  # the default hypothesis, with its version and fit
    captions = [t.get_text() for fig in saved for t in fig.texts if t.get_gid() == "caption"]
    simulated = [c for c in captions if "reports 20 people" in c]  # Figs. 6 and 7
    assert len(simulated) == 2
    for caption in simulated:
        assert label[1:] in caption and "model v3" in caption and "not data" in caption
