"""The one JSON sanitizer: numpy and pandas values to plain Python, strict JSON by default.

Every JSON vibrofocus writes (report.json, ``demo --json``, the description attributes
of a calibration file) passes through :func:`json_safe`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["json_safe"]


def _missing(value: Any) -> bool:
    """True for pandas' missing-value markers (``pd.NA``, ``pd.NaT``), without importing pandas."""
    return type(value).__name__ in ("NAType", "NaTType")


def json_safe(value: Any, *, finite: bool = True) -> Any:
    """Return ``value`` with every part JSON can hold as plain Python, recursively.

    Dicts (keys as str), lists and tuples (as lists), numpy arrays (as nested lists),
    numpy scalars, bools, pandas tables (as a list of row dicts) and missing values
    (None, ``pd.NA``, ``pd.NaT``: None) are converted; anything else is returned as
    it is (``json.dumps(..., default=str)`` can then name it).

    Parameters
    ----------
    value : object
        What is to be written as JSON.
    finite : bool
        True (strict JSON): NaN and infinities become None (null; e.g. a point that
        did not move, a perfect contrast). False keeps them as floats, for readers
        that accept JSON's ``NaN``/``Infinity`` extension (Python's ``json``).

    Returns
    -------
    object
        Built of dict, list, str, int, float, bool and None (plus unknown objects
        passed through).
    """
    if isinstance(value, dict):
        return {str(k): json_safe(v, finite=finite) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v, finite=finite) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist(), finite=finite)
    if hasattr(value, "to_dict") and type(value).__name__ == "DataFrame":
        return [json_safe(r, finite=finite) for r in value.to_dict(orient="records")]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return v if math.isfinite(v) or not finite else None
    if value is None or _missing(value):
        return None
    return value
