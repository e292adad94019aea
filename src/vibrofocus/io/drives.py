"""Drives files: the voltages for the actuators, as ``vibrofocus render`` writes them and ``vibrofocus play`` reads them.

``.npz`` (numpy)
    ``drives`` (n_actuators, n_samples), V; ``fs`` (scalar), Hz; optional
    ``predicted`` (n_points, n_samples), m, and ``desired`` (n_samples,), m; and
    ``metadata``, a JSON object as a string.
``.csv``
    ``#`` lines with the metadata (``key: JSON value``), then a header
    ``time_s,<actuator>_V,...`` and one row per sample: the time in s and each
    actuator's voltage.
``.wav``
    float32, one channel per actuator; the sample value 1.0 is ``volts_per_full_scale``
    volts at the actuator (the drive limit), written with the metadata in a JSON
    sidecar ``<name>.wav.json``.

Every file is written atomically (:mod:`vibrofocus._atomic`).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._docs import fill_doc
from ..errors import ValidationError

__all__ = ["DRIVES_SUFFIXES", "write_drives", "write_drives_wav", "read_drives"]

#: File name endings :func:`write_drives` knows.
DRIVES_SUFFIXES = (".npz", ".csv")


@fill_doc
def write_drives(
    path: str | os.PathLike,
    drives: np.ndarray,
    fs: float,
    *,
    actuator_names: Sequence[str],
    metadata: Mapping[str, Any],
    predicted: np.ndarray | None = None,
    desired: np.ndarray | None = None,
) -> Path:
    """Write drives to an ``.npz`` or ``.csv`` file (by the suffix of ``path``; see the module docstring).

    Parameters
    ----------
    path : path-like
        Destination ending in ``.npz`` or ``.csv``; its folder must exist.
    drives : ndarray, shape (n_actuators, n_samples)
        Voltages, V.
    %(fs)s
    actuator_names : sequence of str
        One name per row of ``drives`` (the CSV's column names).
    metadata : mapping
        JSON-ready description (software, calibration, method, limits, predictions).
    predicted : ndarray, shape (n_points, n_samples), optional
        Predicted displacement at every point, m (``.npz`` only).
    desired : ndarray, shape (n_samples,), optional
        The asked target waveform, m (``.npz`` only).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ValidationError
        ``path`` does not end in ``.npz`` or ``.csv``.
    OutputError
        The file cannot be written; a previous file at ``path`` is unchanged.
    """
    from .._atomic import DRIVES_CSV, atomic_write

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in DRIVES_SUFFIXES:
        raise ValidationError(f"drives file {path}: use a .npz or .csv file name")
    with atomic_write(path, "wb", what="drives file", kind=DRIVES_CSV if suffix == ".csv" else None) as fh:
        if suffix == ".npz":
            extra = {k: v for k, v in (("predicted", predicted), ("desired", desired)) if v is not None}
            np.savez(fh, drives=drives, fs=np.float64(fs), **extra, metadata=json.dumps(dict(metadata)))
        else:
            t = np.arange(drives.shape[1]) / fs
            header = "\n".join(f"{k}: {json.dumps(v)}" for k, v in metadata.items())
            header += "\ntime_s," + ",".join(f"{name}_V" for name in actuator_names)
            np.savetxt(fh, np.column_stack([t, drives.T]), delimiter=",", header=header, comments="# ",
                       fmt="%.9g", encoding="utf-8")
    return path


def write_drives_wav(
    path: str | os.PathLike, drives: np.ndarray, fs: float, *, volts_per_full_scale: float,
    metadata: Mapping[str, Any],
) -> tuple[Path, Path]:
    """Write drives as a float32 multichannel WAV and its JSON sidecar (``<name>.wav.json``).

    Parameters
    ----------
    path : path-like
        Destination ``.wav`` file; its folder must exist.
    drives : ndarray, shape (n_actuators, n_samples)
        Voltages, V, within ``±volts_per_full_scale``.
    fs : float
        Sample rate, Hz (rounded to whole Hz, as WAV stores it).
    volts_per_full_scale : float
        Volts at the actuator for the sample value 1.0 (the drive limit), V.
    metadata : mapping
        JSON-ready description, written to the sidecar with ``volts_per_full_scale``.

    Returns
    -------
    tuple of Path
        The WAV file and its sidecar.

    Raises
    ------
    OutputError
        A file cannot be written; a previous file there is unchanged.
    """
    from scipy.io import wavfile

    from .._atomic import atomic_write, write_text

    path = Path(path)
    # Full scale (1.0) is the drive limit: the drives already respect it, so the
    # samples stay within [-1, 1] and the voltages are sample * volts_per_full_scale.
    with atomic_write(path, "wb", what="WAV file") as fh:
        wavfile.write(fh, int(round(fs)), (drives.T / volts_per_full_scale).astype(np.float32))
    sidecar = path.with_name(path.name + ".json")
    write_text(sidecar, json.dumps({**metadata, "volts_per_full_scale": volts_per_full_scale}, indent=2),
               what="WAV metadata file")
    return path, sidecar


def _npy_header(zf, name: str, path: Path) -> tuple[tuple[int, ...], np.dtype, int]:
    """Shape, dtype and data size (bytes) of member ``name`` of an npz, from its header alone
    (:func:`vibrofocus.io._headers.npy_member_header`)."""
    from ._headers import npy_member_header

    return npy_member_header(zf, name, f"drives file {path}")


def read_drives(path: str | os.PathLike, *, max_duration_s: float | None = None) -> tuple[np.ndarray, float]:
    """Read ``drives`` and ``fs`` from an ``.npz`` drives file.

    The arrays' headers are checked before any data is decompressed: the shape must
    match the data the file holds, the duration must be within ``max_duration_s`` and
    the array must fit in memory (:func:`vibrofocus._validation.check_memory`).

    Parameters
    ----------
    path : path-like
        An ``.npz`` with the arrays ``drives`` (n_actuators, n_samples), V, and ``fs``
        (one number), Hz, as :func:`write_drives` or ``numpy.savez`` write it.
    max_duration_s : float, optional
        Longest drive accepted, s (a rig's ``limits.max_duration_s``), checked from
        the header.

    Returns
    -------
    drives : ndarray, shape (n_actuators, n_samples)
        Voltages, V (NaN/Inf are left to the safety layer to refuse).
    fs : float
        Sample rate, Hz.

    Raises
    ------
    ValidationError
        Missing file or a folder, not an npz, missing or malformed arrays, a header
        that does not match the data, too long a drive, too little memory.
    """
    import zipfile

    from .._atomic import protect
    from .._validation import as_array, check_memory, check_positive, shorten

    path = Path(path)
    protect(path, "drives file")
    if path.is_dir():
        raise ValidationError(f"drives file {path}: it is a folder; give the .npz file written by vibrofocus render")
    if not path.is_file():
        raise ValidationError(f"drives file {path}: no such file")
    try:
        with open(path, "rb") as fh:
            head = fh.read(4)
    except OSError as exc:
        raise ValidationError(f"drives file {path}: cannot be read ({exc.strerror or exc})") from None
    if head[:2] != b"PK":  # an .npz is a zip archive
        raise ValidationError(
            f"drives file {path}: not a readable .npz file (it does not start as a zip archive; write it with "
            "vibrofocus render --out FILE.npz or numpy.savez(FILE, drives=..., fs=...))"
        )
    try:
        with zipfile.ZipFile(path) as zf:
            files = [n.removesuffix(".npy") for n in zf.namelist()]
            missing = [k for k in ("drives", "fs") if k not in files]
            if missing:
                held = shorten(", ".join(files) or "nothing", 200, as_text=True)
                raise ValidationError(f"drives file {path}: missing array(s) {', '.join(missing)} (it holds {held})")
            fs_shape, _, _ = _npy_header(zf, "fs.npy", path)
            if int(np.prod(fs_shape)) != 1:
                raise ValidationError(f"drives file {path}: fs must be one number, got shape {fs_shape}")
            shape, dtype, n_bytes = _npy_header(zf, "drives.npy", path)
        with np.load(path, allow_pickle=False) as data:
            fs_arr = np.asarray(data["fs"])
            fs = check_positive(fs_arr.reshape(()).item(), f"fs in {path}")
            if dtype.kind == "b":
                raise ValidationError(f"drives in {path} must be voltages, got dtype bool")
            if len(shape) == 2 and max_duration_s is not None and shape[1] / fs > max_duration_s:
                raise ValidationError(
                    f"drives file {path}: {shape[1]:,} samples at {fs:g} Hz last {shape[1] / fs:.6g} s, longer than "
                    f"the rig's limit of {max_duration_s:g} s (checked before reading the samples)"
                )
            check_memory(2 * n_bytes, f"drives file {path} (shape {shape})")  # the array and one copy
            drives = as_array(data["drives"], f"drives in {path}", ndim=2, finite=False)
    except (OSError, ValueError, zipfile.BadZipFile, KeyError) as exc:
        if isinstance(exc, ValidationError):
            raise
        raise ValidationError(f"drives file {path}: not a readable .npz file ({exc})") from None
    return drives, fs
