"""The demo figures are written as PNG files."""

import numpy as np

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
