"""Rendering methods of SPEC §2: funneling, inverse filter, combination, time reversal."""

from .taper import band_taper

__all__ = ["band_taper"]
