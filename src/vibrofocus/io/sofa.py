"""Transfer matrices as SOFA files (AES69), convention ``GeneralTF-E``, through sofar.

The calibration's transfer matrix ``H`` (frequency, point, actuator), m/V, is the general
transfer function of the SOFA convention ``GeneralTF-E`` (the ``GeneralTF`` family with
an emitter dimension): **receivers are the skin points** (``ReceiverPosition``, the
points' x, y and z = 0, m) and **emitters are the actuators** (``EmitterPosition``, m),
one measurement (M = 1), frequencies ``N`` in Hz; ``Data.Real`` and ``Data.Imag`` have
the dimensions (M, R, N, E). Listener and source sit at the origin, so the positions are
those of the array (x across the arm toward the thumb, y along it toward the wrist).
vibrofocus's own description rides along in global attributes (``GLOBAL_vibrofocus*``, JSON:
point labels and kinds, actuator names, sample rate, band, participant, layout as JSON),
which other readers ignore. pyfar reads the file
(``pyfar.io.convert_sofa(sofar.read_sofa(path))`` gives a ``FrequencyData`` of cshape
(E, M, R)).

This module reads and writes a plain record (:data:`SOFA_KEYS`); the calibration side
(:func:`vibrofocus.calibration.export_sofa`, :func:`~vibrofocus.calibration.import_sofa`)
builds it. Needs the optional extra ``vibrofocus[sofa]`` (sofar).
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import CalibrationFileError, ValidationError

__all__ = ["SOFA_CONVENTION", "SOFA_KEYS", "write_sofa_tf", "read_sofa_tf", "import_sofar"]

#: The SOFA convention written and read.
SOFA_CONVENTION = "GeneralTF-E"
#: Keys of the record: ``H`` complex (n_freqs, n_points, n_actuators), m/V; ``freqs``
#: (n_freqs,), Hz; ``points_xy`` (n_points, 2) and ``actuators_xy`` (n_actuators, 2), m;
#: ``point_labels``, ``point_kinds``, ``actuator_names`` (lists of str); ``fs``, Hz;
#: ``band`` (low, high), Hz; ``participant_id`` str; ``layout`` dict (JSON-able).
SOFA_KEYS = ("H", "freqs", "points_xy", "actuators_xy", "point_labels", "point_kinds", "actuator_names", "fs",
             "band", "participant_id", "layout")
_ATTR = "GLOBAL_vibrofocus"
# Record key -> attribute name after GLOBAL_vibrofocus (SOFA names hold one underscore).
_ATTRS = {"point_labels": "PointLabels", "point_kinds": "PointKinds", "actuator_names": "ActuatorNames",
          "fs": "SampleRate", "band": "Band", "participant_id": "ParticipantID", "layout": "Layout"}


def import_sofar() -> Any:
    """sofar, or ValidationError saying how to install it."""
    try:
        import sofar
    except ImportError as exc:
        raise ValidationError(f"SOFA files need sofar: pip install 'vibrofocus[sofa]' ({exc})") from None
    return sofar


def _positions(xy: np.ndarray) -> np.ndarray:
    xy = np.asarray(xy, float)
    return np.column_stack([xy, np.zeros(len(xy))])


def write_sofa_tf(record: Mapping[str, Any], path: str | os.PathLike, *, title: str = "") -> Path:
    """Write a transfer-matrix record to a SOFA ``GeneralTF-E`` file, atomically.

    sofar writes to a file name of its own; the bytes then go to ``path`` with
    :func:`vibrofocus._atomic.write_bytes`, so a reader never sees half a file and a
    previous file at ``path`` is unchanged after a failure.

    Parameters
    ----------
    record : mapping
        :data:`SOFA_KEYS`.
    path : path-like
        Destination, conventionally ``*.sofa``; its folder must exist.
    title : str
        ``GLOBAL_Title``.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ValidationError
        A record whose shapes do not agree, or sofar missing.
    OutputError
        The file cannot be written.
    """
    from .._atomic import write_bytes

    sofar = import_sofar()
    missing = [k for k in SOFA_KEYS if k not in record]
    if missing:
        raise ValidationError(f"a SOFA record needs {', '.join(missing)}")
    H = np.asarray(record["H"])
    freqs = np.asarray(record["freqs"], float)
    n_f, n_r, n_e = H.shape if H.ndim == 3 else (None, None, None)
    if n_f != len(freqs) or n_r != len(record["points_xy"]) or n_e != len(record["actuators_xy"]):
        raise ValidationError(f"H has shape {H.shape}, but there are {len(freqs)} frequencies, "
                              f"{len(record['points_xy'])} points and {len(record['actuators_xy'])} actuators")
    sofa = sofar.Sofa(SOFA_CONVENTION)
    sofa.GLOBAL_Title = title
    sofa.GLOBAL_Comment = "vibrofocus transfer matrix: skin displacement per actuator voltage (m/V)"
    sofa.GLOBAL_RoomType = "free field"
    sofa.ListenerPosition = np.zeros((1, 3))
    sofa.SourcePosition = np.zeros((1, 3))
    sofa.SourcePosition_Type, sofa.SourcePosition_Units = "cartesian", "metre"
    sofa.ReceiverPosition = _positions(record["points_xy"])
    sofa.EmitterPosition = _positions(record["actuators_xy"])
    sofa.N = freqs
    # (N, R, E) -> (M=1, R, N, E)
    sofa.Data_Real = np.real(H).transpose(1, 0, 2)[None].astype(float)
    sofa.Data_Imag = np.imag(H).transpose(1, 0, 2)[None].astype(float)
    described = {"point_labels": list(record["point_labels"]), "point_kinds": list(record["point_kinds"]),
                 "actuator_names": list(record["actuator_names"]), "fs": float(record["fs"]),
                 "band": [float(b) for b in record["band"]], "participant_id": str(record["participant_id"]),
                 "layout": record["layout"]}
    for key, value in described.items():
        sofa.add_attribute(f"{_ATTR}{_ATTRS[key]}", json.dumps(value))
    with tempfile.TemporaryDirectory(prefix="vibrofocus-sofa-") as folder:
        built = Path(folder) / "transfer.sofa"
        sofar.write_sofa(str(built), sofa)
        data = built.read_bytes()
    return write_bytes(Path(path), data, what="SOFA file")


def _fail(path: Path, what: str) -> CalibrationFileError:
    return CalibrationFileError(f"{path}: {what}")


def read_sofa_tf(path: str | os.PathLike) -> dict[str, Any]:
    """Read a SOFA ``GeneralTF-E`` file written by :func:`write_sofa_tf` into its record.

    A ``GeneralTF-E`` file of another tool (without the ``GLOBAL_vibrofocus*``
    attributes) reads too: points and actuators are then named by number, the band is
    the frequency axis's extent and ``fs`` twice its top frequency.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    dict
        :data:`SOFA_KEYS`.

    Raises
    ------
    CalibrationFileError
        Missing or unreadable file, another convention, shapes that disagree, NaN/Inf,
        or a frequency axis that does not rise. The message names the file.
    """
    from .._atomic import protect

    sofar = import_sofar()
    path = Path(path)
    protect(path, "SOFA file")
    if not path.is_file():
        raise _fail(path, "no such SOFA file")
    try:
        sofa = sofar.read_sofa(str(path), verify=False, verbose=False)
    except Exception as exc:  # noqa: BLE001 - netCDF4 and sofar raise many kinds
        raise _fail(path, f"is not a readable SOFA file ({str(exc)[:200]})") from None
    convention = getattr(sofa, "GLOBAL_SOFAConventions", None)
    if convention != SOFA_CONVENTION:
        raise _fail(path, f"is a SOFA {convention} file; vibrofocus reads {SOFA_CONVENTION} transfer matrices")
    real, imag = np.asarray(sofa.Data_Real, float), np.asarray(sofa.Data_Imag, float)
    freqs = np.atleast_1d(np.asarray(sofa.N, float))
    receivers = np.atleast_2d(np.asarray(sofa.ReceiverPosition, float))
    emitters = np.atleast_2d(np.asarray(sofa.EmitterPosition, float))
    if real.ndim != 4 or real.shape != imag.shape or real.shape[0] != 1:
        raise _fail(path, f"Data.Real/Data.Imag have shapes {real.shape}/{imag.shape}; expected one measurement "
                          "(1, receivers, frequencies, emitters)")
    _, n_r, n_f, n_e = real.shape
    if (n_f, n_r, n_e) != (len(freqs), len(receivers), len(emitters)):
        raise _fail(path, f"the data ({n_r} receivers, {n_f} frequencies, {n_e} emitters) do not match "
                          f"{len(receivers)} receiver positions, {len(freqs)} frequencies, {len(emitters)} emitter positions")
    for name, arr in (("Data.Real", real), ("Data.Imag", imag), ("N", freqs), ("ReceiverPosition", receivers),
                      ("EmitterPosition", emitters)):
        if not np.isfinite(arr).all():
            raise _fail(path, f"{name} holds NaN/Inf")
    if n_f < 2 or (np.diff(freqs) <= 0).any():
        raise _fail(path, "its frequency axis N must rise")
    attrs = {}
    for key in ("point_labels", "point_kinds", "actuator_names", "fs", "band", "participant_id", "layout"):
        raw = getattr(sofa, f"{_ATTR}{_ATTRS[key]}", None)
        try:
            attrs[key] = None if raw is None else json.loads(raw)
        except ValueError:
            raise _fail(path, f"attribute {_ATTR}{_ATTRS[key]} is not JSON") from None
    H = (real[0] + 1j * imag[0]).transpose(1, 0, 2)
    return {
        "H": H, "freqs": freqs, "points_xy": receivers[:, :2], "actuators_xy": emitters[:, :2],
        "point_labels": attrs["point_labels"] or [str(k + 1) for k in range(n_r)],
        "point_kinds": attrs["point_kinds"] or ["location"] * n_r,
        "actuator_names": attrs["actuator_names"] or [f"A{k + 1}" for k in range(n_e)],
        "fs": float(attrs["fs"]) if attrs["fs"] is not None else 2 * float(freqs[-1]),
        "band": tuple(attrs["band"]) if attrs["band"] is not None else (float(freqs[0]), float(freqs[-1])),
        "participant_id": attrs["participant_id"] or "",
        "layout": attrs["layout"],
    }
