"""Feature-bank files (``.npz``): felt energies of every study stimulus on simulated forearms.

Arrays: ``energy`` (n_forearms, n_methods, n_locations, n_points), float32, felt energy
re the reference tap; ``points_xy`` (n_points, 2), m; ``locations_xy`` (n_locations, 2),
m; ``centre_xy`` (2,), m; ``methods`` (n_methods,), str; ``forearm_seeds``
(n_forearms,), int; ``seed`` (scalar), int; ``actuator_energy`` (n_forearms,
n_methods, n_locations, n_actuators), float32, each actuator's own felt energy at its
contact; ``actuators_xy`` (n_actuators, 2), m; ``model_version`` (scalar), str: the
perceptual model that wrote it. The shipped bank is ``studies/data/feature_bank.npz``
(``scripts/build_feature_bank.py``).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import ValidationError

if TYPE_CHECKING:  # the record type lives in vibrofocus.studies, above this module
    from ..studies.bank import FeatureBank

__all__ = ["save_feature_bank", "load_feature_bank"]


def save_feature_bank(bank: FeatureBank, path: str | os.PathLike, *, model_version: str) -> Path:
    """Write a feature bank to an ``.npz`` file, atomically (:func:`vibrofocus._atomic.atomic_write`).

    Parameters
    ----------
    bank : FeatureBank
        The bank (:func:`vibrofocus.studies.bank.build_feature_bank`).
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

    with atomic_write(path, "wb", what="feature bank") as fh:
        np.savez_compressed(
            fh, energy=bank.energy.astype(np.float32), points_xy=bank.points_xy, locations_xy=bank.locations_xy,
            centre_xy=bank.centre_xy, methods=np.array(bank.methods), forearm_seeds=bank.forearm_seeds,
            seed=np.int64(bank.seed), actuator_energy=bank.actuator_energy.astype(np.float32),
            actuators_xy=bank.actuators_xy, model_version=np.array(model_version),
        )
    return Path(path)


def load_feature_bank(path: str | os.PathLike) -> FeatureBank:
    """Read a feature bank written by :func:`save_feature_bank`.

    Parameters
    ----------
    path : path-like
        A feature-bank ``.npz``.

    Returns
    -------
    FeatureBank

    Raises
    ------
    ValidationError
        The file cannot be read or lacks an array.
    """
    from ..studies.bank import FeatureBank

    try:
        with np.load(path) as z:
            return FeatureBank(
                energy=z["energy"].astype(float), points_xy=z["points_xy"], locations_xy=z["locations_xy"],
                centre_xy=z["centre_xy"], methods=tuple(str(m) for m in z["methods"]),
                forearm_seeds=z["forearm_seeds"], seed=int(z["seed"]),
                actuator_energy=z["actuator_energy"].astype(float), actuators_xy=z["actuators_xy"],
            )
    except (OSError, KeyError, ValueError) as exc:
        raise ValidationError(f"cannot read the feature bank {path}: {exc}") from exc
