"""The Ricker wavelet, the base stimulus of docs/method.md, rendering methods."""

from __future__ import annotations

import numpy as np

from .._docs import fill_doc
from .._validation import as_array, check_choice, check_in_range, check_positive
from ..defaults import N_SAMPLES, SIGMA_S, TARGET_FRACTION
from ..errors import ValidationError

__all__ = ["ricker", "time_axis"]


@fill_doc
def time_axis(n_samples: int, fs: float) -> np.ndarray:
    """Sample times ``k / fs``.

    Parameters
    ----------
    n_samples : int
    %(fs)s

    Returns
    -------
    ndarray, shape (n_samples,)
        Times, s.
    """
    return np.arange(int(n_samples)) / float(fs)


@fill_doc
def ricker(
    fs: float,
    sigma: float = SIGMA_S,
    duration: float | None = None,
    t0: float | None = None,
    *,
    amplitude: float = 1.0,
    form: str = "zero_mean",
) -> np.ndarray:
    """Ricker wavelet ``s(t) = (1 - tau^2/sigma^2) exp(-tau^2 / (2 sigma^2))``, ``tau = t - t0``.

    Parameters
    ----------
    %(fs)s
    sigma : float
        Spread, s. The spectral peak is at ``1 / (sqrt(2) pi sigma)`` (225 Hz for 1 ms).
    duration : float, optional
        Length of the returned signal, s. Default ``N_SAMPLES / fs`` (0.4096 s at 10 kHz).
    t0 : float, optional
        Centre, s. Default: ``TARGET_FRACTION`` of the duration (the middle), which
        leaves room for the acausal part of inverse-filter drives.
    amplitude : float
        Peak value (at ``t0``), in the caller's unit.
    form : {"zero_mean", "printed"}
        ``"zero_mean"`` (default) is the Ricker wavelet proper, whose integral is zero.
        ``"printed"`` uses ``exp(-tau^2 / sigma^2)`` with the same polynomial, as the
        method's source paper prints it. That form has a non-zero mean (its integral is
        ``sigma sqrt(pi) / 2``): a static offset no inertial actuator can render and that
        a band-limited design silently drops, so it is offered for comparison only.

    Returns
    -------
    ndarray, shape (n_samples,)
        The wavelet, ``n_samples = round(duration * fs)``.
    """
    fs = check_positive(fs, "fs")
    sigma = check_positive(sigma, "sigma")
    check_choice(form, "form", ("zero_mean", "printed"))
    duration = N_SAMPLES / fs if duration is None else check_positive(duration, "duration")
    n = int(round(duration * fs))
    if n < 1:
        raise ValidationError(f"duration={duration!r} s is shorter than one sample at fs={fs:g} Hz")
    t0 = TARGET_FRACTION * duration if t0 is None else check_in_range(t0, "t0", 0.0, duration)
    amplitude = float(as_array(amplitude, "amplitude", ndim=0))
    tau2 = (time_axis(n, fs) - t0) ** 2 / sigma**2
    exponent = tau2 / 2 if form == "zero_mean" else tau2
    return amplitude * (1 - tau2) * np.exp(-exponent)
