"""The demo figures are written as PNG files."""

import numpy as np
import pytest

from vibrofocus import SimulatedForearm
from vibrofocus.demo import run_demo
from vibrofocus.demo.figures import field_figure, metrics_figure, propagation_figure


def _is_png(path) -> bool:
    with open(path, "rb") as fh:
        return fh.read(8) == b"\x89PNG\r\n\x1a\n"


def test_figures_are_written(tmp_path):
    rig = SimulatedForearm(seed=0)
    result = run_demo(rig, methods=("funneling", "inverse"), locations=(5,))
    paths = [
        propagation_figure(rig, tmp_path / "p.png", distances_m=(0.006, 0.02)),
        field_figure(result, tmp_path / "f.png", location=5, n_grid=9, offsets_ms=(0.0, 3.0)),
        metrics_figure(result, tmp_path / "m.png"),
    ]
    for path in paths:
        assert path.stat().st_size > 1000 and _is_png(path)
    assert np.isfinite([r["fidelity"] for r in result.rows]).all()


def test_peak_frontier_figure_and_bound(tmp_path, keep_figures):
    """The frontier at one location: the peak bound is minimax at the pseudo-inverse's fidelity, and
    no demo design predicts more peak contrast than the frontier at its own fidelity."""
    from vibrofocus.demo.frontier import frontier_figure, peak_frontiers
    from vibrofocus.demo.run import summarize

    result = run_demo(SimulatedForearm(seed=0), methods=("inverse", "contrast"), locations=(5,))
    front = peak_frontiers(result, fidelities=(0.85, 0.95))[5]
    assert front.fidelity.shape == (3,) and np.isfinite(front.peak_contrast_db).all()
    assert np.all(np.diff(front.peak_contrast_db) <= 0.05)  # fidelities ascending: contrast falls
    inv = result.renderings[(5, "inverse")].metrics(against="reference", contrast_over="points")
    assert front.pinv_fidelity == pytest.approx(inv["fidelity"], abs=1e-3)
    assert front.peak_bound_db >= inv["contrast_all_db"] - 0.05
    path = frontier_figure(result, {5: front}, tmp_path / "frontier.png")
    assert path.stat().st_size > 1000 and _is_png(path)
    assert "Model" in _footer(keep_figures[-1])
    assert keep_figures[-1].axes[0].get_xlabel() == "fidelity to the tap"  # one meaning of "fidelity"
    for row in result.rows:
        row["peak_bound_db"] = front.peak_bound_db
    assert summarize(result.rows)["inverse"]["peak_bound_db"] == pytest.approx(front.peak_bound_db)


@pytest.fixture()
def keep_figures(monkeypatch):
    """Keep the figures the code closes, to read their artists."""
    import matplotlib.pyplot as plt

    kept = []
    monkeypatch.setattr(plt, "close", lambda fig=None: kept.append(fig))
    return kept


def _footer(fig) -> str:
    texts = [t.get_text() for t in fig.texts if t.get_gid() == "model-footer"]
    assert len(texts) == 1, "a figure of the simulated arm says it is a model"
    return texts[0]


def test_propagation_draws_the_asked_ricker_above_the_recording(tmp_path, keep_figures):
    rig = SimulatedForearm(seed=0, noise_m=0.0, dropout_rate=0.0)
    propagation_figure(rig, tmp_path / "p.png", distances_m=(0.006, 0.02))
    fig = keep_figures[-1]
    right = fig.axes[1]
    asked = [li for li in right.get_lines() if (li.get_gid() or "").startswith("asked:")]
    traces = [li for li in right.get_lines() if li.get_color() == "k"]
    assert len(asked) == 2 and traces
    # Dashed and on top: where it matches the recording both stay visible.
    assert min(li.get_zorder() for li in asked) > max(li.get_zorder() for li in traces)
    assert all(li.get_linestyle() == "--" for li in asked)
    assert "Model" in _footer(fig) and "not a measurement" in _footer(fig)


def test_field_target_mark_leaves_the_focal_spot_visible(tmp_path, keep_figures):
    rig = SimulatedForearm(seed=0, noise_m=0.0, dropout_rate=0.0)
    result = run_demo(rig, methods=("inverse",), locations=(5,))
    field_figure(result, tmp_path / "f.png", location=5, n_grid=9, offsets_ms=(0.0,))
    fig = keep_figures[-1]
    ax = fig.axes[0]
    target_mm = rig.layout.locations_xy[4] * 1e3
    rings = [p for p in ax.patches if p.get_gid() == "target-ring"]
    assert len(rings) == 1
    ring = rings[0]
    assert not ring.get_fill() and ring.get_linewidth() <= 1.0
    assert ring.radius >= 4.0  # mm: around the focal spot, not on it
    assert np.allclose(ring.center, target_mm)
    # No marker bigger than a location's dot sits on the target.
    for line in ax.get_lines():
        x, y = line.get_data()
        on_target = np.hypot(np.asarray(x) - target_mm[0], np.asarray(y) - target_mm[1]) < 3.0
        if on_target.any():
            assert line.get_marker() in (".", "None", None) and line.get_markersize() <= 3
    assert "Model" in _footer(fig)


def test_metrics_contrast_axis_and_neutral_shape_legend(tmp_path, keep_figures):
    from vibrofocus._style import METHOD_COLORS
    from matplotlib.colors import to_hex

    result = run_demo(SimulatedForearm(seed=0), methods=("funneling", "inverse", "combination"), locations=(5,))
    metrics_figure(result, tmp_path / "m.png")
    fig = keep_figures[-1]
    note = [t.get_text() for t in fig.texts if t.get_gid() == "fidelity-note"]
    assert len(note) == 1 and "funneling's displacement" in note[0]
    assert "other locations" in fig.axes[1].get_ylabel()
    legend = fig.axes[0].get_legend()
    entries = dict(zip((t.get_text() for t in legend.get_texts()), legend.legend_handles))
    shape = entries["shape (best lag)"]
    method_hexes = {c.lower() for c in METHOD_COLORS.values()}
    assert to_hex(shape.get_markeredgecolor()).lower() not in method_hexes
    assert "Model" in _footer(fig)
