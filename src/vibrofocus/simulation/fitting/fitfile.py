"""Fit files: what a search writes and what adopt reads, checked before anything uses them.

A fit file is JSON: ``hypothesis`` (a registered name), ``levels`` (the feature bank's
level rule), ``budget`` (``n_eval``, ``n_refine``, ``rng_seed``, ``start``: the budget of
the fit it started from or null, and ``unfused`` / ``aware`` when searched), ``weights``
(the objective's weights, :func:`~.objective.weight_keys`), ``fit_seeds`` ([first, stop]),
``model`` (parameters of :class:`~vibrofocus.simulation.PerceptualModel`), and the
optional ``bank_forearms`` and ``loss``. A file that is not exactly that is refused with
one line naming the file and the value.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from pathlib import Path
from typing import Any

from ...errors import ValidationError
from ..hypotheses import available_hypotheses
from ..perception import PerceptualModel
from .objective import weight_keys

__all__ = ["read_fit", "check_fit", "fit_model"]

_REQUIRED = ("hypothesis", "levels", "budget", "weights", "fit_seeds", "model")
_OPTIONAL = ("bank_forearms", "loss")
_BUDGET_INTS = ("n_eval", "n_refine", "rng_seed")
_BUDGET_FLAGS = ("unfused", "aware", "within_ranges")
#: How many searches a fit may have started from, one after another (a guard, not a rule).
_MAX_STARTS = 50


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _keys(d: dict, required: tuple[str, ...], optional: tuple[str, ...], where: str) -> None:
    missing = [k for k in required if k not in d]
    if missing:
        raise ValidationError(f"{where}: missing {', '.join(map(repr, missing))}")
    unknown = sorted(set(d) - set(required) - set(optional))
    if unknown:
        raise ValidationError(f"{where}: unknown key(s) {', '.join(map(repr, unknown))} "
                              f"(known: {', '.join(required + optional)})")


def _check_budget(budget: Any, where: str) -> None:
    for depth in range(_MAX_STARTS + 1):
        if not isinstance(budget, dict):
            raise ValidationError(f"{where}: must be an object, not {type(budget).__name__}")
        _keys(budget, _BUDGET_INTS + ("start",), _BUDGET_FLAGS, where)
        for key in _BUDGET_INTS:
            if not _is_int(budget[key]) or budget[key] < 0:
                raise ValidationError(f"{where}.{key}: must be a whole number >= 0, not {budget[key]!r}")
        for key in _BUDGET_FLAGS:
            if key in budget and budget[key] is not True:
                raise ValidationError(f"{where}.{key}: must be true where present, not {budget[key]!r}")
        if budget["start"] is None:
            return
        budget, where = budget["start"], f"{where}.start"
    raise ValidationError(f"{where}: more than {_MAX_STARTS} searches started from one another")


def _check_model(model: Any, where: str) -> None:
    if not isinstance(model, dict):
        raise ValidationError(f"{where}: must be an object of PerceptualModel parameters, not {type(model).__name__}")
    defaults = {f.name: f.default for f in dataclasses.fields(PerceptualModel)}
    unknown = sorted(set(model) - set(defaults))
    if unknown:
        raise ValidationError(f"{where}: unknown perceptual model parameter(s) {', '.join(map(repr, unknown))}")
    for key, value in model.items():
        default = defaults[key]
        if key == "version":
            ok, kind = isinstance(value, str), "a string"
        elif key == "integration_s":
            ok, kind = value is None or (_is_number(value) and value > 0), "null or a number > 0"
        elif isinstance(default, tuple):
            ok = isinstance(value, (list, tuple)) and len(value) == len(default) and all(map(_is_number, value))
            kind = f"a list of {len(default)} finite numbers"
        else:
            ok, kind = _is_number(value), "a finite number"
        if not ok:
            raise ValidationError(f"{where}.{key}: must be {kind}, not {value!r}")


def check_fit(fit: Any, where: str = "fit") -> dict[str, Any]:
    """Check one fit (a search's record) and return it; raise on anything else.

    Parameters
    ----------
    fit : object
        The parsed JSON of a fit file.
    where : str
        What to call it in messages (the file's name).

    Returns
    -------
    dict
        ``fit`` itself.

    Raises
    ------
    ValidationError
        For anything but a fit: another type, a missing or unknown key, a value of the
        wrong type, a number that is not finite, an unknown hypothesis or parameter.
    """
    if not isinstance(fit, dict):
        raise ValidationError(f"{where}: not a fit (a JSON object written by search), but a {type(fit).__name__}")
    _keys(fit, _REQUIRED, _OPTIONAL, where)
    names = available_hypotheses()
    if not isinstance(fit["hypothesis"], str) or fit["hypothesis"] not in names:
        raise ValidationError(f"{where}: hypothesis {fit['hypothesis']!r} is none of {', '.join(names)}")
    if not isinstance(fit["levels"], str):
        raise ValidationError(f"{where}: levels must be a string, not {fit['levels']!r}")
    if "bank_forearms" in fit and (not _is_int(fit["bank_forearms"]) or fit["bank_forearms"] < 1):
        raise ValidationError(f"{where}: bank_forearms must be a whole number >= 1, not {fit['bank_forearms']!r}")
    if "loss" in fit and not _is_number(fit["loss"]):
        raise ValidationError(f"{where}: loss must be a finite number, not {fit['loss']!r}")
    seeds = fit["fit_seeds"]
    if not (isinstance(seeds, list) and len(seeds) == 2 and all(map(_is_int, seeds)) and 0 <= seeds[0] < seeds[1]):
        raise ValidationError(f"{where}: fit_seeds must be [first, stop] with 0 <= first < stop, not {seeds!r}")
    weights = fit["weights"]
    if not isinstance(weights, dict):
        raise ValidationError(f"{where}: weights must be an object, not {type(weights).__name__}")
    known = weight_keys()
    for key, value in weights.items():
        if key not in known:
            raise ValidationError(f"{where}: weights: unknown statistic {key!r} (one of {', '.join(known)})")
        if not _is_number(value) or value < 0:
            raise ValidationError(f"{where}: weights[{key!r}] must be a finite number >= 0, not {value!r}")
    _check_budget(fit["budget"], f"{where}: budget")
    _check_model(fit["model"], f"{where}: model")
    return fit


def read_fit(path: str | os.PathLike) -> dict[str, Any]:
    """Read and check a fit file (:func:`check_fit`).

    Parameters
    ----------
    path : path-like
        A fit file written by a search (JSON).

    Returns
    -------
    dict
        The fit.

    Raises
    ------
    ValidationError
        The file cannot be read, is not JSON, or is not a fit.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ValidationError(f"{path}: cannot read the fit: {exc}") from None
    try:
        fit = json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise ValidationError(f"{path}: not JSON: {str(exc)[:200]}") from None
    return check_fit(fit, str(path))


def fit_model(fit: dict[str, Any]) -> PerceptualModel:
    """The model of a checked fit: ``PerceptualModel()`` with the fit's parameters.

    Parameters
    ----------
    fit : dict
        A fit (:func:`read_fit`).

    Returns
    -------
    PerceptualModel
    """
    return PerceptualModel().replace(**fit["model"])
