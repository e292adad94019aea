"""One self-describing netCDF4/HDF5 file per calibration (xarray + h5netcdf).

File layout (schema version 2), readable by any netCDF4 or HDF5 reader:

Dimensions
    ``frequency`` (n_fft/2 + 1), ``point``, ``actuator``, ``repeat``, ``drive_sample``,
    ``record_sample``.
Coordinates
    ``frequency`` (Hz), ``point`` (labels ``"1".."9"``, ``"G1"``..), ``point_x``,
    ``point_y`` (m, on ``point``), ``point_kind`` (``location``/``guard``), ``actuator``
    (names), ``actuator_x``, ``actuator_y`` (m).
Variables
    ``H_real``, ``H_imag`` (frequency, point, actuator), m/V: the complex transfer matrix
    as two real variables (plain netCDF4 has no complex type; this is what CF-minded
    readers expect); ``coherence`` (same dims, 1; NaN where not assessable);
    ``drive`` (actuator, drive_sample), V; ``recording`` (actuator, repeat, point,
    record_sample), m, float32, NaN marks a dropout (the simulated rig's: packed as
    int32 steps of its noise, CF ``scale_factor`` and ``_FillValue``, read back as float32); quality figures ``snr_db``,
    ``noise_rms``, ``band_gain``, ``low_coherence_share``, ``coherent_to_hz``, ``clipped``, ``repeats_used``,
    ``dropouts`` (point, actuator) and ``polarity`` (actuator).
    Method ``mimo`` (all actuators in every take) stores ``recording`` as (take, point,
    record_sample) instead, and adds ``code`` (take, actuator; the sign of each
    actuator's sweep in each take), ``multiple_coherence``, ``input_condition`` and
    ``input_correlation`` (frequency, point).
    Optional, when the skin model was fitted (``cal.fit``, :func:`.fit_model`):
    ``fit_value`` (fit_parameter; SI units, named by the coordinate ``fit_parameter``),
    ``fit_std`` (same), ``fit_log_covariance`` (fit_parameter, fit_parameter_b; of the
    natural logarithms) and ``fit_residual`` (point), with the attribute ``fit`` (JSON:
    band, fs, fixed settings, diagnostics). Files without them load as before, and
    readers that do not know them ignore them.
    ``point_measured`` (point; int8, 1 = measured, 0 = predicted): which rows of H were
    measured and which the fitted skin model predicted (a calibration of a subset of
    the points, ``calibrate(..., measure=K)``; its ``fit_*`` variables hold the model).
    A predicted row's recordings are NaN and its figures of a recording (SNR,
    coherence, ...) NaN or 0. Written by every calibration; a file without it has every
    row measured.
Attributes
    ``file_kind = "vibrofocus calibration"``, ``schema_version``, ``software``,
    ``software_version``, ``participant_id``, ``method``, ``fs`` (Hz), ``band_low``,
    ``band_high`` (Hz), ``n_fft``, ``created``, and JSON strings ``layout``, ``rig``,
    ``sweep``, ``quality_issues``, ``quality_thresholds``; ``recorded_s`` (s, the real
    duration of the takes) when known.

Version 2 added the ``mimo`` variables, ``recorded_s`` and two quality thresholds;
version 1 files (``h1``/``paper`` only) load unchanged, their missing thresholds taking
the defaults. :func:`read_calibration_file` checks all of it and raises
:class:`~vibrofocus.errors.CalibrationFileError` naming the file and what is wrong.

This module reads and writes a *calibration record*
(:class:`~vibrofocus.io.calibration_record.CalibrationFileRecord`, a frozen dataclass of
arrays, numbers, strings and JSON-like dicts that checks its own consistency), never a
domain object. The :class:`~vibrofocus.calibration.Calibration` is built from the record
one floor up, by :func:`vibrofocus.calibration.load_calibration`, which also checks the
points and actuators against the layout.
"""

from __future__ import annotations

import contextlib
import gc
import json
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from collections.abc import Mapping
from typing import Any

import numpy as np

from .._validation import shorten
from ..errors import CalibrationFileError, ValidationError
from ._headers import check_hdf5_sizes
from .calibration_record import RECORD_KEYS, CalibrationFileRecord, FitRecord, QualityRecord
from .jsonsafe import json_safe

