"""Validation shared by the rendering functions (built on vibrofocus._validation)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validation import as_array, check_choice, check_finite, check_in_range, check_positive
from ..errors import ValidationError
from ._pinv import REGULARIZATIONS

__all__ = ["ValidatedTransfer", "as_transfer", "check_transfer_energy", "samples_for", "check_regularization", "check_grid", "as_indices"]

#: Default ``reg_param`` of the regularized designs (relative to the largest singular value).
DEFAULT_REG_PARAM = {"tikhonov": 1e-2, "tsvd": 1e-2}


class ValidatedTransfer:
    """Base of a transfer matrix validated when it was made (:class:`~.transfer.TransferMatrix`):
    :func:`as_transfer` hands back its ``H`` without a second pass over the values."""

    H: np.ndarray


def as_transfer(H: Any, name: str = "H", *, values: bool = True) -> np.ndarray:
    """Complex transfer matrix, shape (n_freqs, n_points, n_actuators), finite, non-zero.

    ``values=False`` checks the shape only: the caller checks the values of the part it
    uses (:func:`check_transfer_energy`), saving a pass over a large ``H``. A
    :class:`ValidatedTransfer` was checked when made: its ``H`` is returned as it is.
    """
    if isinstance(H, ValidatedTransfer):
        return H.H
    arr = as_array(H, name, ndim=3, dtype="complex", finite=False)
    if arr.size == 0:
        raise ValidationError(f"{name} is empty (shape {arr.shape}); a transfer matrix needs frequencies, points and actuators")
    if arr.shape[0] < 2:
        raise ValidationError(f"{name} must hold at least 2 frequencies (n // 2 + 1 with n >= 2), got shape {arr.shape}")
    if values:
        # sum |H|^2 in one BLAS pass answers both checks on a large array.
        with np.errstate(over="ignore", invalid="ignore"):
            check_transfer_energy(np.vdot(arr, arr).real, arr, name)
    return arr


def check_transfer_energy(energy: float, arr: np.ndarray, name: str = "H", where: str = "") -> None:
    """Raise unless ``arr`` (a transfer matrix or the part of it in use, ``where``) is finite
    and not all zero, given ``energy = sum |arr|^2``: it is NaN/Inf if any entry is (then
    the detailed check says where; a mere overflow passes it) and 0 only if every entry is."""
    if not np.isfinite(energy):
        check_finite(arr, name)
    if energy == 0:
        raise ValidationError(f"{name} is all zero{where}: no actuator reaches any point (singular transfer matrix)")


#: Most memory one design window may take, bytes: about ten copies of H (the window's
#: transfer matrix, the batched solves, the responses), complex. The reference layout
#: (13 points, 4 actuators) then designs on up to 2**18 samples (26 s at 10 kHz; its
#: responses ring down in well under 1 s); 10**6 samples took 3.4 GB and 32 s.
MAX_DESIGN_BYTES = 2 * 2**30
#: Copies of H a design holds at once (the CLI's memory check counts the same).
H_COPIES = 10


def check_window(n_samples: Any, n_points: int, n_actuators: int, fs: float, name: str = "n_samples") -> int:
    """A design window, samples: an even integer >= 16 whose design fits :data:`MAX_DESIGN_BYTES`.

    Parameters
    ----------
    n_samples : int
        The window asked for.
    n_points, n_actuators : int
        The layout's, which size H.
    fs : float
        Sample rate, Hz (for the message).
    name : str
        The argument, for the message.

    Returns
    -------
    int

    Raises
    ------
    ValidationError
        Not an even integer >= 16, more than :data:`MAX_DESIGN_BYTES`, or more than the
        memory this machine has (:func:`vibrofocus._validation.check_memory`).
    """
    from .._validation import check_memory, shorten

    if isinstance(n_samples, bool) or not isinstance(n_samples, (int, np.integer)) or n_samples < 16 or n_samples % 2:
        raise ValidationError(f"{name} must be an even integer >= 16, got {shorten(n_samples)}")
    n = int(n_samples)
    per_bin = H_COPIES * 16 * n_points * n_actuators
    need = per_bin * (n // 2 + 1)
    if need > MAX_DESIGN_BYTES:
        longest = 2 ** int(np.floor(np.log2(2 * (MAX_DESIGN_BYTES // per_bin - 1))))
        raise ValidationError(
            f"{name}={n} ({n / fs:.3g} s at {fs:g} Hz) needs about {need / 2**30:.3g} GiB for the design ({H_COPIES} "
            f"copies of H: {n // 2 + 1} frequencies x {n_points} points x {n_actuators} actuators, complex), more "
            f"than the {MAX_DESIGN_BYTES / 2**30:g} GiB a design window may take; the longest window of this layout "
            f"is {longest} samples ({longest / fs:.3g} s), far longer than a tap and its ring-down")
    check_memory(need, f"{name}={n}")
    return n


def samples_for(n_freqs: int, n_samples: Any, name: str = "n_samples") -> int:
    """Window length ``n`` of a transfer matrix with ``n_freqs = n // 2 + 1`` bins.

    ``None`` gives the even length ``2 (n_freqs - 1)``; an explicit length must match.
    """
    if n_samples is None:
        return 2 * (n_freqs - 1)
    if isinstance(n_samples, bool) or not isinstance(n_samples, (int, np.integer)) or n_samples < 2:
        raise ValidationError(f"{name} must be an integer >= 2, got {n_samples!r}")
    check_grid(n_freqs, int(n_samples), name)
    return int(n_samples)


def check_grid(n_freqs: int, n: int, what: str) -> None:
    """Raise unless ``n_freqs == n // 2 + 1``."""
    if n_freqs != n // 2 + 1:
        raise ValidationError(
            f"H has {n_freqs} frequencies but {what} implies n = {n} samples, which needs n // 2 + 1 = {n // 2 + 1} "
            f"(H must be on numpy.fft.rfftfreq(n, 1 / fs))"
        )


def check_regularization(regularization: Any, reg_param: Any) -> tuple[str | None, float | None]:
    """Validate the regularization choice and its parameter; fill the default parameter."""
    check_choice(regularization, "regularization", REGULARIZATIONS)
    if regularization is None:
        if reg_param is not None:
            raise ValidationError(
                f"reg_param={reg_param!r} is only used with regularization='tikhonov' or 'tsvd'; "
                "the plain pseudo-inverse (regularization=None) takes none"
            )
        return None, None
    if reg_param is None:
        return regularization, DEFAULT_REG_PARAM[regularization]
    if regularization == "tikhonov":
        value = check_positive(reg_param, "reg_param")
    else:
        value = check_in_range(reg_param, "reg_param", 0.0, 1.0)
        if value == 0.0:
            raise ValidationError("reg_param must be > 0 for regularization='tsvd' (relative truncation level), got 0")
    return regularization, value


def as_indices(indices: Any, name: str, n: int) -> np.ndarray:
    """Unique integer indices in ``0..n-1`` (1-D array)."""
    arr = np.atleast_1d(np.asarray(indices))
    if arr.size == 0 or arr.ndim != 1 or not np.issubdtype(arr.dtype, np.integer):
        raise ValidationError(f"{name} must be a non-empty sequence of integer point indices, got {indices!r}")
    if arr.min() < 0 or arr.max() >= n:
        raise ValidationError(f"{name} holds indices outside the {n} points of H (valid: 0..{n - 1}): {arr.tolist()}")
    if np.unique(arr).size != arr.size:
        raise ValidationError(f"{name} holds repeated point indices: {arr.tolist()}")
    return arr.astype(int)
