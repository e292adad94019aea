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

The files follow AES69-2020/2022 (SOFA 2.x, as sofar writes them). ``Data.Real`` and
``Data.Imag`` carry ``Units`` = ``metre/volt`` (m/V in SOFA's spelling: SOFA units are
written in lower case); ``GLOBAL_DateCreated`` is the calibration's date,
``GLOBAL_AuthorContact``, ``GLOBAL_Organization`` and ``GLOBAL_License`` what the caller
gives. Optional ``Coherence`` (M, R, N, E), units ``1``: the calibration's coherence of
each transfer function, a custom variable beside ``Data`` (SOFA readers that do not know
it ignore it).

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

__all__ = ["SOFA_CONVENTION", "SOFA_KEYS", "SOFA_H_UNITS", "write_sofa_tf", "read_sofa_tf", "import_sofar"]

#: The SOFA convention written and read.
SOFA_CONVENTION = "GeneralTF-E"
#: Keys of the record: ``H`` complex (n_freqs, n_points, n_actuators), m/V; ``freqs``
#: (n_freqs,), Hz; ``points_xy`` (n_points, 2) and ``actuators_xy`` (n_actuators, 2), m;
#: ``point_labels``, ``point_kinds``, ``actuator_names`` (lists of str); ``fs``, Hz;
#: ``band`` (low, high), Hz; ``participant_id`` str; ``layout`` dict (JSON-able).
SOFA_KEYS = ("H", "freqs", "points_xy", "actuators_xy", "point_labels", "point_kinds", "actuator_names", "fs",
             "band", "participant_id", "layout")
#: ``Units`` of ``Data.Real`` and ``Data.Imag``: m/V, spelt as SOFA spells units (lower case).
SOFA_H_UNITS = "metre/volt"
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


def _sofa_date(text: str) -> str:
    """An ISO 8601 time (the calibration's ``created``) as SOFA writes dates: ``yyyy-mm-dd HH:MM:SS`` (UTC)."""
    from datetime import UTC, datetime

    try:
        when = datetime.fromisoformat(str(text))
    except ValueError:
        raise ValidationError(f"the calibration's date {str(text)[:80]!r} is not an ISO 8601 time") from None
    if when.tzinfo is not None:
        when = when.astimezone(UTC)
    return when.strftime("%Y-%m-%d %H:%M:%S")


