"""PNG figures served by the experimenter page (matplotlib, Agg backend, no display)."""

from __future__ import annotations

import io
from typing import Any

__all__ = ["calibration_png", "preview_png"]


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return buf.getvalue()


def calibration_png(calibration: Any) -> bytes:
    """|H| and coherence of a calibration as PNG bytes.

    The calibration package's own figure (:func:`vibrofocus.calibration.figures.plot_calibration`),
    so the experimenter sees the same picture as ``vibrofocus calibrate`` draws.
    """
    from ..calibration.figures import plot_calibration

    return _png(plot_calibration(calibration))


def preview_png(rendering: Any, layout: Any, fs: float, *, method: str, location: int) -> bytes:
    """:func:`vibrofocus.rendering.figures.plot_preview` as PNG bytes (the parameters are its own)."""
    from ..rendering.figures import plot_preview

    return _png(plot_preview(rendering, layout, fs, method=method, location=location))
