"""Adopt fits: keep each hypothesis' best path, score it on held-out seeds, pick the default.

Every fit file is read and checked, and the set is checked as a whole (the same weights
and level rule, the same random paths for every hypothesis, every registered hypothesis
covered) before any study is simulated or any file written.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

from ..._atomic import write_text
from ...errors import ValidationError
from ..bank import FeatureBank, default_bank
from ..hypotheses import available_hypotheses, hypothesis
from ..paper import N_PARTICIPANTS, seed_statistics
from ..perception import PerceptualModel
from .fitfile import read_fit
from .objective import loss
from .seeds import HELD_OUT_SEEDS

__all__ = ["FITS_FILE", "adopt", "check_fit_set"]

#: The fits vibrofocus ships (:func:`vibrofocus.simulation.hypotheses.hypothesis_fits` reads them).
FITS_FILE = Path(__file__).resolve().parents[1] / "data" / "hypotheses_fit.json"

ABOUT = ("Fits of the simulated participants' hypotheses (a MODEL, not data), written by "
         "scripts/fit_participants.py adopt; model: changes to PerceptualModel's defaults. Each "
         "hypothesis keeps the path (paths: its random paths, each with its loss on the fit seeds) "
         "of lowest loss on the fit seeds. The default hypothesis is the one of lowest held-out loss "
         "under the objective every hypothesis was fitted to (loss_held_out_search_weights); "
         "loss_held_out: the same seeds under the standard objective, every finding weighted alike.")


def _rounded(value: Any) -> Any:
    if isinstance(value, (list, tuple)):
        return [_rounded(v) for v in value]
    return float(f"{value:.3g}") if isinstance(value, float) else value


def _budget_key(budget: dict) -> str:
    return json.dumps(budget, sort_keys=True)


def _versions(versions: Iterable[str]) -> dict[str, str]:
    names = available_hypotheses()
    wanted = {}
    for item in versions:
        name, sep, version = item.partition("=")
        if not sep or not version.strip():
            raise ValidationError(f"version {item!r}: give NAME=VERSION")
        if name not in names:
            raise ValidationError(f"version {item!r}: {name!r} is none of the hypotheses {', '.join(names)}")
        wanted[name] = version
    return wanted


def check_fit_set(paths: Sequence[str | os.PathLike], levels: str) -> dict[str, list[tuple[Path, dict]]]:
    """Read and check the fit files of an adoption, and group them by hypothesis.

    Parameters
    ----------
    paths : sequence of path-like
        Fit files written by a search, one or more random paths per hypothesis.
    levels : str
        The level rule of the feature bank they must have been fitted on.

    Returns
    -------
    dict
        ``{hypothesis name: [(path, fit), ...]}``, every registered hypothesis present.

    Raises
    ------
    ValidationError
        A file is not a fit (:func:`~.fitfile.read_fit`), or the set is not one
        adoption: other weights, another level rule, other fit seeds, a hypothesis
        fitted along other paths (budgets) than another, or a registered hypothesis with no fit.
    """
    if not paths:
        raise ValidationError("no fit files given")
    loaded = {Path(p): read_fit(p) for p in paths}
    first_path, first = next(iter(loaded.items()))
    by_name: dict[str, list[tuple[Path, dict]]] = {}
    for path, fit in loaded.items():
        if fit["weights"] != first["weights"]:
            raise ValidationError(f"{path}: fitted with other weights than {first_path}; fit all alike")
        if fit["levels"] != levels:
            raise ValidationError(f"{path}: fitted at {fit['levels']} levels, the shipped bank is at {levels} levels")
        if list(fit["fit_seeds"]) != list(first["fit_seeds"]):
            raise ValidationError(f"{path}: judged on fit seeds {fit['fit_seeds']}, {first_path} on "
                                  f"{first['fit_seeds']}; fit all alike")
        by_name.setdefault(hypothesis(fit["hypothesis"]).name, []).append((path, fit))
    budgets = {name: sorted(_budget_key(fit["budget"]) for _, fit in group) for name, group in by_name.items()}
    one = next(iter(budgets))
    for name, keys in budgets.items():
        if keys != budgets[one]:
            raise ValidationError(f"{name}: its paths have other budgets than those of {one} "
                                  f"({len(keys)} against {len(budgets[one])} paths, or other seeds); fit all alike")
    missing = [name for name in available_hypotheses() if name not in by_name]
    if missing:
        raise ValidationError(f"no fit of the hypothesis(es) {', '.join(missing)}: adopt writes every hypothesis' "
                              "fit, so give the paths of each (the shipped file would lose the others)")
    return by_name


def adopt(paths: Sequence[str | os.PathLike], versions: Iterable[str] = (), *, out: str | os.PathLike,
          bank: FeatureBank | None = None, report: Callable[[str], Any] | None = None,
          fit_seeds: range | None = None, held_out_seeds: range = HELD_OUT_SEEDS,
          n_participants: int = N_PARTICIPANTS) -> dict[str, Any]:
    """Keep each hypothesis' best path, score it on the held-out seeds, write the fits; return them.

    Every file is checked, and the set as a whole (:func:`check_fit_set`), before anything
    is computed or written. The fits are rounded to 3 digits; per hypothesis the path of
    lowest loss on the fit seeds (after rounding) is kept: the held-out seeds play no part
    in that. The default is the hypothesis of lowest held-out loss under the objective
    every hypothesis was fitted to (the search's weights); the standard objective (every
    finding weighted alike) is recorded beside it.

    Parameters
    ----------
    paths : sequence of path-like
        Fit files written by a search, one or more random paths per hypothesis (the same
        paths for each), covering every registered hypothesis.
    versions : iterable of str
        ``NAME=VERSION`` items: the version of a hypothesis' fitted model (bump it when
        its answers change); default the hypothesis' registered version.
    out : path-like
        Where to write the fits (JSON, atomically): :data:`FITS_FILE` to ship them.
    bank : FeatureBank, optional
        The feature bank (default the shipped one).
    report : callable, optional
        Called with a line of text per path scored, per hypothesis kept and at the end.
    fit_seeds : range, optional
        The studies the paths are compared on: those the fit files record (their
        ``fit_seeds``, the seeds the search judged them on), which is the default; a
        range given must be the same.
    held_out_seeds : range
        The studies the default is chosen on (default :data:`~.seeds.HELD_OUT_SEEDS`).
    n_participants : int
        Participants per study (default the paper's 20).

    Returns
    -------
    dict
        What was written: ``{"about", "default", "hypotheses": {name: fit}}``.

    Raises
    ------
    ValidationError
        See :func:`check_fit_set`; ``fit_seeds`` other than the files'; or a version item that is not ``NAME=VERSION`` of a
        registered hypothesis.
    """
    say = report or (lambda line: None)
    bank = bank if bank is not None else default_bank()
    wanted = _versions(versions)
    by_name = check_fit_set(paths, bank.levels)
    recorded = range(*next(iter(by_name.values()))[0][1]["fit_seeds"])
    if fit_seeds is None:
        fit_seeds = recorded
    elif fit_seeds != recorded:
        raise ValidationError(f"the paths were judged on fit seeds {recorded.start}-{recorded.stop - 1}, not "
                              f"{fit_seeds.start}-{fit_seeds.stop - 1}: adopt compares them on the seeds they were "
                              "fitted on")
    defaults = PerceptualModel().to_dict()
    fits, scores = {}, {}
    for name, group in by_name.items():
        paths_tried = []
        for path, fit in group:
            fixed = {k: _rounded(v) for k, v in fit["model"].items()
                     if k not in ("version", "integration_s") and _rounded(v) != _rounded(defaults[k])}
            model = PerceptualModel().replace(**fixed)
            fitted = loss(seed_statistics(model, fit_seeds, n_participants=n_participants, bank=bank, hypothesis=name),
                          fit["weights"])
            paths_tried.append((fitted, path, fit, fixed, model))
            say(f"{name}: {path}: loss {fitted:.4f} on the fit seeds")
        fitted, path, fit, fixed, model = min(paths_tried, key=lambda t: t[0])
        stats = seed_statistics(model, held_out_seeds, n_participants=n_participants, bank=bank, hypothesis=name)
        held, held_weighted = loss(stats), loss(stats, fit["weights"])
        scores[name] = held_weighted
        fits[name] = {"version": wanted.get(name, hypothesis(name).version), "levels": fit["levels"],
                      "bank_forearms": bank.n_forearms, "budget": fit["budget"], "weights": fit["weights"],
                      "fit_seeds": fit["fit_seeds"],
                      "paths": [{"budget": f["budget"], "loss_fit": round(v, 4)}
                                for v, _, f, _, _ in sorted(paths_tried, key=lambda t: _budget_key(t[2]["budget"]))],
                      "loss_fit": round(fitted, 4), "held_out_seeds": [held_out_seeds.start, held_out_seeds.stop],
                      "loss_held_out": round(held, 4), "loss_held_out_search_weights": round(held_weighted, 4),
                      "model": fixed}
        say(f"{name}: kept {path} (of {len(group)} paths): loss {fitted:.4f} on the fit seeds, held out "
            f"{held_weighted:.4f} with the search's weights ({held:.4f} under the standard objective)")
    default = min(scores, key=scores.get)
    doc = {"about": ABOUT, "default": default, "hypotheses": fits}
    write_text(out, json.dumps(doc, indent=1) + "\n", what="fits")
    say(f"default: {default}; wrote {out}")
    return doc