def write_sofa_tf(record: Mapping[str, Any], path: str | os.PathLike, *, title: str = "", author_contact: str = "",
                  organization: str = "", license: str | None = None) -> Path:
    """Write a transfer-matrix record to a SOFA ``GeneralTF-E`` file, atomically.

    sofar writes to a file name of its own; the variables' units that sofar cannot set
    (``Data.Real``/``Data.Imag`` ``Units``, see below) are added there with netCDF4
    (sofar's own backend); the bytes then go to ``path`` with
    :func:`vibrofocus._atomic.write_bytes`, so a reader never sees half a file and a
    previous file at ``path`` is unchanged after a failure.

    Parameters
    ----------
    record : mapping
        :data:`SOFA_KEYS`, and optionally ``created`` (ISO 8601 time of the
        measurement: ``GLOBAL_DateCreated``; without it, the time of writing) and
        ``coherence`` (real, same shape as ``H``, 0..1: written as the custom variable
        ``Coherence``).
    path : path-like
        Destination, conventionally ``*.sofa``; its folder must exist.
    title : str
        ``GLOBAL_Title``.
    author_contact : str
        ``GLOBAL_AuthorContact`` (who to ask about the data: a name, an e-mail).
    organization : str
        ``GLOBAL_Organization``.
    license : str, optional
        ``GLOBAL_License``; None keeps sofar's default ("No license provided, ask the
        author for permission").

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ValidationError
        A record whose shapes do not agree, a text with a control character, or sofar
        missing.
    OutputError
        The file cannot be written.
    """
    from .._atomic import write_bytes
    from .._validation import shorten

    sofar = import_sofar()
    missing = [k for k in SOFA_KEYS if k not in record]
    if missing:
        raise ValidationError(f"a SOFA record needs {', '.join(missing)}")
    for name, text in (("title", title), ("author_contact", author_contact), ("organization", organization),
                       ("license", license or "")):
        if not isinstance(text, str) or not text.isprintable():
            raise ValidationError(f"{name} must be a text without control characters, got {shorten(text)}")
    H = np.asarray(record["H"])
    freqs = np.asarray(record["freqs"], float)
    n_f, n_r, n_e = H.shape if H.ndim == 3 else (None, None, None)
    if n_f != len(freqs) or n_r != len(record["points_xy"]) or n_e != len(record["actuators_xy"]):
        raise ValidationError(f"H has shape {H.shape}, but there are {len(freqs)} frequencies, "
                              f"{len(record['points_xy'])} points and {len(record['actuators_xy'])} actuators")
    coherence = record.get("coherence")
    if coherence is not None:
        coherence = np.asarray(coherence, float)
        if coherence.shape != H.shape:
            raise ValidationError(f"the coherence has shape {coherence.shape}, H {H.shape}")
    sofa = sofar.Sofa(SOFA_CONVENTION)
    sofa.GLOBAL_Title = title
    sofa.GLOBAL_Comment = ("vibrofocus transfer matrix: skin displacement per actuator voltage (Data.Real and "
                           f"Data.Imag in {SOFA_H_UNITS}, i.e. m/V)")
    sofa.GLOBAL_AuthorContact = author_contact
    sofa.GLOBAL_Organization = organization
    if license:
        sofa.GLOBAL_License = license
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
    if coherence is not None:
        sofa.add_variable("Coherence", coherence.transpose(1, 0, 2)[None], "double", "MRNE")
        sofa.add_attribute("Coherence_Units", "1")
        sofa.add_attribute("Coherence_LongName", "coherence of each transfer function (0..1)")
    described = {"point_labels": list(record["point_labels"]), "point_kinds": list(record["point_kinds"]),
                 "actuator_names": list(record["actuator_names"]), "fs": float(record["fs"]),
                 "band": [float(b) for b in record["band"]], "participant_id": str(record["participant_id"]),
                 "layout": record["layout"]}
    for key, value in described.items():
        sofa.add_attribute(f"{_ATTR}{_ATTRS[key]}", json.dumps(value))
    with tempfile.TemporaryDirectory(prefix="vibrofocus-sofa-") as folder:
        built = Path(folder) / "transfer.sofa"
        sofar.write_sofa(str(built), sofa)  # sets DateCreated and DateModified to now
        import netCDF4  # sofar's backend: installed with it

        with netCDF4.Dataset(str(built), "a") as nc:
            # sofar refuses attributes of Data.Real (its name check allows one "_"), so
            # the units are set on the written variables.
            nc["Data.Real"].Units = SOFA_H_UNITS
            nc["Data.Imag"].Units = SOFA_H_UNITS
            if record.get("created"):
                nc.DateCreated = _sofa_date(record["created"])
        data = built.read_bytes()
    return write_bytes(Path(path), data, what="SOFA file")


def _fail(path: Path, what: str) -> CalibrationFileError:
    return CalibrationFileError(f"{path}: {what}")


#: Longest description attribute read, characters (a layout of hundreds of actuators is a few kB).
_MAX_ATTR_CHARS = 1_000_000
#: Deepest nesting of lists and objects a description attribute may have (a layout has 3).
_MAX_ATTR_DEPTH = 16
_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def _depth(value: Any) -> int:
    """Nesting depth of a JSON value (0 for a number or string), without recursion."""
    deepest, stack = 0, [(value, 0)]
    while stack:
        item, level = stack.pop()
        deepest = max(deepest, level)
        if isinstance(item, dict):
            stack.extend((v, level + 1) for v in item.values())
        elif isinstance(item, list):
            stack.extend((v, level + 1) for v in item)
    return deepest


def _json_attr(raw: Any, name: str) -> Any:
    """One JSON description attribute, bounded in length and nesting (ValidationError naming it)."""
    from .._validation import shorten

    if isinstance(raw, bytes):
        raw = raw.decode("utf-8", "replace")
    if not isinstance(raw, str):
        raise ValidationError(f"{name} must be JSON text, got {shorten(raw)}")
    if len(raw) > _MAX_ATTR_CHARS:
        raise ValidationError(f"{name} is {len(raw):,} characters long, more than a description needs "
                              f"({_MAX_ATTR_CHARS:,})")
    try:
        value = json.loads(raw)
    except RecursionError:  # nesting deeper than the parser's stack
        raise ValidationError(f"{name} is nested more than {_MAX_ATTR_DEPTH} levels deep") from None
    except ValueError:
        raise ValidationError(f"{name} is not JSON: {shorten(raw)}") from None
    if _depth(value) > _MAX_ATTR_DEPTH:
        raise ValidationError(f"{name} is nested more than {_MAX_ATTR_DEPTH} levels deep")
    return value


