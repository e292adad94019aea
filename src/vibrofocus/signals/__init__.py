"""Stimulus and excitation signals: the Ricker base stimulus and calibration sweeps."""

from .ricker import ricker, time_axis
from .sweeps import apply_fades, exponential_sweep, exponential_sweep_inverse, linear_sweep, spectral_inverse

__all__ = [
    "ricker",
    "time_axis",
    "linear_sweep",
    "exponential_sweep",
    "exponential_sweep_inverse",
    "spectral_inverse",
    "apply_fades",
]
