"""The band taper of the designs: :func:`vibrofocus.signals.band_taper`, re-exported
here for the rendering modules (signals sit below rendering; nothing flows back up)."""

from ..signals.taper import band_taper

__all__ = ["band_taper"]
