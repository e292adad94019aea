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
    "check_nonnegative",
    "check_positive",
    "check_in_range",
    "check_choice",
    "check_band",
    "check_index",
    "integer_text",
    "number_text",
    "shorten",
    "available_memory_bytes",
    "check_memory",
    "check_declared_size",
]

#: Longest text of a user's value an error message repeats, characters.
SHORTEN_CHARS = 80
#: Share of the available memory one allocation may take.
MEMORY_SHARE = 0.5
#: Most a compressed array can grow when read back: deflate (zlib, gzip, zip) tops out
#: near 1032:1, so data declared beyond this many times its stored bytes is not in the file.
MAX_EXPANSION = 1100
#: Bytes of headers, checksums and padding an uncompressed array may differ from its data by.
_STORAGE_SLACK = 4096


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


def check_nonnegative(arr: np.ndarray, name: str) -> None:
    """Raise if ``arr`` holds a negative value (or NaN), saying how many and where the first is."""
    bad = ~(arr >= 0)
    if bad.any():
        first = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ValidationError(f"{name} must be >= 0; it holds {int(bad.sum())} negative or NaN value(s); first at "
                              f"index {first}")


def check_positive(value: float, name: str, *, allow_zero: bool = False) -> float:
    """Return ``value`` as float if it is finite and > 0 (or >= 0)."""
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise ValidationError(f"{name} must be a number, got {shorten(value)}") from exc
    if not np.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise ValidationError(f"{name} must be {'>= 0' if allow_zero else '> 0'} and finite, got {shorten(value)}")
    return v


def check_in_range(value: float, name: str, low: float, high: float, *, inclusive: bool = True) -> float:
    """Return ``value`` as float if it lies in [low, high] (or (low, high))."""
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise ValidationError(f"{name} must be a number, got {shorten(value)}") from exc
    inside = low <= v <= high if inclusive else low < v < high
    if not np.isfinite(v) or not inside:
        brackets = ("[", "]") if inclusive else ("(", ")")
        raise ValidationError(f"{name} must lie in {brackets[0]}{low}, {high}{brackets[1]}, got {shorten(value)}")
    return v


def check_choice(value: Any, name: str, choices: Iterable[Any]) -> Any:
    """Return ``value`` if it is one of ``choices``."""
    choices = tuple(choices)
    if value not in choices:
        raise ValidationError(f"{name} must be one of {', '.join(map(repr, choices))}; got {shorten(value)}")
    return value


def check_band(band: Any, fs: float, name: str = "band") -> tuple[float, float]:
    """Validate a frequency band ``(low, high)`` in Hz against ``0 < low < high <= fs/2``."""
    try:
        low, high = (float(b) for b in band)
    except (TypeError, ValueError) as exc:
        raise ValidationError(f"{name} must be a pair (low_hz, high_hz), got {shorten(band)}") from exc
    nyquist = fs / 2
    if not (np.isfinite(low) and np.isfinite(high)) or not 0 < low < high <= nyquist:
        raise ValidationError(
            f"{name} must satisfy 0 < low < high <= fs/2 = {nyquist:g} Hz, got ({low:g}, {high:g}) Hz"
        )
    return low, high


def check_index(index: Any, name: str, n: int, *, what: str = "items") -> int:
    """Return ``index`` as int if ``0 <= index < n``."""
    if isinstance(index, bool) or not isinstance(index, (int, np.integer)):
        raise ValidationError(f"{name} must be an integer index, got {shorten(index)}")
    if not 0 <= int(index) < n:
        raise ValidationError(f"{name}={index} is outside the {n} {what} (valid: 0..{n - 1})")
    return int(index)


def integer_text(text: str) -> int | None:
    """``text`` as an int if it writes an integer (``"3"``, ``"3.0"``, ``" 3 "``), else None.

    For values read from text files (a trials file's study or a response's locations),
    where a bad value is reported with its line rather than raised at once. Only ASCII
    digits count: ``float`` also reads other scripts' digits (``"٣"``), which no file
    of the contract holds.
    """
    value = number_text(text)
    if value is None or value != int(value):
        return None
    return int(value)