__all__ = ["SCHEMA_VERSION", "FILE_KIND", "RECORD_KEYS", "CalibrationFileRecord", "write_calibration_file",
           "read_calibration_file", "calibration_bytes", "estimate_calibration_bytes"]

#: Version of the calibration file layout this vibrofocus writes (and the newest it reads).
SCHEMA_VERSION = 2
#: The ``file_kind`` attribute that marks a vibrofocus calibration file.
FILE_KIND = "vibrofocus calibration"
_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
_QUALITY_VARS = {
    "snr_db": ("dB", "in-band signal-to-noise ratio"),
    "noise_rms": ("m", "in-band noise floor from the pre-sweep silence"),
    "band_gain": ("m/V", "RMS of |H| over the calibrated band"),
    "low_coherence_share": ("1", "share of band frequencies with low coherence"),
    "coherent_to_hz": ("Hz", "frequency up to which the pair is coherent"),
    "clipped": ("1", "1 if any recording of the pair was clipped"),
    "repeats_used": ("1", "recordings kept after excluding dropouts"),
    "dropouts": ("1", "recordings left out because of dropouts"),
}
_REQUIRED_VARS = ("H_real", "H_imag", "coherence", "drive", "recording", *_QUALITY_VARS, "polarity")
#: Variables of a ``mimo`` calibration besides those: dimensions, units, meaning.
_MIMO_VARS = {
    "code": (("take", "actuator"), "1", "sign of each actuator's sweep in each take (+1/-1)"),
    "multiple_coherence": (("frequency", "point"), "1",
                           "share of the response the actuators together explain (NaN: not assessable)"),
    "input_condition": (("frequency", "point"), "1", "condition number of the input spectral matrix"),
    "input_correlation": (("frequency", "point"), "1", "largest normalised input cross-spectrum"),
}
_REQUIRED_ATTRS = ("schema_version", "participant_id", "method", "fs", "band_low", "band_high", "n_fft",
                   "created", "software_version", "layout", "rig", "sweep", "quality_issues",
                   "quality_thresholds")


