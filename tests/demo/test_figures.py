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


def test_peak_frontier_figure_and_bound(tmp_path):
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
    for row in result.rows:
        row["peak_bound_db"] = front.peak_bound_db
    assert summarize(result.rows)["inverse"]["peak_bound_db"] == pytest.approx(front.peak_bound_db)
