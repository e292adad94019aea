"""High-level rendering: one call from a transfer matrix to drives (docs/method.md, "Rendering methods").

:func:`render` is *the* way to design a tap: ``render(Inverse(regularization="tikhonov"),
cal, fs, layout, 5)``, a method object (:mod:`.methods`, or a lab's registered one) and a
transfer matrix. It makes a :class:`~.transfer.TransferMatrix` of what it is given and
returns ``method.design(tm, location)``. A method's registered name with its options
(``render("inverse", ..., regularization="tikhonov")``) is the same call, the object made
by :func:`~.registry.make_method`. The functions and the operator object the methods are
built from (``inverse_filter``, ``InverseOperator``, ...) are building blocks, not a
second way (docs/usage.md, "Designing a tap").
"""

from __future__ import annotations

import dataclasses
import warnings
from typing import Any

import numpy as np

from .._docs import fill_doc
from ..errors import CausalityError, ValidationError
from ..layout import ArrayLayout
from .design import Design
from .method import Method
from .methods import CONTROL_SETS, DEFAULT_GUARD_WEIGHT
from .registry import make_method
from .transfer import as_transfer_matrix, target_on_model

__all__ = ["Design", "render", "render_fitted", "CONTROL_SETS", "DEFAULT_GUARD_WEIGHT"]

#: render's own keywords besides the method's options.
RENDER_KEYWORDS = ("target_xy", "n_samples", "calibrated_band")


@fill_doc
def render(method: Method | str, H: Any, fs: float, layout: ArrayLayout, location: int | None = None, *,
           target_xy: Any = None, n_samples: int | None = None, calibrated_band: tuple[float, float] | None = None,
           **options: Any) -> Design:
    """Render a tap at a layout location, or anywhere on the skin: the one way to design a tap.

    Parameters
    ----------
    method : Method or str
        The method object with its options (:mod:`vibrofocus.rendering.methods`:
        ``Funneling()``, ``Inverse(regularization="tikhonov")``, ``Combination()``,
        ``TimeReversal()``, ``Contrast()``, ``Constrained(min_contrast_db=20)``,
        ``Minimax()``, or a lab's :class:`~vibrofocus.rendering.Method`); or a registered
        method's name (:func:`~vibrofocus.rendering.available_methods`), with its options
        as keywords.
    H : TransferMatrix, Calibration, skin model or ndarray
        The transfer matrix, m/V. A :class:`~vibrofocus.rendering.TransferMatrix` is used
        as it is (its kept caches with it); a ``Calibration`` gives
        ``TransferMatrix.from_calibration(cal, n_samples)`` (default the calibration's own
        resolution, ``n_fft``: :func:`~vibrofocus.rendering.transfer.calibration_window`;
        its band the calibrated band); a model of the skin (``transfer(points_xy, freqs)``: a
        ``FittedSkin``, a ``SimulatedForearm``) gives ``TransferMatrix.from_model``; an
        array, shape (n // 2 + 1, n_points, n_actuators), on ``rfftfreq(n, 1 / fs)``, rows
        in the order of ``layout.points_xy``, is validated into one.
    %(fs)s
    %(layout)s
    location : int, optional
        1-based location number of the target; give this or ``target_xy``.
    target_xy : (float, float), optional
        A target anywhere on the skin, m, designed with a model of the skin (a calibration's
        ``fit``, or a model as ``H``); it joins the layout as location ``n_locations + 1``.
    n_samples : int, optional
        Design window, samples; default ``2 (n_freqs - 1)`` of an array, the
        calibration's ``n_fft`` (4096 for the reference setup's), the model's
        ``design_window()``.
    calibrated_band : (float, float), optional
        Band ``H`` is valid in, Hz; default the calibration's (or model's) own.
    **options
        Only with a method's name: its options, those every method has
        (:class:`~.method.Method`: ``band``, ``sigma``, ``limit_v``, ``scale_to_limit``,
        ...) and its own (e.g. ``regularization`` and ``guard_weight`` of
        :class:`~.methods.Inverse`, ``min_contrast_db`` of :class:`~.methods.Constrained`).
        Options of the former ``render`` a method does not have are ignored; any other
        option is refused with the list of the valid ones. A method object carries its
        options itself: none are taken beside it.

    Returns
    -------
    Design

    Raises
    ------
    ValidationError
        An unknown option (the message lists the valid ones), options beside a method
        object, a method that is neither a ``Method`` nor a registered name.

    Warns
    -----
    UserWarning
        ``H`` comes from a fitted skin model with a verdict
        (:attr:`~vibrofocus.calibration.FittedSkin.verdict`: it misses its measured
        points), as the model itself or through a calibration's predicted points.
    """
    chosen = _method_of(method, options)
    if not isinstance(layout, ArrayLayout):
        raise ValidationError(f"layout must be an ArrayLayout, got {type(layout).__name__}")
    if (location is None) == (target_xy is None):
        raise ValidationError("give the target as location= (a layout location number) or target_xy= (a skin "
                              "position, m), " + ("not both" if location is not None else "one of them"))
    if target_xy is not None:
        H, layout, location = target_on_model(H, layout, target_xy)
    _warn_of_a_poor_fit(H)
    tm = as_transfer_matrix(H, fs, layout, n_samples=n_samples, calibrated_band=calibrated_band,
                            taper_octaves=options.get("taper_octaves", getattr(chosen, "taper_octaves", 0.5)))
    return chosen.design(tm, location)