def _to_dataset(rec: CalibrationFileRecord):
    import xarray as xr

    pts, act = np.asarray(rec.points_xy, float), np.asarray(rec.actuators_xy, float)
    q = rec.quality
    method = rec.method
    pa = ("point", "actuator")
    data_vars = {
        "H_real": (("frequency", *pa), rec.H.real, {"units": "m/V", "long_name": "transfer matrix, real part"}),
        "H_imag": (("frequency", *pa), rec.H.imag, {"units": "m/V", "long_name": "transfer matrix, imaginary part"}),
        "coherence": (("frequency", *pa), rec.coherence,
                      {"units": "1", "long_name": "coherence over repeats (NaN: not assessable)"}),
        "drive": (("actuator", "drive_sample"), rec.drives,
                  {"units": "V", "long_name": "voltage on the measured actuator's channel (others zero)"}),
        "recording": (_recording_dims(method), rec.recordings,
                      {"units": "m", "long_name": "raw displacement (NaN: dropout)"}),
        "polarity": (("actuator",), np.asarray(q.polarity).astype(np.int8),
                     {"units": "1", "long_name": "relative polarity (+1/-1, 0 not judged)"}),
    }
    figures = {"snr_db": q.snr_db, "noise_rms": q.noise_rms_m, "band_gain": q.band_gain,
               "low_coherence_share": q.low_coherence_share, "coherent_to_hz": q.coherent_to_hz,
               "clipped": np.asarray(q.clipped).astype(np.int8),
               "repeats_used": np.asarray(q.repeats_used).astype(np.int32),
               "dropouts": np.asarray(q.dropouts).astype(np.int32)}
    for name, values in figures.items():
        units, long_name = _QUALITY_VARS[name]
        data_vars[name] = (pa, values, {"units": units, "long_name": long_name})
    if method == "mimo":
        mimo = {"code": np.asarray(rec.codes).astype(np.int8), "multiple_coherence": rec.multiple_coherence,
                "input_condition": q.input_condition, "input_correlation": q.input_correlation}
        for name, values in mimo.items():
            dims, units, long_name = _MIMO_VARS[name]
            data_vars[name] = (dims, values, {"units": units, "long_name": long_name})
    coords = {}
    fit = rec.fit
    if fit is not None:
        coords["fit_parameter"] = ("fit_parameter", list(fit.names))
        data_vars["fit_value"] = (("fit_parameter",), fit.values,
                                  {"units": "SI", "long_name": "fitted skin-model parameter"})
        data_vars["fit_std"] = (("fit_parameter",), fit.std, {"units": "SI", "long_name": "standard error"})
        data_vars["fit_log_covariance"] = (("fit_parameter", "fit_parameter_b"), fit.log_covariance,
                                           {"units": "1", "long_name": "covariance of log parameters"})
        data_vars["fit_residual"] = (("point",), fit.residual,
                                     {"units": "1", "long_name": "relative fit residual per point"})
    measured = rec.measured
    measured = np.ones(len(rec.point_labels), bool) if measured is None else np.asarray(measured, bool)
    data_vars["point_measured"] = (("point",), measured.astype(np.int8), {
        "units": "1", "long_name": "1 if H at the point was measured, 0 if predicted by the fitted skin model",
        "flag_values": np.array([0, 1], np.int8), "flag_meanings": "predicted measured"})
    coords |= {
        "frequency": ("frequency", rec.freqs, {"units": "Hz"}),
        "point": ("point", list(rec.point_labels)),
        "point_x": ("point", pts[:, 0], {"units": "m", "long_name": "x, across the arm toward the thumb"}),
        "point_y": ("point", pts[:, 1], {"units": "m", "long_name": "y, along the arm toward the wrist"}),
        "point_kind": ("point", list(rec.point_kinds)),
        "actuator": ("actuator", list(rec.actuator_names)),
        "actuator_x": ("actuator", act[:, 0], {"units": "m"}),
        "actuator_y": ("actuator", act[:, 1], {"units": "m"}),
    }
    attrs = {
        "title": f"vibrofocus calibration of {rec.participant_id}",
        "file_kind": FILE_KIND,
        "schema_version": np.int32(SCHEMA_VERSION),
        "software": "vibrofocus",
        "software_version": rec.software_version,
        "participant_id": rec.participant_id,
        "method": method,
        "fs": float(rec.fs),
        "band_low": float(rec.band[0]),
        "band_high": float(rec.band[1]),
        "n_fft": np.int32(rec.n_fft),
        "created": rec.created,
        "layout": json.dumps(rec.layout),
        "rig": _json_text(rec.rig),
        "sweep": json.dumps(rec.sweep),
        "quality_issues": json.dumps(list(q.issues)),
        "quality_thresholds": json.dumps(q.thresholds),
    }
    if rec.straps is not None:
        attrs["strap_forces"] = json.dumps(rec.straps)
    if np.isfinite(rec.recorded_s):
        attrs["recorded_s"] = float(rec.recorded_s)
    if fit is not None:
        attrs["fit"] = _json_text({"band": list(fit.band), "fs": fit.fs, "fixed": fit.fixed,
                                   "info": fit.info})
    return xr.Dataset(data_vars, coords=coords, attrs=attrs)


def _recording_dims(method: str) -> tuple[str, ...]:
    """Dimensions of ``recording``: one actuator per take, or all at once (``mimo``)."""
    if method == "mimo":
        return ("take", "point", "record_sample")
    return ("actuator", "repeat", "point", "record_sample")


def _json_text(value) -> str:
    """A description attribute as JSON text (NaN kept: Python's json reads it back)."""
    return json.dumps(json_safe(value, finite=False), default=str)


def calibration_bytes(record: CalibrationFileRecord | Mapping[str, Any]) -> bytes:
    """The calibration file's bytes (netCDF4/HDF5), built in memory from a record.

    Serializing in memory first means the HDF5 library never writes to the disk itself:
    a full disk then surfaces as a plain, catchable ``OSError`` at the write, never as a
    crash inside the library.

    Parameters
    ----------
    record : CalibrationFileRecord or mapping
        The record, or a mapping keyed as :data:`RECORD_KEYS` (made into one, and so checked).
    """
    if not isinstance(record, (CalibrationFileRecord, Mapping)):
        raise ValidationError(f"a calibration record must be a CalibrationFileRecord, got {type(record).__name__}")
    rec = CalibrationFileRecord.from_mapping(record)
    ds = _to_dataset(rec)
    # Every array carries an HDF5 Fletcher-32 checksum: a flipped bit in H (a plausible,
    # finite, wrong value) then fails loading instead of silently changing the design.
    # Arrays of floats are compressed without loss (byte shuffle and zlib): H and the
    # other figures keep every bit of their float64 (docs/file-formats.md, "Size and precision").
    encoding = {name: {"fletcher32": True, **(_LOSSLESS if var.dtype.kind == "f" and var.size >= 1024 else {})}
                for name, var in ds.variables.items() if var.size > 1 and var.dtype.kind in "fiub"}
    encoding["recording"] = _recording_encoding(rec)
    return bytes(ds.to_netcdf(None, engine="h5netcdf", encoding=encoding))