def _names(value: Any, name: str, n: int, what: str, choices: tuple[str, ...] | None = None) -> list[str]:
    """A list of ``n`` strings (or ``choices``), or ValidationError naming ``name``."""
    from .._validation import check_choice, shorten

    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise ValidationError(f"{name} must be a list of {n} texts (one per {what}), got {shorten(value)}")
    if len(value) != n:
        raise ValidationError(f"{name} must name the {n} {what}s, got {len(value)} name(s): {shorten(value)}")
    if choices is not None:
        for v in value:
            check_choice(v, name, choices)
    return value


def _array(raw: Any, name: str) -> np.ndarray:
    """A stored array as float64, or ValidationError naming it (text, objects, complex)."""
    from .._validation import as_array

    return as_array(np.ma.filled(raw, np.nan) if np.ma.isMaskedArray(raw) else raw, name, finite=False)


def read_sofa_tf(path: str | os.PathLike) -> dict[str, Any]:
    """Read a SOFA ``GeneralTF-E`` file written by :func:`write_sofa_tf` into its record.

    A ``GeneralTF-E`` file of another tool (without the ``GLOBAL_vibrofocus*``
    attributes) reads too: points and actuators are then named by number, the band is
    the frequency axis's extent and ``fs`` twice its top frequency.

    The file is treated as untrusted: before sofar reads it, every variable's declared
    size is checked against the bytes the file stores for it and all together against a
    cap from the file's size (:func:`vibrofocus.io._headers.check_hdf5_sizes`); every
    description attribute is bounded in length and nesting and checked for its type and
    range (``fs`` a positive number, ``band`` a pair ``0 < low < high <= fs/2``, one
    label per point and one name per actuator).

    Parameters
    ----------
    path : path-like

    Returns
    -------
    dict
        :data:`SOFA_KEYS`, and ``coherence`` (n_freqs, n_points, n_actuators), or None
        where the file has no ``Coherence``.

    Raises
    ------
    CalibrationFileError
        Missing or unreadable file, not netCDF-4/HDF5, arrays declared larger than the
        file holds, another convention, shapes that disagree, NaN/Inf, a frequency axis
        that does not rise, or a description attribute of the wrong type, range or
        size. The message names the file.
    """
    from .._atomic import protect
    from ._headers import check_hdf5_sizes

    sofar = import_sofar()
    path = Path(path)
    protect(path, "SOFA file")
    if not path.is_file():
        raise _fail(path, "no such SOFA file")
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
    except OSError as exc:
        raise _fail(path, f"cannot be read ({exc.strerror or exc})") from None
    if head != _HDF5_SIGNATURE:
        raise _fail(path, "is not a readable SOFA file (SOFA files are netCDF-4/HDF5; this one does not start "
                          "with the HDF5 signature)")
    try:
        check_hdf5_sizes(path, "a SOFA file")
        sofa = sofar.read_sofa(str(path), verify=False, verbose=False)
    except ValidationError as exc:
        raise _fail(path, str(exc)) from None
    except Exception as exc:  # noqa: BLE001 - netCDF4 and sofar raise many kinds
        raise _fail(path, f"is not a readable SOFA file ({str(exc)[:200]})") from None
    convention = getattr(sofa, "GLOBAL_SOFAConventions", None)
    if convention != SOFA_CONVENTION:
        raise _fail(path, f"is a SOFA {str(convention)[:80]} file; vibrofocus reads {SOFA_CONVENTION} transfer "
                          "matrices")
    try:
        return _record(sofa)
    except ValidationError as exc:
        raise _fail(path, str(exc)) from None


