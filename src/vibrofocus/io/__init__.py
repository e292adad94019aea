"""File formats: one module per on-disk format, each the only writer and reader of it.

:mod:`.calibration_nc`
    Calibration files (netCDF4/HDF5), as records (:class:`CalibrationFileRecord`, a frozen
    dataclass of :mod:`.calibration_record` that checks itself): :func:`write_calibration_file`,
    :func:`read_calibration_file` (the :class:`~vibrofocus.calibration.Calibration` is built
    above, by :func:`vibrofocus.calibration.load_calibration`).
:mod:`.drives`
    Drives files (``.npz``, ``.csv``, ``.wav``): :func:`write_drives`,
    :func:`write_drives_wav`, :func:`read_drives`.
:mod:`.trials_csv`
    The trials file (CSV): :func:`write_trials_csv`, :func:`read_trials_csv`,
    :func:`read_trials_table`.
:mod:`.responses`
    A stored response (``"4 5"``): :func:`format_response`, :func:`parse_response_text`.
:mod:`.report_json`
    report.json: :func:`write_report_json`, :func:`read_report_json`, :func:`check_report`.
:mod:`.feature_bank`
    Feature banks of simulated forearms (``.npz``): :func:`save_feature_bank`,
    :func:`load_feature_bank`.
:mod:`.layout_json`
    Array layout files (JSON): :func:`write_layout_json`, :func:`read_layout_json`.
:mod:`.jsonsafe`
    The one JSON sanitizer, :func:`json_safe`.
:mod:`.bids`
    BIDS behavioural datasets (``vibrofocus export --bids``): :func:`write_bids_dataset`,
    :func:`read_bids_trials_table`.
:mod:`.lsl`
    Lab Streaming Layer markers (``--lsl``, extra ``vibrofocus[lsl]``): :class:`MarkerOutlet`,
    :func:`marker_code` (the event codes), :func:`stable_source_id`.
:mod:`.files`
    Any other file, written atomically under the package's rules: :func:`write_text`,
    :func:`save_figure`, :func:`atomic_path` (for scripts and other programs).
:mod:`.sofa`
    Transfer matrices as SOFA ``GeneralTF-E`` files (extra ``vibrofocus[sofa]``):
    :func:`write_sofa_tf`, :func:`read_sofa_tf`.

This package is the bottom floor: it reads and writes plain arrays and records and
imports nothing of vibrofocus but :mod:`~vibrofocus.errors`, :mod:`~vibrofocus.defaults`,
:mod:`~vibrofocus._validation` and :mod:`~vibrofocus._atomic` (tests/test_layering.py), so
every layer can use it and domain objects are built above it.
"""

from .bids import read_bids_trials_table, write_bids_dataset
from .calibration_nc import read_calibration_file, write_calibration_file
from .calibration_record import CalibrationFileRecord
from .drives import read_drives, write_drives, write_drives_wav
from .feature_bank import load_feature_bank, save_feature_bank
from .files import atomic_path, save_figure, write_text
from .jsonsafe import json_safe
from .layout_json import read_layout_json, write_layout_json
from .lsl import MarkerOutlet, marker_code, stable_source_id
from .report_json import check_report, read_report_json, write_report_json
from .responses import format_response, parse_response_text
from .sofa import read_sofa_tf, write_sofa_tf
from .trials_csv import TRIALS_COLUMNS, read_trials_csv, read_trials_table, write_trials_csv

__all__ = [
    "CalibrationFileRecord",
    "write_calibration_file",
    "read_calibration_file",
    "write_drives",
    "write_drives_wav",
    "read_drives",
    "TRIALS_COLUMNS",
    "write_trials_csv",
    "read_trials_csv",
    "read_trials_table",
    "format_response",
    "parse_response_text",
    "check_report",
    "write_report_json",
    "read_report_json",
    "save_feature_bank",
    "load_feature_bank",
    "json_safe",
    "write_layout_json",
    "read_layout_json",
    "write_bids_dataset",
    "read_bids_trials_table",
    "MarkerOutlet",
    "marker_code",
    "stable_source_id",
    "write_sofa_tf",
    "read_sofa_tf",
    "write_text",
    "save_figure",
    "atomic_path",
]