_LOSSLESS = {"zlib": True, "complevel": 1, "shuffle": True}
#: A simulated rig's recordings are stored in steps of this part of their smallest noise floor.
RECORDING_STEP_OF_NOISE = 1 / 16
#: The packed recording's count for a dropout (NaN).
_PACKED_FILL = np.int32(-(2**31))


def _recording_encoding(rec: CalibrationFileRecord) -> dict[str, Any]:
    """How ``recording`` is stored: float32, or a simulated rig's as int32 steps of its noise.

    Raw recordings are mostly noise, which hardly compresses: light, fast zlib. A hardware
    rig's are kept as float32 (every bit of a 24-bit converter). The simulated forearm's
    are made again from its seed, and stored as counts of :data:`RECORDING_STEP_OF_NOISE`
    times the smallest noise floor of the file (CF packing: ``scale_factor``, ``_FillValue``):
    the rounding adds noise of RMS step/sqrt(12), 1/55 of the noise floor (0.03 % of its
    power), and the file is about half as large.
    """
    plain = {"zlib": True, "complevel": 1, "shuffle": True, "fletcher32": True}
    noise = np.asarray(rec.quality.noise_rms_m, float)
    noise = noise[np.isfinite(noise) & (noise > 0)]
    if (rec.rig or {}).get("kind") != "simulated" or not noise.size:
        return plain | {"dtype": "float32"}
    step = float(noise.min() * RECORDING_STEP_OF_NOISE)
    peak = float(np.nanmax(np.abs(rec.recordings), initial=0.0))
    if not np.isfinite(peak) or peak / step >= 2**31 - 2:
        return plain | {"dtype": "float32"}
    return plain | {"dtype": "int32", "scale_factor": step, "_FillValue": _PACKED_FILL}


def _unpacked_recording(ds, path: Path) -> np.ndarray:
    """``recording`` as float32, m: stored so, or packed as int32 steps (:func:`_recording_encoding`)."""
    var = ds["recording"]
    if not np.issubdtype(var.dtype, np.integer):
        return var.values
    step = var.attrs.get("scale_factor", var.encoding.get("scale_factor"))
    fill = var.attrs.get("_FillValue", var.encoding.get("_FillValue", _PACKED_FILL))
    try:
        step = float(np.asarray(step).reshape(()))
    except (TypeError, ValueError):
        step = float("nan")
    if not (np.isfinite(step) and step > 0):
        raise _fail(path, f"variable recording is packed as integers without a positive scale_factor (got {step!r})")
    counts = var.values
    out = (counts * step).astype(np.float32)
    out[counts == fill] = np.nan
    return out


def estimate_calibration_bytes(n_points: int, n_actuators: int, repeats: int, n_record: int, n_fft: int,
                               *, all_at_once: bool = False) -> int:
    """Upper estimate of a calibration file's size, bytes (for a free-space check before measuring).

    Parameters
    ----------
    n_points, n_actuators : int
        Recorded points and actuators.
    repeats : int
        Recordings per point and actuator.
    n_record : int
        Samples per recording.
    n_fft : int
        FFT length of the stored transfer matrix.
    all_at_once : bool
        All actuators play in every take (``mimo``): one recording set, not one per actuator.
    """
    n_freqs = n_fft // 2 + 1
    sets = 1 if all_at_once else n_actuators
    recordings = 4 * sets * repeats * n_points * n_record  # float32, noise hardly compresses
    matrices = 3 * 8 * n_freqs * n_points * n_actuators  # H real, H imag, coherence
    drives = 8 * n_actuators * n_record
    mimo = 3 * 8 * n_freqs * n_points if all_at_once else 0  # multiple coherence, conditioning
    return int(1.1 * (recordings + matrices + drives + mimo)) + 64 * 1024