def number_text(text: str) -> float | None:
    """``text`` as a float if it writes a finite number in ASCII (``"-10"``, ``"2.5e-3"``), else None.

    The reading :func:`integer_text` builds on: NaN, infinities and other scripts' digits
    are None, for the caller to report with its line.
    """
    if not text.isascii():
        return None
    try:
        value = float(text)
    except ValueError:
        return None
    return value if np.isfinite(value) else None


def shorten(value: Any, limit: int = SHORTEN_CHARS, *, as_text: bool = False) -> str:
    """``repr(value)`` cut to at most about ``limit`` characters, so a message never echoes unbounded input.

    Parameters
    ----------
    value : object
        What the user gave.
    limit : int
        Characters kept.
    as_text : bool
        Use ``str(value)`` instead of the repr (no quotes), for lists of names.

    Returns
    -------
    str
        The repr (or text), or its start followed by ``... (N characters)``.
    """
    text = str(value) if as_text else repr(value)
    if len(text) <= limit:
        return text
    return f"{text[:limit]}... ({len(text)} characters)"


def available_memory_bytes() -> int | None:
    """Memory the system can still give this process, bytes (``MemAvailable``; None where unknown)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        import os

        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def check_memory(n_bytes: float, what: str) -> None:
    """Refuse, before allocating, a job needing more than half the available memory.

    Parameters
    ----------
    n_bytes : float
        Estimated peak memory of the job, bytes.
    what : str
        The job and the input that sized it (``"--n-samples 100000000"``), for the message.

    Raises
    ------
    ValidationError
    """
    free = available_memory_bytes()
    if free is not None and n_bytes > MEMORY_SHARE * free:
        raise ValidationError(
            f"{what} needs about {n_bytes / 2**30:.3g} GiB of memory; this machine has {free / 2**30:.3g} GiB "
            f"available (at most {MEMORY_SHARE:.0%} of it is used for one job)"
        )


def check_declared_size(
    shape: Sequence[int],
    itemsize: int,
    name: str,
    *,
    stored_bytes: int | None = None,
    compressed: bool = False,
    limit_bytes: int | None = None,
    limit_reason: str = "",
) -> int:
    """Size of an array a file's header declares, refused before anything is read or allocated.

    A header is a claim: a few bytes can declare terabytes (an HDF5 dataset that was
    never written reads back as its fill value, an npy header names any shape). Readers
    of hostile files call this with the header's shape before reading the data.

    Parameters
    ----------
    shape : sequence of int
        The declared shape.
    itemsize : int
        Bytes per element.
    name : str
        The array and its file, for the message (``"variable H_real of P01.nc"``).
    stored_bytes : int, optional
        Bytes the file actually holds for the array. Uncompressed data must fit in them
        (give or take a few KiB of checksums); compressed data may be up to
        :data:`MAX_EXPANSION` times larger, no more.
    compressed : bool
        Whether ``stored_bytes`` are compressed.
    limit_bytes : int, optional
        Largest size the caller accepts for this array, bytes.
    limit_reason : str
        What ``limit_bytes`` stands for (``"4 x the file's size"``), for the message.

    Returns
    -------
    int
        The declared size, bytes.

    Raises
    ------
    ValidationError
        A negative length, more than the file holds or ``limit_bytes`` allow, or more
        memory than :func:`check_memory` grants.
    """
    dims = tuple(int(n) for n in shape)
    if any(n < 0 for n in dims):
        raise ValidationError(f"{name} declares a negative length: shape {dims}")
    n_bytes = int(itemsize)
    for n in dims:
        n_bytes *= n  # Python integers: no overflow whatever the header says
    said = f"{name} declares shape {dims} ({n_bytes:,} bytes)"
    if stored_bytes is not None:
        room = int(stored_bytes) * MAX_EXPANSION if compressed else int(stored_bytes) + _STORAGE_SLACK
        if n_bytes > room:
            held = f"{int(stored_bytes):,} {'compressed ' if compressed else ''}bytes"
            raise ValidationError(f"{said} but the file holds {held} of it; the file is corrupt or was edited "
                                  "(checked before reading)")
    if limit_bytes is not None and n_bytes > limit_bytes:
        raise ValidationError(f"{said}, more than {limit_reason or 'the limit'} ({int(limit_bytes):,} bytes); "
                              "refused before reading")
    check_memory(n_bytes, f"{name} (shape {dims})")
    return n_bytes
