"""Stimulus and excitation signals: the Ricker base stimulus, calibration sweeps and the band taper."""

from .ricker import ricker, time_axis
from .sweeps import apply_fades, exponential_sweep, exponential_sweep_inverse, linear_sweep, spectral_inverse
from .taper import band_taper

__all__ = [
    "ricker",
    "time_axis",
    "linear_sweep",
    "exponential_sweep",
    "exponential_sweep_inverse",
    "spectral_inverse",
    "apply_fades",
    "band_taper",
]