def write_calibration_file(record: CalibrationFileRecord | Mapping[str, Any], path: str | os.PathLike) -> Path:
    """Write a calibration record to one netCDF4/HDF5 file (see the module docstring).

    The file is built in memory, written next to its destination, fsynced and renamed
    over it (:func:`vibrofocus._atomic.atomic_write`): a full disk, a read-only folder
    or an interrupt never leaves a half-written calibration under ``path``, and a
    previous file there is unchanged.

    Parameters
    ----------
    record : CalibrationFileRecord or mapping
        The calibration's arrays and descriptions (a mapping keyed as :data:`RECORD_KEYS`
        is made into a record, and so checked).
    path : str or PathLike
        Destination, conventionally ``*.nc``; its folder must exist.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    OutputError
        The file cannot be written (no space, read-only, missing folder, ...); the
        record is untouched, so the caller can save it elsewhere.
    """
    from .._atomic import write_bytes

    data = calibration_bytes(record)
    return write_bytes(Path(path), data, what="calibration")


def _fail(path: Path, what: str) -> CalibrationFileError:
    return CalibrationFileError(f"{path}: {what}")


def read_calibration_file(path: str | os.PathLike) -> CalibrationFileRecord:
    """Read and validate a calibration file into a record.

    Parameters
    ----------
    path : str or PathLike

    Returns
    -------
    CalibrationFileRecord
        The record: plain arrays, numbers, strings and JSON-like dicts.

    Raises
    ------
    CalibrationFileError
        Missing or unreadable file; not HDF5 (foreign file); truncated or corrupt HDF5;
        not a vibrofocus calibration; unknown schema version; missing variables or
        attributes; inconsistent dimensions, shapes or dtypes; NaN/Inf in the transfer
        matrix (named with its frequency, point and actuator), or a finite one that no
        skin gives (a magnitude of H above :data:`~vibrofocus.defaults.H_MAX_M_PER_V` anywhere, or
        the whole array below :data:`~vibrofocus.defaults.H_MIN_PEAK_M_PER_V` in the
        band; named likewise); a bad band. The message names the file. (Points and
        actuators are checked against the layout where the layout is built,
        :func:`vibrofocus.calibration.load_calibration`.)
    """
    import xarray as xr

    from .._atomic import protect

    path = Path(path)
    protect(path, "calibration")
    if not path.exists():
        raise _fail(path, "no such calibration file")
    if not path.is_file():
        raise _fail(path, "is not a file")
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
    except OSError as exc:
        raise _fail(path, f"cannot be read ({exc.strerror or exc})") from exc
    if head != _HDF5_SIGNATURE:
        what = "it is empty" if not head else f"it starts with {head!r}"
        raise _fail(path, f"is not a netCDF4/HDF5 calibration file ({what}, not the HDF5 signature)")
    problem = None
    with _quiet_half_open_files():
        try:
            shapes, unknown = check_hdf5_sizes(path, "a calibration file", _KNOWN_VARS)
            with xr.open_dataset(path, engine="h5netcdf", mask_and_scale=False, phony_dims="access",
                                 drop_variables=unknown) as ds:
                _check_netcdf_shapes(ds, shapes, unknown)
                ds = ds.load()
        except ValidationError as exc:
            raise _fail(path, str(exc)) from None
        except Exception as exc:  # h5py reports truncation as OSError, others as ValueError/KeyError
            problem = str(exc)[:300]
    if problem is not None:
        # Not chained: the traceback would keep h5netcdf's half-open file alive.
        raise _fail(path, f"is truncated or corrupt: the HDF5 library could not read it ({problem})")
    return _from_dataset(ds, path)


#: Every variable and coordinate a calibration file of this schema may hold; others are never read.
_KNOWN_VARS = frozenset({*_REQUIRED_VARS, *_MIMO_VARS, "fit_value", "fit_std", "fit_log_covariance", "fit_residual",
                         "point_measured",
                         "fit_parameter", "frequency", "point", "point_x", "point_y", "point_kind", "actuator",
                         "actuator_x", "actuator_y"})


