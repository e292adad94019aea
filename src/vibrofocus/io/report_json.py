"""report.json: the analysis report as data (docs/file-formats.md, report folder).

The contract: ``study1.anova`` is a list of rows, each with at least
:data:`ANOVA_COLUMNS`; ``study2.friedman`` has the factors :data:`FRIEDMAN_FACTORS`,
each with at least :data:`FRIEDMAN_KEYS`. A statistic that could not be computed is
empty or null (``anova: []``, null ``chi2``/``dof``/``p``). The file is strict JSON
(UTF-8, no NaN: missing values are ``null``). The report's content is assembled by
:func:`vibrofocus.analysis.report_dict`; this module checks, writes and reads it.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..errors import ValidationError
from .jsonsafe import json_safe

__all__ = ["REPORT_JSON", "ANOVA_COLUMNS", "FRIEDMAN_FACTORS", "FRIEDMAN_KEYS", "check_report",
           "write_report_json", "read_report_json"]

#: File name of the report's data in a report folder.
REPORT_JSON = "report.json"
#: Columns every row of ``study1.anova`` has.
ANOVA_COLUMNS = ("effect", "F", "ddof1", "ddof2", "p_unc", "p_gg", "eps")
#: Factors of ``study2.friedman``.
FRIEDMAN_FACTORS = ("location", "method")
#: Keys of each factor of ``study2.friedman`` (null where no test could be run).
FRIEDMAN_KEYS = ("chi2", "dof", "p")


def check_report(report: Mapping[str, Any], *, where: str = "report") -> None:
    """Check that ``report`` keeps the report.json contract (see the module docstring).

    Parameters
    ----------
    report : mapping
        The report's content, as :func:`vibrofocus.analysis.report_dict` returns it.
    where : str
        Names the report in error messages (a file name).

    Raises
    ------
    ValidationError
        A key of the contract is missing, naming it.
    """
    def need(mapping: Any, key: str, path: str) -> Any:
        if not isinstance(mapping, Mapping) or key not in mapping:
            raise ValidationError(f"{where} breaks the report.json contract: {path}{key} is missing")
        return mapping[key]

    study1 = need(report, "study1", "")
    anova = need(study1, "anova", "study1.")
    if not isinstance(anova, list):
        raise ValidationError(f"{where} breaks the report.json contract: study1.anova is not a list")
    for i, row in enumerate(anova):
        for column in ANOVA_COLUMNS:
            need(row, column, f"study1.anova[{i}].")
    friedman = need(need(report, "study2", ""), "friedman", "study2.")
    for factor in FRIEDMAN_FACTORS:
        stats = need(friedman, factor, "study2.friedman.")
        for key in FRIEDMAN_KEYS:
            need(stats, key, f"study2.friedman.{factor}.")


def write_report_json(report: Mapping[str, Any], path: str | os.PathLike) -> Path:
    """Check ``report`` (:func:`check_report`) and write it as strict, indented UTF-8 JSON, atomically.

    Parameters
    ----------
    report : mapping
        The report's content; numpy and pandas values are converted
        (:func:`~vibrofocus.io.jsonsafe.json_safe`), NaN and infinities written as null.
    path : path-like
        Destination, conventionally ``report.json``; its folder must exist.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ValidationError
        ``report`` breaks the contract.
    OutputError
        The file cannot be written; a previous file at ``path`` is unchanged.
    """
    from .._atomic import REPORT_JSON as REPORT_KIND, write_text

    check_report(report)
    text = json.dumps(json_safe(report), indent=2, ensure_ascii=False, allow_nan=False)
    return write_text(path, text, what="report", kind=REPORT_KIND)


def read_report_json(path: str | os.PathLike) -> dict[str, Any]:
    """Read a report.json and check its contract.

    Parameters
    ----------
    path : path-like
        A report.json written by :func:`write_report_json` (``vibrofocus analyze``).

    Returns
    -------
    dict
        The report's content.

    Raises
    ------
    ValidationError
        The file cannot be read, is not JSON, or breaks the contract (naming the key).
    """
    path = Path(path)
    try:
        report = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ValidationError(f"cannot read the report {path}: {exc.strerror or exc}") from None
    except ValueError as exc:  # JSONDecodeError and UnicodeDecodeError
        raise ValidationError(f"{path} is not a JSON report: {exc}") from None
    check_report(report, where=str(path))
    return report
