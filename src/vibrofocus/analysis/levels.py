"""The stimulus levels of a study: each method's peak drive and level at the target, per location.

A study's trials file (a study database's export) records, per trial, the session's level
rule (``levels``: ``paper`` or ``equal-peak``), the largest |drive| of the stimulus played
(``drive_peak_v``, V) and its peak displacement at the target predicted from the
participant's calibration (``target_peak_um``, µm). The table here summarises them per
method and location over the main trials, so that a report says at which levels the
methods were compared (the paper compared them at its own levels, not at equal drive).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = ["STIMULUS_LEVEL_COLUMNS", "stimulus_levels"]

#: Columns of :func:`stimulus_levels`.
STIMULUS_LEVEL_COLUMNS = ("method", "target", "levels", "n", "drive_peak_v", "drive_peak_v_min", "drive_peak_v_max",
                          "target_peak_um")


def stimulus_levels(trials: pd.DataFrame) -> pd.DataFrame | None:
    """Median peak drive and predicted peak at the target per method and location (main trials).

    Parameters
    ----------
    trials : DataFrame
        Typed trials (:func:`~vibrofocus.analysis.load_trials`); the stimulus columns
        ``levels``, ``drive_peak_v`` (V) and ``target_peak_um`` (µm) are used when present.

    Returns
    -------
    DataFrame or None
        One row per (method, target): ``levels`` (the rules seen, joined by ``/``), ``n``
        (trials with a recorded peak), ``drive_peak_v`` (median, V) with its range over
        participants (``drive_peak_v_min``, ``drive_peak_v_max``) and ``target_peak_um``
        (median, µm); NaN where no peak was recorded. None when the trials carry no
        stimulus columns (a trials file written by hand or by an older vibrofocus).
    """
    if "drive_peak_v" not in trials.columns or "levels" not in trials.columns:
        return None
    main = trials[trials["phase"] == "main"]
    if main.empty:
        return None
    rows = []
    for (method, target), cell in main.groupby(["method", "target"], sort=True):
        drive = pd.to_numeric(cell["drive_peak_v"], errors="coerce").to_numpy(dtype=float)
        target_um = pd.to_numeric(cell["target_peak_um"], errors="coerce").to_numpy(dtype=float)
        known = np.isfinite(drive)
        rules = sorted({str(x) for x in cell["levels"] if isinstance(x, str) and x})
        rows.append({
            "method": str(method), "target": int(target), "levels": "/".join(rules) or None, "n": int(known.sum()),
            "drive_peak_v": float(np.median(drive[known])) if known.any() else np.nan,
            "drive_peak_v_min": float(drive[known].min()) if known.any() else np.nan,
            "drive_peak_v_max": float(drive[known].max()) if known.any() else np.nan,
            "target_peak_um": float(np.nanmedian(target_um)) if np.isfinite(target_um).any() else np.nan,
        })
    return pd.DataFrame(rows, columns=list(STIMULUS_LEVEL_COLUMNS))
