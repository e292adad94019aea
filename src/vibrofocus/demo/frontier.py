"""The peak-contrast frontier of the demo (``vibrofocus demo --frontier``): for each
location, the least largest peak at every other calibrated point that any drive reaches at
a given fidelity (the minimax design), beside where the demo's methods sit.

Each design's point is its prediction through the design's own ``H`` (the frontier's): the
fidelity against the band-limited tap and the peak contrast against every other calibrated
point (guards included), so the gap between a method and the curve is what the physics
would still allow at that fidelity.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from .._atomic import save_figure
from .._style import method_colors
from .run import DemoResult

__all__ = ["FRONTIER_FIDELITIES", "LocationFrontier", "peak_bound", "peak_frontiers", "frontier_figure"]

#: Fidelities of the demo's frontier (the pseudo-inverse's own is added per location).
FRONTIER_FIDELITIES = (0.8, 0.85, 0.9, 0.95, 0.98)
_LEFT = 0.78  # the figure's left edge: designs of lower fidelity are drawn there, hollow


@dataclass(frozen=True)
class LocationFrontier:
    """The frontier at one location.

    Attributes
    ----------
    location : int
        1-based location number.
    fidelity : ndarray, shape (k,)
        Achieved fidelity of each minimax design (NaN where out of reach).
    peak_contrast_db : ndarray, shape (k,)
        Its peak contrast against every other calibrated point, dB.
    peak_bound_db : float
        The peak bound: minimax's peak contrast at the pseudo-inverse's fidelity, dB.
    pinv_fidelity : float
        The pseudo-inverse's fidelity through the same ``H``.
    seconds : float
        Wall time of the location's frontier, s.
    """

    location: int
    fidelity: np.ndarray
    peak_contrast_db: np.ndarray
    peak_bound_db: float
    pinv_fidelity: float
    seconds: float


def peak_frontiers(result: DemoResult, *, fidelities=FRONTIER_FIDELITIES,
                   progress: Callable[[str], None] | None = None) -> dict[int, LocationFrontier]:
    """The minimax frontier at every location of a demo run, through the ``H`` it designed from.

    Parameters
    ----------
    result : DemoResult
    fidelities : sequence of float
        Least fidelities, each in (0, 1); the pseudo-inverse's own is added.
    progress : callable, optional
        Called with a short label after each location.

    Returns
    -------
    dict of int to LocationFrontier
    """
    from ..rendering.transfer import as_transfer_matrix

    rig = result.rig
    tm = as_transfer_matrix(result.H, rig.fs, rig.layout, n_samples=result.H.shape[0] * 2 - 2)
    out = {}
    for loc in sorted({r["location"] for r in result.rows}):
        out[loc] = _location_frontier(tm, loc, fidelities)
        if progress is not None:
            progress(f"frontier, location {loc}")
    return out


def peak_bound(tm, location: int) -> float:
    """The peak bound at one location, dB: the most peak contrast against every other
    calibrated point that any drive on the minimax support reaches at the pseudo-inverse's
    fidelity, predicted through ``tm`` (the energy bound's counterpart for peaks).

    Parameters
    ----------
    tm : TransferMatrix
    location : int
        1-based location number.

    Returns
    -------
    float
        NaN if the pseudo-inverse's fidelity is out of the support's reach.
    """
    return _location_frontier(tm, location, ()).peak_bound_db


def _location_frontier(tm, location: int, fidelities) -> LocationFrontier:
    from ..rendering.methods import Minimax

    method = Minimax()
    pinv_fid = min(method.pinv(method.problem(tm, location))[0], 0.999)
    asked = np.array(sorted({*map(float, fidelities), pinv_fid}))
    front = method.frontier(tm, location, asked)
    at = int(np.flatnonzero(asked == pinv_fid)[0])
    return LocationFrontier(location=int(location), fidelity=front.fidelity, peak_contrast_db=front.peak_contrast_db,
                            peak_bound_db=float(front.peak_contrast_db[at]), pinv_fidelity=pinv_fid,
                            seconds=front.seconds)


def frontier_figure(result: DemoResult, frontiers: dict[int, LocationFrontier], path: Path) -> Path:
    """Peak contrast against fidelity per location: the minimax frontier and each method's
    design (predicted through the design's ``H``). The program fixes the target's projection
    on the tap, so its quiet peak falls with the fidelity asked; the target's own peak may
    move a little with it, so the peak contrast need not be monotone. A design of fidelity
    below 0.78 (funneling and the combination arrive late) is drawn hollow at the left edge.

    Parameters
    ----------
    result : DemoResult
        The demo run whose designs are marked.
    frontiers : dict of int to LocationFrontier
        From :func:`peak_frontiers` of the same run.
    path : Path
        The PNG to write (atomically).

    Returns
    -------
    Path
    """
    from .._style import model_footer
    from .figures import _pyplot, arm_footer, arm_label

    plt = _pyplot()
    locations = sorted(frontiers)
    methods = list(dict.fromkeys(r["method"] for r in result.rows))
    colors = method_colors(methods)
    cols = 3
    rows = int(np.ceil(len(locations) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(10, 3 * rows + 0.8), sharex=True, squeeze=False)
    for ax, loc in zip(axes.ravel(), locations):
        f = frontiers[loc]
        ok = np.isfinite(f.fidelity)
        ax.plot(f.fidelity[ok], f.peak_contrast_db[ok], "k-", lw=1.5, label="minimax frontier")
        ax.plot([f.pinv_fidelity], [f.peak_bound_db], "k*", ms=9, label="peak bound (pinv's fidelity)")
        for method in methods:
            rendering = result.renderings.get((loc, method))
            if rendering is None:
                continue
            m = rendering.metrics(against="reference", contrast_over="points")
            # A design far below the frontier's fidelities (funneling, the combination: late
            # arrivals) sits on the left edge, marked as off the axis.
            off = m["fidelity"] < _LEFT
            ax.plot([max(m["fidelity"], _LEFT)], [m["contrast_all_db"]], "<" if off else "o", color=colors[method],
                    mfc="white" if off else colors[method], label=method)
        ax.set_title(f"location {loc}", fontsize=9)
        ax.grid(alpha=0.3)
    axes[0, 0].set_xlim(_LEFT - 0.005, 1.005)
    for ax in axes.ravel()[len(locations):]:
        ax.set_visible(False)
    for ax in axes[:, 0]:
        ax.set_ylabel("peak contrast, all points (dB)")
    for ax in axes[-1]:
        ax.set_xlabel("fidelity to the tap")
    handles, labels = axes.ravel()[0].get_legend_handles_labels()
    # The title and the two legend rows take the top 0.85 in; the panels start below. The
    # title comes after the layout, which would otherwise leave room for it a second time.
    height = fig.get_figheight()
    rig = getattr(result, "rig", None)
    simulated = rig is None or getattr(rig, "kind", "simulated") == "simulated"
    if simulated:
        model_footer(fig, arm_footer(rig))
    fig.tight_layout(rect=(0, 0.3 / height if simulated else 0, 1, 1 - 0.85 / height))
    fig.suptitle(f"Peak-contrast frontier on the {arm_label(getattr(result, 'rig', None))}", y=1 - 0.08 / height,
                 va="top")
    fig.legend(handles, labels, ncol=min(len(labels), 5), fontsize=8, loc="upper center", frameon=False,
               bbox_to_anchor=(0.5, 1 - 0.35 / height))
    save_figure(fig, path, dpi=120)
    plt.close(fig)
    return Path(path)
