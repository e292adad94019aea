"""Feature-bank files (``.npz``): felt energies of every study stimulus on simulated forearms.

Arrays: ``energy`` (n_forearms, n_methods, n_locations, n_points), float32, felt energy
re the reference tap; ``points_xy`` (n_points, 2), m; ``locations_xy`` (n_locations, 2),
m; ``centre_xy`` (2,), m; ``methods`` (n_methods,), str; ``forearm_seeds``
(n_forearms,), int; ``seed`` (scalar), int; ``actuator_energy`` (n_forearms,
n_methods, n_locations, n_actuators), float32, each actuator's own felt energy at its
contact; ``actuators_xy`` (n_actuators, 2), m; ``model_version`` (scalar), str: the
perceptual model that wrote it; ``levels`` (scalar), str: the level rule the stimuli were
rendered with (a bank written before it was stored: ``equal-peak``); ``drive_peak_v``
(n_forearms, n_methods, n_locations), V, and ``target_peak_m`` (the same shape), m: each
stimulus's largest |drive| and its peak at the target predicted from the calibration
(absent in a bank written before them). The shipped bank is ``simulation/data/feature_bank.npz``
(``scripts/build_feature_bank.py``).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ValidationError

__all__ = ["FEATURE_BANK_ARRAYS", "FEATURE_BANK_OPTIONAL", "save_feature_bank", "load_feature_bank"]

#: The arrays of a feature bank, as :func:`save_feature_bank` takes them and
#: :func:`load_feature_bank` returns them (besides ``model_version``).
FEATURE_BANK_ARRAYS = ("energy", "points_xy", "locations_xy", "centre_xy", "methods", "forearm_seeds", "seed",
                       "actuator_energy", "actuators_xy")
#: Optional entries (``levels``, then the stimulus peaks): a bank without them is read
#: with ``levels="equal-peak"`` and no peaks (None).
FEATURE_BANK_OPTIONAL = ("levels", "drive_peak_v", "target_peak_m")


def save_feature_bank(bank: Mapping[str, Any], path: str | os.PathLike, *, model_version: str) -> Path:
    """Write a feature bank's arrays to an ``.npz`` file, atomically (:func:`vibrofocus._atomic.atomic_write`).

    Parameters
    ----------
    bank : mapping
        The arrays named :data:`FEATURE_BANK_ARRAYS` (see the module docstring for shapes
        and units), e.g. ``dataclasses.asdict`` of a
        :class:`~vibrofocus.simulation.bank.FeatureBank`.
    path : path-like
        Destination ``.npz``; its folder must exist.
    model_version : str
        Version of the perceptual model the energies were computed with.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    OutputError
        The file cannot be written; a previous file at ``path`` is unchanged.
    """
    from .._atomic import atomic_write

    missing = [name for name in FEATURE_BANK_ARRAYS if name not in bank]
    if missing:
        raise ValidationError(f"a feature bank needs the arrays {', '.join(missing)}")
    extra = {name: np.asarray(bank[name]) for name in FEATURE_BANK_OPTIONAL if bank.get(name) is not None}
    with atomic_write(path, "wb", what="feature bank") as fh:
        np.savez_compressed(
            fh, **extra, energy=np.asarray(bank["energy"]).astype(np.float32), points_xy=bank["points_xy"],
            locations_xy=bank["locations_xy"], centre_xy=bank["centre_xy"], methods=np.array(bank["methods"]),
            forearm_seeds=bank["forearm_seeds"], seed=np.int64(bank["seed"]),
            actuator_energy=np.asarray(bank["actuator_energy"]).astype(np.float32), actuators_xy=bank["actuators_xy"],
            model_version=np.array(model_version),
        )
    return Path(path)


def load_feature_bank(path: str | os.PathLike) -> dict[str, Any]:
    """Read a feature bank's arrays written by :func:`save_feature_bank`.

    Parameters
    ----------
    path : path-like
        A feature-bank ``.npz``.

    Returns
    -------
    dict
        :data:`FEATURE_BANK_ARRAYS` and :data:`FEATURE_BANK_OPTIONAL`: ``energy`` float,
        ``methods`` a tuple of str, ``seed`` an int, ``levels`` a str, the others arrays
        (the peaks None when absent); ready for ``FeatureBank(**...)``.

    Raises
    ------
    ValidationError
        The file cannot be read or lacks an array.
    """
    try:
        with np.load(path) as z:
            return {"energy": z["energy"].astype(float), "points_xy": z["points_xy"], "locations_xy": z["locations_xy"],
                    "centre_xy": z["centre_xy"], "methods": tuple(str(m) for m in z["methods"]),
                    "forearm_seeds": z["forearm_seeds"], "seed": int(z["seed"]),
                    "actuator_energy": z["actuator_energy"].astype(float), "actuators_xy": z["actuators_xy"],
                    "levels": str(z["levels"]) if "levels" in z.files else "equal-peak",
                    "drive_peak_v": z["drive_peak_v"].astype(float) if "drive_peak_v" in z.files else None,
                    "target_peak_m": z["target_peak_m"].astype(float) if "target_peak_m" in z.files else None}
    except (OSError, KeyError, ValueError) as exc:
        raise ValidationError(f"cannot read the feature bank {path}: {exc}") from exc