def _check_netcdf_shapes(ds, shapes: Mapping[str, tuple[int, ...]], unknown: list[str]) -> None:
    """Refuse, before loading, a known variable whose netCDF view differs from its HDF5 header.

    A dataset added with plain HDF5 tools carries no netCDF dimensions; the reader then
    makes up dimensions for it from its shape, which can resize a known variable (a
    frequency axis of 5e9 values from an added 5e9-element dataset)."""
    for name, shape in shapes.items():
        if name in ds.variables and tuple(ds[name].shape) != shape:
            foreign = f" (it holds datasets this schema does not name: {shorten(', '.join(unknown), as_text=True)})"
            raise ValidationError(f"variable {name} reads as shape {tuple(ds[name].shape)} but its HDF5 header "
                                  f"declares {shape}: the file's netCDF dimensions are inconsistent, as when "
                                  f"datasets are added with plain HDF5 tools{foreign if unknown else ''}")


@contextlib.contextmanager
def _quiet_half_open_files() -> Iterator[None]:
    """Silence what a half-constructed h5netcdf file says when it is collected.

    A corrupt header stops ``h5netcdf.File.__init__`` midway; the object's ``__del__``
    then fails (``'File' object has no attribute '_writable'``) and Python prints an
    "Exception ignored" traceback after the one-line error. The object is collected
    here, inside the body's scope, with that one report dropped.
    """
    previous = sys.unraisablehook

    def hook(unraisable) -> None:
        if "h5netcdf" not in getattr(getattr(unraisable.object, "__func__", unraisable.object), "__module__", ""):
            previous(unraisable)

    sys.unraisablehook = hook
    try:
        yield
    finally:
        gc.collect()
        sys.unraisablehook = previous


def _number_attr(attrs, name: str, path: Path) -> float:
    """One real number from a global attribute, or CalibrationFileError naming it."""
    raw = attrs[name]
    try:
        arr = np.asarray(raw)
        if arr.size != 1 or arr.dtype.kind not in "iuf":
            raise TypeError
        return float(arr.reshape(()).item())
    except (TypeError, ValueError):
        raise _fail(path, f"attribute {name} must be one number, got {raw!r}") from None


def _from_dataset(ds, path: Path) -> CalibrationFileRecord:
    """The record a loaded dataset holds; what the record checks itself is reported with the path."""
    attrs = ds.attrs
    version, method = _header(ds, path)
    described = _descriptions(attrs, path)
    _check_dims(ds, method, path)
    labels = [str(v) for v in ds["point"].values]
    names = [str(v) for v in ds["actuator"].values]
    H_real, H_imag = ds["H_real"].values, ds["H_imag"].values
    mimo = method == "mimo"
    fit = _fit_from_dataset(ds, attrs, path) if "fit_value" in ds.variables else None
    try:
        record = CalibrationFileRecord(
            H=H_real.astype(float) + 1j * H_imag.astype(float), freqs=np.asarray(ds["frequency"].values, float),
            coherence=ds["coherence"].values.astype(float), drives=ds["drive"].values,
            recordings=_unpacked_recording(ds, path), fs=_number_attr(attrs, "fs", path),
            band=(_number_attr(attrs, "band_low", path), _number_attr(attrs, "band_high", path)),
            n_fft=_integer_attr(attrs, "n_fft", path), method=method, participant_id=str(attrs["participant_id"]),
            created=str(attrs["created"]), software_version=str(attrs["software_version"]), schema_version=version,
            layout=described["layout"], point_labels=labels,
            point_kinds=[str(v) for v in ds["point_kind"].values] if "point_kind" in ds.variables else None,
            actuator_names=names, points_xy=_xy(ds, "point"), actuators_xy=_xy(ds, "actuator"),
            rig=described["rig"], sweep=described["sweep"], quality=_quality_from_dataset(ds, described, mimo),
            codes=ds["code"].values if mimo else None,
            multiple_coherence=ds["multiple_coherence"].values.astype(float) if mimo else None,
            straps=described["strap_forces"],
            recorded_s=_number_attr(attrs, "recorded_s", path) if "recorded_s" in attrs else float("nan"),
            fit=fit, measured=ds["point_measured"].values if "point_measured" in ds.variables else None)
    except ValidationError as exc:
        raise _fail(path, str(exc)) from None
    freqs = record.freqs
    for name, arr in (("H_real", H_real), ("H_imag", H_imag)):
        bad = ~np.isfinite(arr)
        if bad.any():
            f, p, a = np.argwhere(bad)[0]
            raise _fail(path, f"variable {name} holds {int(bad.sum())} NaN/Inf value(s); first at "
                              f"{freqs[f]:g} Hz, point {labels[p]}, actuator {names[a]}")
    _check_plausible(H_real, H_imag, freqs, record.band, labels, names, path)
    return record


