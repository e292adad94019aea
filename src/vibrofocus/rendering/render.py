"""High-level rendering: one call from a transfer matrix to drives (docs/method.md, "Rendering methods").

:func:`render` is a thin front over the method registry (:mod:`.registry`): it makes a
:class:`~.transfer.TransferMatrix` of what it is given, the method object of the name
and options, and returns ``method.design(tm, location)``.
"""

from __future__ import annotations

from typing import Any

from .._docs import fill_doc
from ..errors import CausalityError, ValidationError
from ..layout import ArrayLayout
from .design import Design, Rendering
from .methods import CONTROL_SETS, DEFAULT_GUARD_WEIGHT
from .registry import make_method
from .transfer import as_transfer_matrix, target_on_model

__all__ = ["Design", "Rendering", "render", "render_fitted", "CONTROL_SETS", "DEFAULT_GUARD_WEIGHT"]


@fill_doc
def render(method: str, H: Any, fs: float, layout: ArrayLayout, location: int | None = None, *,
           target_xy: Any = None, n_samples: int | None = None, calibrated_band: tuple[float, float] | None = None,
           **options: Any) -> Design:
    """Render a tap at a layout location, or anywhere on the skin, with a registered method.

    Parameters
    ----------
    method : str
        A registered method's name (:func:`~vibrofocus.rendering.available_methods`): the
        built-in ``"funneling"``, ``"inverse"``, ``"combination"``, ``"time_reversal"``,
        ``"contrast"``, ``"constrained"`` (:mod:`vibrofocus.rendering.methods`) or one a lab
        registered.
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
        The method's options: those every method has (:class:`~.method.Method`:
        ``band``, ``sigma``, ``limit_v``, ``scale_to_limit``, ...) and its own (e.g.
        ``regularization`` and ``guard_weight`` of :class:`~.methods.Inverse`,
        ``min_contrast_db`` of :class:`~.methods.Constrained`). Options of the former
        ``render`` a method does not have are ignored.

    Returns
    -------
    Design
    """
    chosen = make_method(method, **options)
    if not isinstance(layout, ArrayLayout):
        raise ValidationError(f"layout must be an ArrayLayout, got {type(layout).__name__}")
    if (location is None) == (target_xy is None):
        raise ValidationError("give the target as location= (a layout location number) or target_xy= (a skin "
                              "position, m), " + ("not both" if location is not None else "one of them"))
    if target_xy is not None:
        H, layout, location = target_on_model(H, layout, target_xy)
    tm = as_transfer_matrix(H, fs, layout, n_samples=n_samples, calibrated_band=calibrated_band,
                            taper_octaves=options.get("taper_octaves", 0.5))
    return chosen.design(tm, location)


def render_fitted(method: str, H: Any, fs: float, layout: ArrayLayout, location: int | None = None,
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
        As in :func:`render`; given ``taper_ends``, no second try.

    Returns
    -------
    Design
    """
    try:
        return render(method, H, fs, layout, location, **options)
    except CausalityError:
        if "taper_ends" in options:
            raise
        return render(method, H, fs, layout, location, taper_ends=True, **options)
