"""The report's "Hypotheses" part: the figure and the table of a hypotheses fit (model output).

The fit itself is made above the analysis, by
:func:`vibrofocus.simulation.fitting.fit_trials` (``vibrofocus analyze --hypotheses``),
and reaches the report as its JSON-ready dict (``hypotheses.json``): this module only
draws and tabulates it. Everything here is labelled model output; the observed
frequencies are the lab's data. docs/fitting-hypotheses.md.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

__all__ = ["HYPOTHESES_JSON", "HYPOTHESES_FIGURE", "MODEL_OUTPUT", "plot_hypotheses_check", "hypotheses_table"]

#: File names of the fit in a report folder.
HYPOTHESES_JSON = "hypotheses.json"
HYPOTHESES_FIGURE = "hypotheses_check.png"
#: What every figure and table of the fit says of itself.
MODEL_OUTPUT = ("MODEL OUTPUT: predictions of the simulated participants' hypotheses fitted to these trials; "
                "the observed frequencies are the lab's data")


def plot_hypotheses_check(fit: Mapping[str, Any]):
    """Observed vs predicted Study 1 answer share per location: a row per hypothesis, a column per method.

    Parameters
    ----------
    fit : mapping
        ``hypotheses.json`` as :func:`vibrofocus.simulation.fitting.fit_trials` returns it.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt

    from .._style import method_colors, model_footer

    names = list(fit["hypotheses"])
    checks = {n: (fit["hypotheses"][n].get("check") or {}).get("study1") or {} for n in names}
    methods = list(dict.fromkeys(m for c in checks.values() for m in c))
    fig, axes = plt.subplots(max(len(names), 1), max(len(methods), 1), squeeze=False, sharex=True, sharey=True,
                             figsize=(3.2 * max(len(methods), 1), 2.2 * max(len(names), 1) + 0.8),
                             layout="constrained")
    colors = method_colors(methods)
    for r, name in enumerate(names):
        for c, method in enumerate(methods):
            ax = axes[r, c]
            cell = checks[name].get(method)
            if cell is None:
                ax.set_axis_off()
                continue
            x = np.arange(1, len(cell["observed"]) + 1)
            ax.bar(x, cell["observed"], color="0.8", label="observed (data)")
            ax.plot(x, cell["predicted"], "o-", color=colors[method], ms=3, label="predicted (model)")
            if r == 0:
                ax.set_title(method)
            if c == 0:
                ax.set_ylabel(f"{name}\nshare of answers", fontsize=8)
            if r == len(names) - 1:
                ax.set_xlabel("answered location")
            ax.set_xticks(x)
    axes[0, 0].legend(fontsize=7, loc="upper left")
    chosen = fit.get("chosen")
    fig.suptitle(f"Study 1 answers: observed vs hypotheses' predictions (chosen: {chosen})", fontsize=10)
    model_footer(fig, MODEL_OUTPUT, color="#b45309")
    return fig


def hypotheses_table(fit: Mapping[str, Any]) -> pd.DataFrame:
    """One row per hypothesis: ELPD, its SE, the difference to the chosen, the fitted parameters.

    Parameters
    ----------
    fit : mapping
        ``hypotheses.json``.

    Returns
    -------
    DataFrame
        Sorted by ELPD, highest first.
    """
    rows = []
    best = fit["hypotheses"][fit["chosen"]]["elpd"]
    for name, h in fit["hypotheses"].items():
        params = ", ".join(f"{k} = {v:.4g}" for k, v in h["params"].items()) or "none free"
        rows.append({"hypothesis": name, "ELPD": h["elpd"], "SE": h["se"], "ELPD - chosen": h["elpd"] - best,
                     "parameters": params})
    return pd.DataFrame(rows).sort_values("ELPD", ascending=False, kind="stable").reset_index(drop=True)