def _header(ds, path: Path) -> tuple[int, str]:
    """The file's schema version and method, after checking its kind and that nothing required is missing."""
    attrs = ds.attrs
    if attrs.get("file_kind") != FILE_KIND:
        raise _fail(path, f"is an HDF5/netCDF file but not a vibrofocus calibration (file_kind is "
                          f"{attrs.get('file_kind')!r}, expected {FILE_KIND!r})")
    raw_version = attrs.get("schema_version")
    try:
        value = np.asarray(raw_version).item()
        if isinstance(value, (bool, np.bool_)) or not float(value).is_integer():
            raise ValueError
        version = int(value)
    except (TypeError, ValueError, OverflowError):
        raise _fail(path, f"has no valid schema_version (got {raw_version!r}; expected an integer)") from None
    if version > SCHEMA_VERSION:
        raise _fail(path, f"has schema version {version}, newer than this vibrofocus reads "
                          f"({SCHEMA_VERSION}); it was written by vibrofocus {attrs.get('software_version', '?')}; "
                          "upgrade vibrofocus")
    if version < 1:
        raise _fail(path, f"has schema version {version}, which no vibrofocus release wrote "
                          f"(this version reads {SCHEMA_VERSION})")
    missing = [a for a in _REQUIRED_ATTRS if a not in attrs]
    if missing:
        raise _fail(path, f"lacks the attribute(s) {', '.join(missing)}")
    method = str(attrs["method"])
    mimo = method == "mimo"
    if mimo and version < 2:
        raise _fail(path, f"has method mimo but schema version {version}; mimo calibrations are version 2 or later")
    missing = [v for v in (*_REQUIRED_VARS, *(_MIMO_VARS if mimo else ())) if v not in ds.variables]
    if missing:
        raise _fail(path, f"lacks the variable(s) {', '.join(missing)}")
    return version, method


def _descriptions(attrs, path: Path) -> dict[str, Any]:
    """The JSON attributes, parsed and of the right kind (``strap_forces`` None when absent)."""
    kinds = {"layout": dict, "rig": dict, "sweep": dict, "quality_issues": list, "quality_thresholds": dict}
    try:
        out = {name: json.loads(attrs[name]) for name in kinds}
        out["strap_forces"] = json.loads(attrs["strap_forces"]) if "strap_forces" in attrs else None
    except (ValueError, TypeError) as exc:  # JSONDecodeError is a ValueError
        raise _fail(path, f"has an unreadable description attribute ({exc})") from exc
    for name in ("rig", "layout", "sweep", "quality_issues", "quality_thresholds"):
        if not isinstance(out[name], kinds[name]):
            raise _fail(path, f"has an unreadable description attribute (attribute {name} must be a JSON "
                              f"{'object' if kinds[name] is dict else 'list'}, got {type(out[name]).__name__})")
    return out


def _check_dims(ds, method: str, path: Path) -> None:
    """Every known variable on its dimensions, numeric, and floating point where the data is."""
    expected_dims = {
        "H_real": ("frequency", "point", "actuator"), "H_imag": ("frequency", "point", "actuator"),
        "coherence": ("frequency", "point", "actuator"), "drive": ("actuator", "drive_sample"),
        "recording": _recording_dims(method), "polarity": ("actuator",),
        **{name: ("point", "actuator") for name in _QUALITY_VARS},
        **({name: spec[0] for name, spec in _MIMO_VARS.items()} if method == "mimo" else {}),
    }
    for name, dims in expected_dims.items():
        if ds[name].dims != dims:
            raise _fail(path, f"variable {name} has dimensions {ds[name].dims}, expected {dims}")
        if not np.issubdtype(ds[name].dtype, np.number):
            raise _fail(path, f"variable {name} has dtype {ds[name].dtype}, expected a numeric type")
    for name in ("H_real", "H_imag", "coherence", "drive", "recording"):
        if name == "recording" and np.issubdtype(ds[name].dtype, np.integer):
            continue  # packed: _unpacked_recording checks its scale
        if not np.issubdtype(ds[name].dtype, np.floating):
            raise _fail(path, f"variable {name} has dtype {ds[name].dtype}, expected floating point")