def _warn_of_a_poor_fit(H: Any) -> None:
    """Warn (``UserWarning``) when the design's ``H`` comes from a fitted skin model that
    misses its measured points (:attr:`~vibrofocus.calibration.FittedSkin.verdict`): the
    model as ``H``, or a calibration whose unmeasured rows it predicted."""
    fit = H
    if hasattr(H, "transfer_for"):  # a calibration: its fit made the rows not measured
        measured = getattr(H, "measured", None)
        fit = getattr(H, "fit", None) if measured is not None and not np.all(measured) else None
    verdict = getattr(fit, "verdict", None)
    if isinstance(verdict, str):
        warnings.warn(f"designing from a fitted skin model that does not describe the skin: {verdict}",
                      UserWarning, stacklevel=3)


def _method_of(method: Method | str, options: dict[str, Any]) -> Method:
    """The method object ``render`` designs with: ``method`` itself, or made of a name and options."""
    if isinstance(method, Method):
        if options:
            fields = sorted(f.name for f in dataclasses.fields(method) if f.init)
            raise ValidationError(
                f"render takes no option {', '.join(sorted(options))} beside a method object: give it to the "
                f"method ({type(method).__name__}({next(iter(sorted(options)))}=...)); its options are "
                f"{', '.join(fields)}; render's own keywords are {', '.join(RENDER_KEYWORDS)}")
        return method
    if not isinstance(method, str):
        raise ValidationError(f"method must be a Method object or a registered method's name, got "
                              f"{type(method).__name__}")
    return make_method(method, **options)


def render_fitted(method: Method | str, H: Any, fs: float, layout: ArrayLayout, location: int | None = None,
                  **options: Any) -> Design:
    """:func:`render`, made again with the window's ends tapered if the design does not fit.

    A measured ``H`` carries noise, which spreads a little of an inverse design's drive over
    the whole window: played once from silence, such a drive may leave more of its response
    past the window than the wrap-around check allows
    (:class:`~vibrofocus.errors.CausalityError`), on any window (a longer one only pads the
    measured impulse responses). The design is then made again with ``taper_ends=True``, as
    the contrast designs always are; a design that does not fit even so is refused.
    ``vibrofocus render`` and the studies' renderer
    (:class:`~vibrofocus.studies.engine.CalibrationRenderer`) render through this.

    Parameters
    ----------
    method, H, fs, layout, location
        As in :func:`render`.
    **options
        As in :func:`render`; given ``taper_ends`` (or a method object with it set), no
        second try.

    Returns
    -------
    Design
    """
    try:
        return render(method, H, fs, layout, location, **options)
    except CausalityError:
        if isinstance(method, Method):
            if method.taper_ends:
                raise
            return render(dataclasses.replace(method, taper_ends=True), H, fs, layout, location, **options)
        if "taper_ends" in options:
            raise
        return render(method, H, fs, layout, location, taper_ends=True, **options)
