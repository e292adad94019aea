"""Funneling (phantom sensation) gains (docs/method.md, "Rendering methods")."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validation import as_array, check_choice, check_positive
from ..defaults import FUNNELING_AMPLITUDE_V
from ..errors import ValidationError
from ..layout import _infer_spacing

__all__ = ["funneling_gains", "funneling_weights"]


def funneling_weights(actuators_xy: Any, target_xy: Any, spacing_xy: tuple[float, float] | None = None) -> np.ndarray:
    """Bilinear weights ``w_q = max(0, 1 - |dx_q|/D_x) * max(0, 1 - |dy_q|/D_y)``.

    Parameters
    ----------
    actuators_xy : ndarray, shape (n_actuators, 2)
        Actuator centres, m.
    target_xy : ndarray, shape (2,)
        Virtual point, m.
    spacing_xy : (float, float), optional
        Actuator spacings ``(D_x, D_y)``, m; default inferred as
        :class:`~vibrofocus.layout.ArrayLayout` does (smallest non-zero coordinate
        differences).

    Returns
    -------
    ndarray, shape (n_actuators,)
        Weights in [0, 1]. Each factor is clipped at 0, so an actuator one spacing or
        more away (along either axis) gets no weight. On a rectangular grid these are the
        bilinear-interpolation weights: they sum to 1 for any point inside the grid and
        only the actuators of the cell holding the point are non-zero. Outside the grid
        they sum to less than 1 (a point beyond the array fades out).
    """
    act = as_array(actuators_xy, "actuators_xy", ndim=2, shape=(None, 2))
    if len(act) == 0:
        raise ValidationError("actuators_xy must hold at least one actuator, got 0")
    target = as_array(target_xy, "target_xy", ndim=1, shape=(2,))
    if spacing_xy is None:
        spacing = np.array(_infer_spacing(act))
    else:
        try:
            pair = tuple(spacing_xy)
        except TypeError as exc:
            raise ValidationError(f"spacing_xy must be a pair (D_x, D_y) in m, got {spacing_xy!r}") from exc
        if len(pair) != 2:
            raise ValidationError(f"spacing_xy must be a pair (D_x, D_y) in m, got {spacing_xy!r}")
        spacing = np.array([check_positive(d, "spacing_xy") for d in pair])
    factors = np.clip(1.0 - np.abs(act - target) / spacing, 0.0, None)
    return factors[:, 0] * factors[:, 1]


def funneling_gains(
    actuators_xy: Any,
    target_xy: Any,
    amplitude: float = FUNNELING_AMPLITUDE_V,
    law: str = "linear",
    spacing_xy: tuple[float, float] | None = None,
) -> np.ndarray:
    """Per-actuator amplitudes that place a phantom tap at ``target_xy``.

    ``"linear"``: ``A_q = A w_q`` (the bilinear law of the paper); ``"energy"``:
    ``A_q = A sqrt(w_q)``, which keeps the summed power ``sum A_q^2 = A^2`` constant
    inside the grid. ``w_q`` are the clipped bilinear weights of
    :func:`funneling_weights`.

    Parameters
    ----------
    actuators_xy : ndarray, shape (n_actuators, 2)
        Actuator centres, m.
    target_xy : ndarray, shape (2,)
        Virtual point, m.
    amplitude : float
        ``A``, V (>= 0).
    law : {"linear", "energy"}
    spacing_xy : (float, float), optional
        Actuator spacings, m; see :func:`funneling_weights`.

    Returns
    -------
    ndarray, shape (n_actuators,)
        Amplitudes, V.

    Raises
    ------
    ValidationError
        If ``target_xy`` lies one spacing or more from every actuator (all weights 0).
    """
    check_choice(law, "law", ("linear", "energy"))
    amplitude = check_positive(amplitude, "amplitude", allow_zero=True)
    weights = funneling_weights(actuators_xy, target_xy, spacing_xy)
    if not np.any(weights > 0):
        raise ValidationError(
            f"target_xy={np.asarray(target_xy).tolist()} m is one spacing or more from every actuator; "
            "funneling cannot place a tap there"
        )
    return amplitude * (weights if law == "linear" else np.sqrt(weights))