def _xy(ds, dim: str) -> np.ndarray:
    """The stored positions on ``point`` or ``actuator``, m, shape (n, 2)."""
    return np.stack([ds[f"{dim}_x"].values, ds[f"{dim}_y"].values], axis=1).astype(float)


def _integer_attr(attrs, name: str, path: Path) -> float | int:
    """A number attribute, as an int when it is a whole number (the record refuses the rest)."""
    value = _number_attr(attrs, name, path)
    return int(value) if float(value).is_integer() else value


def _quality_from_dataset(ds, described: Mapping[str, Any], mimo: bool) -> QualityRecord:
    return QualityRecord(
        issues=described["quality_issues"], thresholds=described["quality_thresholds"],
        snr_db=ds["snr_db"].values, noise_rms_m=ds["noise_rms"].values, band_gain=ds["band_gain"].values,
        low_coherence_share=ds["low_coherence_share"].values, coherent_to_hz=ds["coherent_to_hz"].values,
        clipped=ds["clipped"].values.astype(bool), repeats_used=ds["repeats_used"].values.astype(int),
        dropouts=ds["dropouts"].values.astype(int), polarity=ds["polarity"].values.astype(int),
        input_condition=ds["input_condition"].values.astype(float) if mimo else None,
        input_correlation=ds["input_correlation"].values.astype(float) if mimo else None)


def _check_plausible(H_real: np.ndarray, H_imag: np.ndarray, freqs: np.ndarray, band: tuple[float, float],
                     labels: list[str], names: list[str], path: Path) -> None:
    """Refuse a finite H that no skin gives (:data:`~vibrofocus.defaults.H_MAX_M_PER_V`,
    :data:`~vibrofocus.defaults.H_MIN_PEAK_M_PER_V`), naming where and what."""
    from ..defaults import H_MAX_M_PER_V, H_MIN_PEAK_M_PER_V

    mag = np.hypot(H_real, H_imag)
    f, p, a = np.unravel_index(int(np.argmax(mag)), mag.shape)
    if mag[f, p, a] > H_MAX_M_PER_V:
        n_over = int((mag > H_MAX_M_PER_V).sum())
        raise _fail(path, f"its transfer matrix is not physically plausible: |H| = {mag[f, p, a]:.3g} m/V at "
                          f"{freqs[f]:g} Hz, point {labels[p]}, actuator {names[a]} ({n_over} value(s) above "
                          f"{H_MAX_M_PER_V:g} m/V, i.e. {H_MAX_M_PER_V * 1e3:g} mm of skin motion per volt); the "
                          "file is corrupt or was edited: calibrate again")
    inside = (freqs >= band[0]) & (freqs <= band[1])
    peak = float(mag[inside].max()) if inside.any() else 0.0
    if peak < H_MIN_PEAK_M_PER_V:
        raise _fail(path, f"its transfer matrix is not physically plausible: |H| is at most {peak:.3g} m/V over the "
                          f"band {band[0]:g}-{band[1]:g} Hz, below {H_MIN_PEAK_M_PER_V:g} m/V (1 pm per volt): no "
                          "actuator moved the skin measurably; check the rig and calibrate again")


def _fit_from_dataset(ds, attrs, path: Path) -> FitRecord:
    """The stored skin-model fit, or CalibrationFileError naming what is wrong."""
    missing = [v for v in ("fit_log_covariance", "fit_residual") if v not in ds.variables]
    if "fit" not in attrs:
        missing.append("attribute fit")
    if missing:
        raise _fail(path, f"has fit_value but lacks {', '.join(missing)}")
    try:
        meta = json.loads(attrs["fit"])
        return FitRecord(names=[str(v) for v in ds["fit_parameter"].values], fs=float(meta["fs"]),
                         band=tuple(meta["band"]), values=ds["fit_value"].values.astype(float),
                         std=ds["fit_std"].values.astype(float) if "fit_std" in ds.variables else None,
                         log_covariance=ds["fit_log_covariance"].values.astype(float),
                         residual=ds["fit_residual"].values.astype(float), fixed=meta["fixed"],
                         info=meta.get("info", {}))
    except (ValueError, TypeError, KeyError) as exc:
        raise _fail(path, f"has an unreadable skin-model fit ({exc})") from exc
