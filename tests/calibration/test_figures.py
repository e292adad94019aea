"""The calibration figure: every point told apart, its band and coherence lines named, a
simulated calibration labelled a model."""

import colorsys
import dataclasses
import itertools

import numpy as np
import pytest

from vibrofocus.calibration import TRUSTED_COHERENCE, plot_calibration

pytest.importorskip("matplotlib")
from matplotlib.colors import to_rgb  # noqa: E402


def _point_lines(ax, labels):
    return [line for line in ax.get_lines() if line.get_label() in labels]


def test_every_point_has_its_own_colour_and_line_style(fir_calibration):
    _, cal = fir_calibration
    fig = plot_calibration(cal)
    labels = set(cal.layout.point_labels)
    lines = _point_lines(fig.axes[0], labels)
    assert len(lines) == cal.layout.n_points == 13
    # (colour, dash pattern): get_linestyle() names every custom dash pattern "--".
    looks = {(str(line.get_color()), str(line._dash_pattern)) for line in lines}
    assert len(looks) == 13
    # Locations in hues of their own: a paired palette (tab20) gives points 1 and 2 the
    # same hue, light and dark (hue difference 0.004); tab10's closest pair differs by 0.029.
    hsv = [colorsys.rgb_to_hsv(*to_rgb(line.get_color())) for line in lines[:cal.layout.n_locations]]
    chromatic = [h for h, s, _ in hsv if s > 0.2]
    closest = min(min(abs(a - b), 1 - abs(a - b)) for a, b in itertools.combinations(chromatic, 2))
    assert closest > 0.02


def test_coherence_line_at_the_trusted_criterion_and_band_named(fir_calibration):
    _, cal = fir_calibration
    fig = plot_calibration(cal)
    coherence_ax = fig.axes[cal.n_actuators]
    levels = [line.get_ydata()[0] for line in coherence_ax.get_lines() if len(set(line.get_ydata())) == 1
              and line.get_label() not in set(cal.layout.point_labels)]
    assert TRUSTED_COHERENCE == 0.9
    assert TRUSTED_COHERENCE in levels
    names = [t.get_text() for t in fig.legends[0].get_texts()]
    assert any("calibrated band" in n for n in names)
    assert any(f"coherence {TRUSTED_COHERENCE:g}" in n for n in names)


def test_simulated_calibration_carries_a_model_footer(fir_calibration):
    _, cal = fir_calibration
    footers = [t for t in plot_calibration(cal).texts if t.get_gid() == "model-footer"]
    assert footers == []  # a rig that is not the simulated forearm: no footer
    simulated = dataclasses.replace(cal, rig={**cal.rig, "kind": "simulated", "skin": "nominal", "seed": 3})
    footers = [t.get_text() for t in plot_calibration(simulated).texts if t.get_gid() == "model-footer"]
    assert len(footers) == 1 and "Model" in footers[0] and "skin nominal, seed 3" in footers[0]


def test_quality_table_says_what_its_decibels_measure(fir_calibration):
    from rich.console import Console

    _, cal = fir_calibration
    console = Console(width=100, record=True)
    console.print(cal.quality.table(cal.layout))
    text = console.export_text()
    assert "A1 (SNR)" in text and "signal-to-noise" in text
    assert np.isfinite(cal.quality.snr_db).all()