def _record(sofa: Any) -> dict[str, Any]:
    """The record of a read ``GeneralTF-E`` object, every field checked (ValidationError naming it)."""
    from .._validation import check_band, check_positive

    real, imag = _array(sofa.Data_Real, "Data.Real"), _array(sofa.Data_Imag, "Data.Imag")
    freqs = np.atleast_1d(_array(sofa.N, "N"))
    receivers = np.atleast_2d(_array(sofa.ReceiverPosition, "ReceiverPosition"))
    emitters = np.atleast_2d(_array(sofa.EmitterPosition, "EmitterPosition"))
    if real.ndim != 4 or real.shape != imag.shape or real.shape[0] != 1:
        raise ValidationError(f"Data.Real/Data.Imag have shapes {real.shape}/{imag.shape}; expected one measurement "
                              "(1, receivers, frequencies, emitters)")
    for name, arr in (("ReceiverPosition", receivers), ("EmitterPosition", emitters)):
        if arr.ndim != 2 or arr.shape[1] < 2:
            raise ValidationError(f"{name} must have one row of coordinates (x, y, z) per position, got shape "
                                  f"{arr.shape}")
    _, n_r, n_f, n_e = real.shape
    if freqs.ndim != 1 or (n_f, n_r, n_e) != (len(freqs), len(receivers), len(emitters)):
        raise ValidationError(f"the data ({n_r} receivers, {n_f} frequencies, {n_e} emitters) do not match "
                              f"{len(receivers)} receiver positions, {freqs.size} frequencies, {len(emitters)} "
                              "emitter positions")
    for name, arr in (("Data.Real", real), ("Data.Imag", imag), ("N", freqs), ("ReceiverPosition", receivers),
                      ("EmitterPosition", emitters)):
        if not np.isfinite(arr).all():
            raise ValidationError(f"{name} holds NaN/Inf")
    if n_f < 2 or (np.diff(freqs) <= 0).any():
        raise ValidationError("its frequency axis N must rise")
    attrs = {}
    for key in ("point_labels", "point_kinds", "actuator_names", "fs", "band", "participant_id", "layout"):
        name = f"{_ATTR}{_ATTRS[key]}"
        raw = getattr(sofa, name, None)
        attrs[key] = None if raw is None else _json_attr(raw, f"attribute {name}")
    fs_name, band_name = f"attribute {_ATTR}{_ATTRS['fs']}", f"attribute {_ATTR}{_ATTRS['band']}"
    if attrs["fs"] is None:
        fs = 2 * float(freqs[-1])
    elif isinstance(attrs["fs"], bool) or not isinstance(attrs["fs"], (int, float)):
        raise ValidationError(f"{fs_name} must be a number (Hz), got {type(attrs['fs']).__name__}")
    else:
        fs = check_positive(attrs["fs"], fs_name)
    if attrs["band"] is None:
        band = (float(freqs[0]), float(freqs[-1]))
    else:
        raw_band = attrs["band"]
        if not isinstance(raw_band, list) or len(raw_band) != 2 or not all(
                isinstance(b, (int, float)) and not isinstance(b, bool) for b in raw_band):
            raise ValidationError(f"{band_name} must be a pair [low_hz, high_hz], got {raw_band!r:.80}")
        band = check_band(raw_band, fs, band_name)
    participant = attrs["participant_id"]
    if participant is not None and not isinstance(participant, str):
        raise ValidationError(f"attribute {_ATTR}{_ATTRS['participant_id']} must be a text, got "
                              f"{type(participant).__name__}")
    layout = attrs["layout"]
    if layout is not None and not isinstance(layout, dict):
        raise ValidationError(f"attribute {_ATTR}{_ATTRS['layout']} must be a JSON object, got "
                              f"{type(layout).__name__}")
    H = (real[0] + 1j * imag[0]).transpose(1, 0, 2)
    coherence = getattr(sofa, "Coherence", None)
    if coherence is not None:
        coherence = _array(coherence, "Coherence")
        if coherence.shape != real.shape:
            raise ValidationError(f"Coherence has shape {coherence.shape}, Data.Real {real.shape}")
        if not np.isfinite(coherence).all() or (coherence < 0).any() or (coherence > 1 + 1e-9).any():
            raise ValidationError("Coherence must hold numbers from 0 to 1")
        coherence = coherence[0].transpose(1, 0, 2)
    return {"coherence": coherence,
        "H": H, "freqs": freqs, "points_xy": receivers[:, :2], "actuators_xy": emitters[:, :2],
        "point_labels": (_names(attrs["point_labels"], f"attribute {_ATTR}{_ATTRS['point_labels']}", n_r, "point")
                         if attrs["point_labels"] is not None else [str(k + 1) for k in range(n_r)]),
        "point_kinds": (_names(attrs["point_kinds"], f"attribute {_ATTR}{_ATTRS['point_kinds']}", n_r, "point",
                               ("location", "guard"))
                        if attrs["point_kinds"] is not None else ["location"] * n_r),
        "actuator_names": (_names(attrs["actuator_names"], f"attribute {_ATTR}{_ATTRS['actuator_names']}", n_e,
                                  "actuator")
                           if attrs["actuator_names"] is not None else [f"A{k + 1}" for k in range(n_e)]),
        "fs": fs, "band": band, "participant_id": participant or "", "layout": layout,
    }
