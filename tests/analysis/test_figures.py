"""Analysis figures: one look per method across the package, readable ellipses, p-values
that never read 0, and a baseline image."""

import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from vibrofocus import ArrayLayout
from vibrofocus._style import METHOD_COLORS
from vibrofocus.analysis import load_trials, localization_summary
from vibrofocus.analysis.figures import method_colors, plot_counts, plot_localization
from vibrofocus.analysis.study2 import study2_counts
from vibrofocus.analysis.report_html import _table

from .synthetic import make_trials

BASELINES = Path(__file__).parent / "baseline"


def test_a_method_keeps_its_colour_whichever_methods_a_figure_shows():
    assert method_colors(["inverse"])["inverse"] == method_colors(["combination", "inverse", "funneling"])["inverse"]
    assert method_colors(["inverse", "contrast"])["contrast"] == METHOD_COLORS["contrast"]
    # The package's six methods have six different colours; unknown names get others.
    assert len(set(METHOD_COLORS.values())) == len(METHOD_COLORS)
    other = method_colors(["inverse", "my_method"])["my_method"]
    assert other not in METHOD_COLORS.values()


def test_demo_and_analysis_draw_a_method_in_the_same_colour(tmp_path, monkeypatch):
    import matplotlib.pyplot as plt

    from vibrofocus.demo.figures import metrics_figure

    kept = []
    monkeypatch.setattr(plt, "close", lambda fig=None: kept.append(fig))
    rows = [dict(location=loc, method=m, fidelity=0.5, shape_fidelity=0.5, contrast_db=1.0, target_peak_m=1e-7)
            for loc in (1, 2) for m in ("inverse", "time_reversal")]
    metrics_figure(type("R", (), {"rows": rows})(), tmp_path / "m.png")
    bars = kept[-1].axes[0].containers
    from matplotlib.colors import to_hex

    drawn = {c.get_label(): to_hex(c.patches[0].get_facecolor()) for c in bars}
    assert drawn == {m: method_colors([m])[m].lower() for m in ("inverse", "time_reversal")}


@pytest.fixture(scope="module")
def positions():
    return localization_summary(load_trials(make_trials(6, seed=4, studies=(1,))))


def test_ellipses_are_told_apart_by_line_style_and_sit_on_the_means(positions):
    fig = plot_localization(positions, ArrayLayout.reference())
    ellipses = {p.get_gid(): p for ax in fig.axes for p in ax.patches if (p.get_gid() or "").startswith("ellipse:")}
    assert len(ellipses) == len(positions)
    styles = {}
    for row in positions.itertuples(index=False):
        patch = ellipses[f"ellipse:{row.method}:{row.location}"]
        np.testing.assert_allclose(patch.center, (row.mean_x_mm, row.mean_y_mm), rtol=1e-12)
        styles.setdefault(row.method, set()).add(str(patch.get_linestyle()))
    assert all(len(s) == 1 for s in styles.values())
    assert len({next(iter(s)) for s in styles.values()}) == len(styles)  # one style per method


def test_report_tables_bound_tiny_p_values_instead_of_printing_zero():
    html = _table(pd.DataFrame({"effect": ["a", "b"], "F": [40.0, 1.0], "p_unc": [1e-15, 0.03], "p-corr": [0.0, 0.5]}))
    cells = [c.split("</td>")[0] for c in html.split("<td>")[1:]]
    assert cells == ["a", "40", "&lt; 1e-12", "&lt; 1e-12", "b", "1", "0.03", "0.5"]


def _matches_baseline(fig, name, tmp_path):
    from matplotlib.testing.compare import compare_images

    for text in fig.findobj(lambda a: hasattr(a, "get_text") and hasattr(a, "set_visible")):
        text.set_visible(False)  # fonts differ between machines; shapes do not
    actual = tmp_path / name
    fig.savefig(actual, dpi=60)
    baseline = BASELINES / name
    if os.environ.get("VIBROFOCUS_UPDATE_BASELINES") == "1":  # pragma: no cover - after a reviewed change
        baseline.write_bytes(actual.read_bytes())
    assert baseline.exists(), f"missing {baseline}; write it with VIBROFOCUS_UPDATE_BASELINES=1 and review it"
    # RMS difference of the 0-255 pixel values; 3 tolerates anti-aliasing differences.
    return compare_images(str(baseline), str(actual), tol=3) is None


def test_localization_figure_matches_its_baseline_image(positions, tmp_path):
    assert _matches_baseline(plot_localization(positions, ArrayLayout.reference()), "localization.png", tmp_path)


def test_counts_figure_matches_its_baseline_image(tmp_path):
    counts, _ = study2_counts(load_trials(make_trials(6, seed=5, studies=(2,))))
    assert _matches_baseline(plot_counts(counts), "counts.png", tmp_path)
