"""One family of validation helpers, so every entry point words its errors alike.

Each helper names the offending argument (``name``) and says what was expected and
what was received, then raises :class:`vibrofocus.errors.ValidationError`.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from .errors import ValidationError

__all__ = [
    "as_array",
    "check_shape",
    "check_finite",
    "check_positive",
    "check_in_range",
    "check_choice",
    "check_band",
    "check_index",
    "integer_text",
]


def _describe_shape(shape: Sequence[int | None]) -> str:
    return "(" + ", ".join("any" if s is None else str(s) for s in shape) + (",)" if len(shape) == 1 else ")")


def as_array(
    value: Any,
    name: str,
    *,
    ndim: int | None = None,
    shape: Sequence[int | None] | None = None,
    dtype: str = "float",
    finite: bool = True,
) -> np.ndarray:
    """Convert ``value`` to an ndarray and validate it.

    Parameters
    ----------
    value : array_like
        The input.
    name : str
        Argument name used in error messages.
    ndim : int, optional
        Required number of dimensions.
    shape : sequence of int or None, optional
        Required shape; ``None`` entries accept any length.
    dtype : {"float", "complex"}
        Target dtype family. Real input is accepted for ``"complex"``; complex input
        is refused for ``"float"``.
    finite : bool
        Refuse NaN and Inf.

    Returns
    -------
    ndarray
        ``float64`` or ``complex128`` array.
    """
    try:
        arr = np.asarray(value)
    except Exception as exc:  # ragged lists and the like
        raise ValidationError(f"{name} must be array-like, got {type(value).__name__}: {exc}") from exc
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise ValidationError(f"{name} must be numeric, got dtype {arr.dtype}")
    if dtype == "float":
        if np.iscomplexobj(arr):
            raise ValidationError(f"{name} must be real-valued, got complex dtype {arr.dtype}")
        arr = arr.astype(np.float64, copy=False)
    elif dtype == "complex":
        arr = arr.astype(np.complex128, copy=False)
    else:  # pragma: no cover - programming error
        raise ValueError(f"unknown dtype family {dtype!r}")
    if ndim is not None and arr.ndim != ndim:
        raise ValidationError(f"{name} must have {ndim} dimension(s), got {arr.ndim} with shape {arr.shape}")
    if shape is not None:
        check_shape(arr, name, shape)
    if finite:
        check_finite(arr, name)
    return arr


def check_shape(arr: np.ndarray, name: str, shape: Sequence[int | None]) -> None:
    """Raise unless ``arr.shape`` matches ``shape`` (``None`` = any length)."""
    ok = arr.ndim == len(shape) and all(s is None or s == a for s, a in zip(shape, arr.shape))
    if not ok:
        raise ValidationError(f"{name} must have shape {_describe_shape(shape)}, got {arr.shape}")


def check_finite(arr: np.ndarray, name: str) -> None:
    """Raise if ``arr`` holds NaN or Inf, saying how many and where the first is."""
    bad = ~np.isfinite(arr)
    if bad.any():
        first = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ValidationError(
            f"{name} contains {int(bad.sum())} non-finite value(s) (NaN or Inf); first at index {first}"
        )


def check_positive(value: float, name: str, *, allow_zero: bool = False) -> float:
    """Return ``value`` as float if it is finite and > 0 (or >= 0)."""
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise ValidationError(f"{name} must be a number, got {value!r}") from exc
    if not np.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise ValidationError(f"{name} must be {'>= 0' if allow_zero else '> 0'} and finite, got {value!r}")
    return v


def check_in_range(value: float, name: str, low: float, high: float, *, inclusive: bool = True) -> float:
    """Return ``value`` as float if it lies in [low, high] (or (low, high))."""
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise ValidationError(f"{name} must be a number, got {value!r}") from exc
    inside = low <= v <= high if inclusive else low < v < high
    if not np.isfinite(v) or not inside:
        brackets = ("[", "]") if inclusive else ("(", ")")
        raise ValidationError(f"{name} must lie in {brackets[0]}{low}, {high}{brackets[1]}, got {value!r}")
    return v


def check_choice(value: Any, name: str, choices: Iterable[Any]) -> Any:
    """Return ``value`` if it is one of ``choices``."""
    choices = tuple(choices)
    if value not in choices:
        raise ValidationError(f"{name} must be one of {', '.join(map(repr, choices))}; got {value!r}")
    return value


def check_band(band: Any, fs: float, name: str = "band") -> tuple[float, float]:
    """Validate a frequency band ``(low, high)`` in Hz against ``0 < low < high <= fs/2``."""
    try:
        low, high = (float(b) for b in band)
    except (TypeError, ValueError) as exc:
        raise ValidationError(f"{name} must be a pair (low_hz, high_hz), got {band!r}") from exc
    nyquist = fs / 2
    if not (np.isfinite(low) and np.isfinite(high)) or not 0 < low < high <= nyquist:
        raise ValidationError(
            f"{name} must satisfy 0 < low < high <= fs/2 = {nyquist:g} Hz, got ({low:g}, {high:g}) Hz"
        )
    return low, high


def check_index(index: Any, name: str, n: int, *, what: str = "items") -> int:
    """Return ``index`` as int if ``0 <= index < n``."""
    if isinstance(index, bool) or not isinstance(index, (int, np.integer)):
        raise ValidationError(f"{name} must be an integer index, got {index!r}")
    if not 0 <= int(index) < n:
        raise ValidationError(f"{name}={index} is outside the {n} {what} (valid: 0..{n - 1})")
    return int(index)


def integer_text(text: str) -> int | None:
    """``text`` as an int if it writes an integer (``"3"``, ``"3.0"``, ``" 3 "``), else None.

    For values read from text files (a trials file's study or a response's locations),
    where a bad value is reported with its line rather than raised at once.
    """
    try:
        value = float(text)
    except ValueError:
        return None
    if not np.isfinite(value) or value != int(value):
        return None
    return int(value)
